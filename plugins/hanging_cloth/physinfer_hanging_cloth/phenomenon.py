"""The hanging-cloth phenomenon record and its embedded default target.

The default target is simulated (fan W2, seed 0) and rendered deterministically from a
fabric away from the centre of θ, so ``physinfer refine --plugin hanging_cloth`` works
out of the box. Its default embedder is the flag plugin's parameter-free ``spectral``
one (30 frames at 25 fps, which the short default clips cover).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache

from physinfer import Effect, Phenomenon, Target

#: Ground truth of the embedded target: a fairly stiff, light fabric.
DEFAULT_TRUTH = {"bending_multiplier": 12.0, "area_weight": 0.12}
#: Seed of the embedded target (the refinement's default seed, so the truth reproduces it).
DEFAULT_SEED = 0


def make_simulator(effects: Sequence[Effect] = ()):  # noqa: ANN201 - HangingClothSimulator
    """The hanging-cloth simulator at its default configuration (fan W2)."""
    from physinfer_hanging_cloth.simulator import make_simulator as make

    return make(effects)


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
    )
