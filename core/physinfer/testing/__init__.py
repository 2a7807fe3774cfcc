"""Contract checks every plugin's tests run (like scikit-learn's ``check_estimator``).

Each ``check_*`` raises ``AssertionError`` with a message naming the broken promise.
Plugin authors call them from their own tests; pytest fixtures come from
:mod:`physinfer.testing.fixtures`, published through the ``pytest11`` entry point.
:func:`check_effect` checks one effect (:mod:`physinfer.testing.effects`);
:func:`embedding_sensitivity` measures whether the embedder can tell the parameters apart
(:mod:`physinfer.testing.sensitivity`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.parameters import ParameterSpace
from physinfer.plugins import load_registry
from physinfer.registry import Registry
from physinfer.roles import Embedder, Phenomenon, Renderer, Simulator, Target
from physinfer.testing.effects import check_effect, effects_of
from physinfer.testing.sensitivity import embedding_sensitivity
from physinfer.types import Clip, Trajectory

__all__ = [
    "check_effect",
    "check_embedder",
    "check_phenomenon",
    "check_renderer",
    "check_simulator",
    "embedding_sensitivity",
]


def check_simulator(simulator: Simulator, params: Mapping[str, float] | None = None) -> Trajectory:
    """Check the Simulator contract; returns the trajectory of ``params`` (default: defaults).

    Checks: a :class:`ParameterSpace`; a valid finite :class:`Trajectory`; determinism for a
    fixed seed; ``simulate_batch`` agrees with ``simulate``; the normalised centre and
    corners of the space simulate without NaN.
    """
    space = simulator.parameter_space
    assert isinstance(space, ParameterSpace), "simulator.parameter_space must be a ParameterSpace"
    params = dict(params) if params is not None else space.defaults()
    traj = simulator.simulate(params, seed=0)
    assert isinstance(traj, Trajectory), "simulate() must return a Trajectory"
    assert traj.n_frames >= 2, "a trajectory needs at least two frames"
    assert traj.is_finite(), "trajectory has NaN/inf vertices at the default parameters"
    again = simulator.simulate(params, seed=0)
    np.testing.assert_array_equal(
        traj.vertices, again.vertices, err_msg="simulate() is not deterministic for a seed"
    )
    batch = simulator.simulate_batch([params, params], seeds=[0, 0])
    assert len(batch) == 2, "simulate_batch must return one trajectory per parameter set"
    np.testing.assert_allclose(
        batch[0].vertices,
        traj.vertices,
        atol=1e-4,
        err_msg="simulate_batch disagrees with simulate",
    )
    for corner in (-1.0, 1.0):
        extreme = space.from_unit(np.full(len(space), corner))
        assert simulator.simulate(extreme, seed=1).is_finite(), (
            f"NaN at the corner {corner:+} of the space"
        )
    return traj


def check_renderer(
    renderer: Renderer, trajectory: Trajectory, render_params: Mapping[str, Any] | None = None
) -> Clip:
    """Check the Renderer contract; returns the rendered clip.

    Checks: a :class:`Clip` of uint8 RGB frames, one per trajectory frame, at its fps;
    determinism for fixed ζ; not a blank image.
    """
    clip = renderer.render(trajectory, render_params)
    assert isinstance(clip, Clip), "render() must return a Clip"
    assert clip.n_frames == trajectory.n_frames, "one frame per trajectory frame"
    assert clip.frames.shape[3] == 3, "frames must be RGB"
    assert abs(clip.fps - trajectory.fps) < 1e-9, "the clip keeps the trajectory's fps"
    assert clip.frames.std() > 1.0, "the render is blank"
    again = renderer.render(trajectory, render_params)
    np.testing.assert_array_equal(
        clip.frames, again.frames, err_msg="render() is not deterministic for fixed ζ"
    )
    return clip


def check_embedder(embedder: Embedder, clip: Clip) -> np.ndarray:
    """Check the Embedder contract; returns the embedding of ``clip``.

    Checks: a finite 1-D float vector; determinism; ``embed_many`` shape; a clip shorter
    than ``n_frames`` is refused with :class:`UserInputError`.
    """
    e = embedder.embed(clip)
    assert isinstance(e, np.ndarray) and e.ndim == 1 and e.size > 0, (
        "embed() must return a (D_e,) array"
    )
    assert np.isfinite(e).all(), "embedding has NaN/inf"
    np.testing.assert_allclose(
        embedder.embed(clip), e, rtol=1e-5, atol=1e-6, err_msg="embed() not deterministic"
    )
    assert embedder.embed_many([clip, clip]).shape == (2, e.size), "embed_many must return (N, D_e)"
    short = Clip(clip.frames[:2], clip.fps)
    try:
        embedder.embed(short)
    except UserInputError:
        pass
    else:
        raise AssertionError("a 2-frame clip must be refused with UserInputError")
    return e


def check_phenomenon(
    phenomenon: Phenomenon, embedder: Embedder, *, registry: Registry | None = None
) -> None:
    """Check a Phenomenon end to end: its parts' contracts, its effects and its default target.

    The default target's truth must lie inside the parameter space and re-simulating it
    must reproduce the target exactly (distance 0) in embedding space. Every effect
    registered for the phenomenon (or named in its ``effects``) passes :func:`check_effect`
    at that truth, and no two effects share a parameter name.

    Args:
        phenomenon: The record to check.
        embedder: The embedder to check the default target with (usually its default one).
        registry: Where its effects are registered (default: a freshly loaded registry of
            every installed plugin).
    """
    if registry is None:
        registry, _ = load_registry()
    assert isinstance(phenomenon.parameter_space, ParameterSpace)
    simulator = phenomenon.make_simulator(())
    target = phenomenon.default_target()
    assert isinstance(target, Target), "default_target() must return a Target"
    assert target.truth is not None, "the embedded default target must carry its ground truth"
    phenomenon.parameter_space.complete(target.truth)  # inside the bounds
    traj = check_simulator(simulator, target.truth)
    owners: dict[str, str] = {}
    for name in effects_of(phenomenon, registry):
        effect = check_effect(
            phenomenon, name, registry=registry, params=target.truth, baseline=traj
        )
        for param in effect.parameter_space.names:
            assert param not in owners, (
                f"effects {owners[param]!r} and {name!r} share the parameter {param!r}"
            )
            owners[param] = name
    renderer = phenomenon.make_renderer()
    clip = check_renderer(renderer, traj, target.render_params)
    e_target = check_embedder(embedder, target.clip)
    e_again = embedder.embed(clip)
    assert float(np.sum((e_target - e_again) ** 2)) < 1e-6 * (1 + float(np.sum(e_target**2))), (
        "re-simulating the default target's truth must reproduce its embedding"
    )
    renderer.close()
