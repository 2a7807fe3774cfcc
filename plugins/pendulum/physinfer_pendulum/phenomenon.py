"""The pendulum phenomenon record and its embedded default target."""

from __future__ import annotations

from functools import cache
from pathlib import Path

from physinfer import Phenomenon, Target
from physinfer.registry import resolve

#: The shipped amortized estimator (``make posterior-pendulum``): reads the first 8 s of a video.
DEFAULT_POSTERIOR = Path(__file__).parent / "data" / "posterior_default.safetensors"

#: Ground truth of the embedded target (a 10-s clip), away from the centre of the space.
DEFAULT_TRUTH = {"length": 0.6, "damping": 0.05, "amplitude": 20.0, "phase": 0.3}


@cache
def default_target() -> Target:
    """A clip simulated and rendered deterministically from :data:`DEFAULT_TRUTH`."""
    from physinfer_pendulum.physics import make_simulator
    from physinfer_pendulum.render import PendulumRenderer

    renderer = PendulumRenderer()
    clip = renderer.render(make_simulator().simulate(DEFAULT_TRUTH, seed=0))
    renderer.close()
    return Target(
        clip=clip,
        truth=dict(DEFAULT_TRUTH),
        render_params=dict(PendulumRenderer.default_render_params),
        description="synthetic pendulum, 10 s",
    )


def make_phenomenon() -> Phenomenon:
    """Build the record (imports the implementation modules)."""
    from physinfer_pendulum.physics import NUISANCE, make_simulator, pendulum_parameter_space

    return Phenomenon(
        name="pendulum",
        description="a bob on a string, from real footage: length, damping, amplitude (phase as nuisance)",
        parameter_space=pendulum_parameter_space(),
        make_simulator=make_simulator,
        make_renderer=resolve("physinfer_pendulum.render:PendulumRenderer"),
        default_embedder="motion",
        default_target=default_target,
        effects=("air_drag",),
        default_steps=24,
        diagnose_batch_size=2,
        nuisance=NUISANCE,
        duration_from_target=True,
        video_estimate=resolve("physinfer_pendulum.estimate:video_estimate"),
        default_posterior=str(DEFAULT_POSTERIOR),
    )
