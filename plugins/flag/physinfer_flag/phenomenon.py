"""The flag phenomenon record and its embedded default target.

The default target is simulated and rendered deterministically from a ground truth away
from the centre of the space. The flag refines with the SDN and the weights shipped in
``physinfer_flag/data/sdn_default.safetensors`` (``make pretrained`` reproduces them);
``--embedder spectral`` is the parameter-free fallback. Its posterior estimator
(``physinfer_flag/data/posterior_default.safetensors``, 2.4-s clips, ``spectral`` embedder;
``make posterior`` reproduces it) gives ``infer`` and ``refine`` their intervals.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from functools import cache
from pathlib import Path
from typing import Any

from physinfer import Effect, Phenomenon, Target, UserInputError
from physinfer.registry import resolve
from physinfer.scene import SceneSetting

#: The shipped posterior estimator (``make posterior``).
DEFAULT_POSTERIOR = Path(__file__).resolve().parent / "data" / "posterior_default.safetensors"
#: The shipped estimator for flags of other sizes: trained across 0.9-3 m × 0.6-2 m flags
#: (``make posterior-sizes``), it takes the flag's size (``--scene-set``) as input.
SIZES_POSTERIOR = Path(__file__).resolve().parent / "data" / "posterior_sizes.safetensors"
#: The shipped estimator told the camera and light (``make posterior-camera``): chosen by
#: ``infer --render-set`` giving them all, sharper than the default, which averages over them.
CAMERA_POSTERIOR = Path(__file__).resolve().parent / "data" / "posterior_camera.safetensors"
#: The shipped estimator for a flag pinned at its two top corners (``make posterior-corners``):
#: trained across the same sizes as the sizes estimator, which it takes as input too.
CORNERS_POSTERIOR = Path(__file__).resolve().parent / "data" / "posterior_corners.safetensors"

#: Ground truth of the embedded target: wind and area weight off-centre, bending at 1×.
DEFAULT_TRUTH_BASE = {"wind_speed": 6.5, "area_weight": 0.12}


def _default_truth() -> dict[str, float]:
    from physinfer_flag.simulator import flag_parameter_space

    truth = flag_parameter_space().defaults()
    truth.update({name: 1.0 for name in truth if name.startswith("bend_")})
    truth.update(DEFAULT_TRUTH_BASE)
    return truth


#: The flag's scene settings (``--scene-set``); defaults are the simulator's 1.5 m × 1 m flag
#: held along its hoist on a 3 m pole. Sizes span pocket to large pole flags (0.9–3 m are
#: common); the grid keeps its 5 cm cells, so cost grows with the area (docs/real-videos.md).
SCENE_SETTINGS = (
    SceneSetting("flag_length", "float", 1.5, (0.5, 4.0), unit="m",
                 help="hoist-to-fly length of the flag, along the wind"),
    SceneSetting("flag_height", "float", 1.0, (0.3, 3.0), unit="m", help="hoist length, along the pole"),
    SceneSetting("pinning", "choice", "hoist", choices=("hoist", "corners"),
                 help="hoist: the whole hoist edge on the pole; corners: only its two corners (ArcSim's flag)"),
    SceneSetting("pole_height", "float", 3.0, (0.5, 30.0), unit="m",
                 help="height of the pole's top above the ground; the flag's top is 5 cm below it"),
)
#: Grid spacing the scene's flag is meshed at: the default flag's 5 cm (docs/flag-physics.md).
SCENE_SPACING = 0.05


def scene_config(scene: Mapping[str, Any]) -> dict[str, Any]:
    """``FlagSimConfig`` settings of a complete scene: size, pinning, pole and a grid of about
    5 cm cells (31 × 21 nodes for the default flag, so the default scene is the default flag).

    Raises:
        UserInputError: a pole too short for the flag.
    """
    from physinfer_flag.simulator import POLE_CAP

    length, height, pole = float(scene["flag_length"]), float(scene["flag_height"]), float(scene["pole_height"])
    if pole < height + POLE_CAP:
        raise UserInputError(
            f"--scene-set pole_height={pole:g} is too short for flag_height={height:g}: the pole must reach "
            f"at least flag_height + {POLE_CAP:g} m = {height + POLE_CAP:g} m"
        )
    return {
        "width": length,
        "height": height,
        "grid_u": max(3, round(length / SCENE_SPACING) + 1),
        "grid_v": max(3, round(height / SCENE_SPACING) + 1),
        "pin_mode": "edge" if scene["pinning"] == "hoist" else "corners",
        "pole_height": pole,
    }


def make_simulator(  # noqa: ANN201 - FlagSimulator
    effects: Sequence[Effect] = (), *, duration_s: float | None = None, scene: Mapping[str, Any] | None = None
):
    """The flag simulator (a ``FlagSimulator``) at its default configuration, or a scene's.

    Args:
        effects: Effects switched into the wind.
        duration_s: Record this many seconds (rounded up to whole frames) instead of the
            default 60 frames; datasets of longer clips ask for it. A longer recording
            starts with the same frames as a shorter one of the same seed.
        scene: Complete scene settings (:data:`SCENE_SETTINGS`, validated by
            :func:`physinfer.scene.resolve_scene`); ``None``: the default flag.
    """
    from physinfer_flag.simulator import FlagSimConfig
    from physinfer_flag.simulator import make_simulator as make

    config: dict[str, Any] = scene_config(scene) if scene is not None else {}
    if duration_s is not None:
        config["n_frames"] = max(1, math.ceil(duration_s * FlagSimConfig().fps - 1e-9))
    return make(effects, **config)


def make_renderer(scene: Mapping[str, Any] | None = None):  # noqa: ANN201 - FlagRenderer
    """The pyrender flag renderer. It frames the flag from the trajectory's own size; a scene's
    ``pole_height`` draws the pole of a trajectory that carries none (another simulator's)."""
    from physinfer_flag.render import FlagRenderer

    if scene is None:
        return FlagRenderer()
    return FlagRenderer(pole_height=float(scene["pole_height"]))


@cache
def default_target() -> Target:
    """A clip of the flag at :func:`_default_truth`, seed 12345, default ζ."""
    return Target.synthetic(
        make_simulator(), make_renderer(), _default_truth(), seed=12345, description="synthetic flag (seed 12345)"
    )


#: The moving region of a flag flying in the renderer's default view spans 0.98 fly lengths
#: across (the fly end folds back) and, drooping in a light wind, up to 1.02 lengths down;
#: its top-left corner lies 0.23 lengths right of and 0.18 below the framed square's (the
#: hoist barely moves). Medians over 27 encoded, noisy composites of renders at 2.5-10 m/s
#: and varied cameras (docs/real-videos.md).
FRAMING_SPAN = (0.98, 1.02)
FRAMING_OFFSET = (0.23, 0.18)
#: The renderer's automatic square, in fly lengths (``physinfer_flag.flag_scene``'s 2 × 0.68).
FRAMING_SIDE = 1.36


def framing(box: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """The square the flag renderer frames, from the box ``(x, y, w, h)`` the flag moves in.

    The fly length in pixels is the larger of what the box's width (flying) and height
    (drooping) imply; the square hangs from the box's top-left corner, the hoist, as the
    renderer's square hangs from the hoist top. Assumes the flag flies to the right (a target
    flying left is mirrored first: :mod:`physinfer_flag.facing`).
    """
    x, y, w, h = box
    length = max(w / FRAMING_SPAN[0], h / FRAMING_SPAN[1])
    side = FRAMING_SIDE * length
    return (x - FRAMING_OFFSET[0] * length, y - FRAMING_OFFSET[1] * length, side, side)


def make_phenomenon() -> Phenomenon:
    """Build the record (imports the implementation modules)."""
    from physinfer_flag.simulator import flag_parameter_space

    return Phenomenon(
        name="flag",
        description="a flag on a pole waving in the wind (Wang bending, area weight, wind)",
        parameter_space=flag_parameter_space(),
        make_simulator=make_simulator,
        make_renderer=make_renderer,
        default_embedder="sdn",
        default_target=default_target,
        default_steps=40,
        default_steps_with_posterior=16,  # 20 held-out targets: 16 trials beat 40 (docs/benchmarks.md)
        default_posterior=str(DEFAULT_POSTERIOR),
        scene_posteriors=(str(SIZES_POSTERIOR), str(CAMERA_POSTERIOR), str(CORNERS_POSTERIOR)),
        framing=framing,
        scene_settings=SCENE_SETTINGS,
        facing=resolve("physinfer_flag.facing:flag_facing"),
    )
