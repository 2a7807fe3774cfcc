"""The flag phenomenon record and its embedded default target.

The default target is simulated and rendered deterministically from a ground truth away
from the centre of the space. The flag refines with the SDN and the weights shipped in
``physinfer_flag/data/sdn_default.safetensors`` (``make pretrained`` reproduces them);
``--embedder spectral`` is the parameter-free fallback. Its posterior estimator
(``physinfer_flag/data/posterior_default.safetensors``, 2.4-s clips embedded by that SDN;
``make posterior`` reproduces it) gives ``infer`` and ``refine`` their intervals.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cache
from pathlib import Path

from physinfer import Effect, Phenomenon, Target

#: The shipped posterior estimator (``make posterior``).
DEFAULT_POSTERIOR = Path(__file__).resolve().parent / "data" / "posterior_default.safetensors"

#: Ground truth of the embedded target: wind and area weight off-centre, bending at 1×.
DEFAULT_TRUTH_BASE = {"wind_speed": 6.5, "area_weight": 0.12}


def _default_truth() -> dict[str, float]:
    from physinfer_flag.simulator import flag_parameter_space

    truth = flag_parameter_space().defaults()
    truth.update({name: 1.0 for name in truth if name.startswith("bend_")})
    truth.update(DEFAULT_TRUTH_BASE)
    return truth


def make_simulator(effects: Sequence[Effect] = (), *, duration_s: float | None = None):  # noqa: ANN201
    """The flag simulator (a ``FlagSimulator``) at its default configuration.

    Args:
        effects: Effects switched into the wind.
        duration_s: Record this many seconds (rounded up to whole frames) instead of the
            default 60 frames; datasets of longer clips ask for it. A longer recording
            starts with the same frames as a shorter one of the same seed.
    """
    from physinfer_flag.simulator import FlagSimConfig
    from physinfer_flag.simulator import make_simulator as make

    if duration_s is None:
        return make(effects)
    fps = FlagSimConfig().fps
    return make(effects, n_frames=max(1, math.ceil(duration_s * fps - 1e-9)))


def make_renderer():  # noqa: ANN201 - FlagRenderer
    """The pyrender flag renderer."""
    from physinfer_flag.render import FlagRenderer

    return FlagRenderer()


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
#: The renderer's automatic square, in fly lengths (``physinfer_flag.render``'s 2 × 0.68).
FRAMING_SIDE = 1.36


def framing(box: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """The square the flag renderer frames, from the box ``(x, y, w, h)`` the flag moves in.

    The fly length in pixels is the larger of what the box's width (flying) and height
    (drooping) imply; the square hangs from the box's top-left corner, the hoist, as the
    renderer's square hangs from the hoist top. Assumes the flag flies to the right.
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
        default_posterior=str(DEFAULT_POSTERIOR),
        framing=framing,
    )
