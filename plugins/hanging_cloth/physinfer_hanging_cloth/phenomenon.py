"""The hanging-cloth phenomenon record and its embedded default target.

The default target is simulated (fan W2, seed 0) and rendered deterministically from a
fabric away from the centre of θ, so ``physinfer refine --plugin hanging_cloth`` works
out of the box. Its default embedder is the flag plugin's parameter-free ``spectral``
one (30 frames at 25 fps, which the short default clips cover).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from functools import cache
from pathlib import Path
from typing import Any

from physinfer import Effect, Phenomenon, Target
from physinfer.scene import SceneSetting

#: The shipped posterior estimator (``make posterior-hanging-cloth``): fan W2, the default
#: 0.6 m × 0.8 m fabric, 32-frame clips, the ``spectral`` embedder; trained as users give videos.
DEFAULT_POSTERIOR = Path(__file__).resolve().parent / "data" / "posterior_default.safetensors"

#: Ground truth of the embedded target: a fairly stiff, light fabric.
DEFAULT_TRUTH = {"bending_multiplier": 12.0, "area_weight": 0.12}
#: Seed of the embedded target (the refinement's default seed, so the truth reproduces it).
DEFAULT_SEED = 0


#: The hanging cloth's scene settings (``--scene-set``); defaults are the simulator's 0.6 m ×
#: 0.8 m fabric in front of the fan at W2 (Bouman et al.'s videos show three fan levels).
SCENE_SETTINGS = (
    SceneSetting("cloth_width", "float", 0.6, (0.2, 2.0), unit="m", help="width of the fabric along the rod"),
    SceneSetting("cloth_height", "float", 0.8, (0.2, 1.5), unit="m",
                 help="hanging length of the fabric, rod to hem (the rod is 1.5 m high)"),
    SceneSetting("fan", "choice", "W2", choices=("W1", "W2", "W3"), help="fan level of the video (W1 weakest)"),
)


def make_simulator(  # noqa: ANN201 - HangingClothSimulator
    effects: Sequence[Effect] = (), *, duration_s: float | None = None, scene: Mapping[str, Any] | None = None
):
    """The hanging-cloth simulator at its default configuration (fan W2), or a scene's.

    Args:
        effects: Effects (the hanging cloth has none; any is refused).
        duration_s: Record this many seconds after the warm-up (rounded up to whole frames)
            instead of the default 32 frames: ``dataset generate``'s 60-frame clips and
            ``simulate --duration`` ask for it.
        scene: Complete settings of :data:`SCENE_SETTINGS` (the grid keeps its 4 cm spacing);
            ``None``: the default fabric at fan W2.
    """
    from physinfer_hanging_cloth.simulator import HangingClothConfig
    from physinfer_hanging_cloth.simulator import make_simulator as make

    config: dict[str, Any] = {}
    if scene is not None:
        config = {"width": float(scene["cloth_width"]), "height": float(scene["cloth_height"]),
                  "fan_level": str(scene["fan"])}
    if duration_s is not None:
        config["n_frames"] = max(2, math.ceil(duration_s * HangingClothConfig().fps - 1e-9))
    return make(effects, **config)


def make_renderer():  # noqa: ANN201 - HangingClothRenderer
    """The pyrender hanging-cloth renderer."""
    from physinfer_hanging_cloth.render import HangingClothRenderer

    return HangingClothRenderer()


@cache
def default_target() -> Target:
    """A clip of the fabric :data:`DEFAULT_TRUTH` at fan W2, seed 0, default ζ."""
    return Target.synthetic(
        make_simulator(), make_renderer(), DEFAULT_TRUTH, seed=DEFAULT_SEED,
        description=f"synthetic hanging cloth (fan W2, seed {DEFAULT_SEED})",
    )


def make_phenomenon() -> Phenomenon:
    """Build the record (imports the implementation modules)."""
    from physinfer_hanging_cloth.simulator import hanging_cloth_parameter_space

    return Phenomenon(
        name="hanging_cloth",
        description="a fabric hanging from a rod in front of a fan (Bouman et al. 2013): bending, area weight",
        parameter_space=hanging_cloth_parameter_space(),
        make_simulator=make_simulator,
        make_renderer=make_renderer,
        default_embedder="spectral",
        default_target=default_target,
        default_steps=20,
        default_posterior=str(DEFAULT_POSTERIOR),
        scene_settings=SCENE_SETTINGS,
    )
