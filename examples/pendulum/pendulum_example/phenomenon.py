"""The pendulum phenomenon record and its embedded default target."""

from __future__ import annotations

from functools import cache

from physinfer import Phenomenon, Target
from physinfer.registry import resolve

#: Ground truth of the embedded target, away from the centre of the space.
DEFAULT_TRUTH = {"length": 1.25, "damping": 0.12, "amplitude": 42.0}


@cache
def default_target() -> Target:
    """A clip simulated and rendered deterministically from :data:`DEFAULT_TRUTH`."""
    from pendulum_example.physics import make_simulator
    from pendulum_example.render import PendulumRenderer

    renderer = PendulumRenderer()
    clip = renderer.render(make_simulator().simulate(DEFAULT_TRUTH, seed=0))
    renderer.close()
    return Target(
        clip=clip,
        truth=dict(DEFAULT_TRUTH),
        render_params=dict(PendulumRenderer.default_render_params),
        description="synthetic pendulum (example plugin)",
    )


def make_phenomenon() -> Phenomenon:
    """Build the record (imports the implementation modules)."""
    from pendulum_example.physics import make_simulator, pendulum_parameter_space

    return Phenomenon(
        name="pendulum_lab",
        description="a damped pendulum swinging in front of a wall (worked example)",
        parameter_space=pendulum_parameter_space(),
        make_simulator=make_simulator,
        make_renderer=resolve("pendulum_example.render:PendulumRenderer"),
        default_embedder="grid_spectrum",
        default_target=default_target,
        effects=("quadratic_drag",),
        default_steps=20,
        # Ax's step is most of a trial here: two per GP fit (docs/benchmarks.md, "Two trials
        # per GP fit": the pendulum's diagnosis table kept every decision).
        diagnose_batch_size=2,
    )
