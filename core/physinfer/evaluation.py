"""Trial evaluation: simulate θ, render it with ζ, embed the clip, measure the distance.

The loop (:mod:`physinfer.loop`), the noise floor (:mod:`physinfer.noise`), the trial
workers (:mod:`physinfer.trial_workers`) and the diagnosis all evaluate trials through these
functions; they sit below all of them. A simulation that raises, returns NaN or blows up is a
failed trial (an error string), never an exception: it is a property of θ, not a bug.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from physinfer.roles import Effect, Embedder, Phenomenon, Renderer, Simulator
from physinfer.types import Clip, Trajectory


class ClipWorkers(Protocol):
    """Simulates and renders a step's jobs elsewhere (:class:`~physinfer.trial_workers.TrialWorkers`)."""

    def clips(
        self,
        params: Sequence[Mapping[str, float]],
        seeds: Sequence[int],
        render_params: Mapping[str, Any],
    ) -> list[tuple[Clip | None, str | None, dict[str, float]]]:
        """Job ``j`` = ``(params[j], seeds[j])`` as :func:`make_clips` makes it here; in order."""
        ...


@dataclass
class Pipeline:
    """The built roles of one phenomenon for one run.

    ``workers``, when set, simulates and renders the trials of each step on an executor
    (:class:`ClipWorkers`, attached by :func:`physinfer.trial_workers.trial_workers`)
    instead of in this process.
    """

    phenomenon: Phenomenon
    simulator: Simulator
    renderer: Renderer
    embedder: Embedder
    effects: Sequence[Effect] = ()
    workers: ClipWorkers | None = None


def squared_distance(a: np.ndarray, b: np.ndarray) -> float:
    """``||a - b||²``, the paper's distance."""
    return float(np.sum((np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)) ** 2))


NON_FINITE = "the simulation produced NaN or infinite positions"
NON_FINITE_DISTANCE = "the embedding distance is not finite"


def simulate_one(simulator: Simulator, params: Mapping[str, float], seed: int) -> tuple[Trajectory | None, str | None]:
    """One simulation as ``(trajectory, None)``, or ``(None, reason)`` when it fails.

    Any exception of the simulator is a property of this θ (a blow-up, an unstable
    setting), not a bug of the loop, so it becomes a failed trial.
    """
    try:
        trajectory = simulator.simulate(params, seed=seed)
    except Exception as exc:
        return None, f"{type(exc).__name__}: {exc}"
    if not trajectory.is_finite():
        return None, NON_FINITE
    return trajectory, None


def simulate_many(
    simulator: Simulator, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
) -> list[tuple[Trajectory | None, str | None]]:
    """:func:`simulate_one` for ``B`` jobs, through the simulator's batched engine.

    A batch call fails as a whole when one member fails; only then are the jobs simulated
    one by one, to learn which failed and why (failures are rare, so the batch's speed is
    kept in the common case).
    """
    try:
        trajectories = simulator.simulate_batch(params, seeds=seeds)
    except Exception:
        return [simulate_one(simulator, p, s) for p, s in zip(params, seeds, strict=True)]
    return [(t, None) if t.is_finite() else (None, NON_FINITE) for t in trajectories]


#: Simulates, renders and embeds clips elsewhere (a diagnosis's idle workers): ``(θ list,
#: seeds)`` → one embedding per pair, ``None`` for a failed simulation, each what
#: :func:`simulate_and_embed` gives here (the same simulator, ζ and embedder).
ClipEmbedder = Callable[[Sequence[Mapping[str, float]], Sequence[int]], "list[np.ndarray | None]"]


def simulate_and_embed(
    pipeline: Pipeline,
    params: Mapping[str, float],
    render_params: Mapping[str, Any],
    seed: int,
) -> tuple[np.ndarray | None, str | None, dict[str, float]]:
    """Simulate, render and embed one θ; returns ``(embedding, error, timings)``.

    A failing simulation gives ``(None, reason, timings)``; render and embed errors
    propagate (they are not properties of θ).
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    trajectory, error = simulate_one(pipeline.simulator, params, seed)
    if trajectory is None:
        timings["simulate"] = time.perf_counter() - t0
        return None, error, timings
    t1 = time.perf_counter()
    clip = pipeline.renderer.render(trajectory, render_params)
    t2 = time.perf_counter()
    embedding = np.asarray(pipeline.embedder.embed(clip))
    timings.update(simulate=t1 - t0, render=t2 - t1, embed=time.perf_counter() - t2)
    return embedding, None, timings


def evaluate(
    pipeline: Pipeline,
    params: Mapping[str, float],
    target_embedding: np.ndarray,
    render_params: Mapping[str, Any],
    seed: int,
) -> tuple[float | None, str | None, dict[str, float]]:
    """:func:`simulate_and_embed` and the distance to the target: ``(distance, error, timings)``."""
    embedding, error, timings = simulate_and_embed(pipeline, params, render_params, seed)
    if embedding is None:
        return None, error, timings
    distance = squared_distance(embedding, target_embedding)
    if not np.isfinite(distance):
        return None, NON_FINITE_DISTANCE, timings
    return distance, None, timings


def evaluate_mean(
    pipeline: Pipeline,
    params: Mapping[str, float],
    target_embedding: np.ndarray,
    render_params: Mapping[str, Any],
    seeds: Sequence[int],
) -> tuple[float | None, str | None, dict[str, float]]:
    """:func:`evaluate` under each seed; the mean distance (failed if any seed fails)."""
    distances, totals = [], {}
    for seed in seeds:
        distance, error, timings = evaluate(pipeline, params, target_embedding, render_params, seed)
        for phase, seconds in timings.items():
            totals[phase] = totals.get(phase, 0.0) + seconds
        if distance is None:
            return None, error, totals
        distances.append(distance)
    return float(np.mean(distances)), None, totals


def evaluate_batch(
    pipeline: Pipeline,
    params: Sequence[Mapping[str, float]],
    target_embedding: np.ndarray,
    render_params: Mapping[str, Any],
    seeds: Sequence[int],
) -> list[tuple[float | None, str | None, dict[str, float]]]:
    """:func:`evaluate_mean` of ``q`` θ, simulated as one batch and embedded together.

    Every θ is simulated under every seed and rendered (:func:`make_clips`); the clips are
    embedded with ``embed_many``. A θ's timings are its simulate and render time (its
    share of a batched simulation) plus its share of the embedding time. One θ in this
    process takes the sequential path (:func:`evaluate_mean`), so ``batch_size=1`` runs
    exactly as before.

    Returns:
        One ``(distance, error, timings)`` per θ, in order.
    """
    if len(params) == 1 and pipeline.workers is None:
        return [evaluate_mean(pipeline, params[0], target_embedding, render_params, seeds)]
    jobs = [(i, seed) for i in range(len(params)) for seed in seeds]
    made = make_clips(pipeline, [params[i] for i, _ in jobs], [seed for _, seed in jobs], render_params)
    timings = [{"simulate": 0.0, "render": 0.0, "embed": 0.0} for _ in params]
    errors: list[str | None] = [None] * len(params)
    clips, owners = [], []
    for (i, _), (clip, error, job_timings) in zip(jobs, made, strict=True):
        for phase, seconds in job_timings.items():
            timings[i][phase] += seconds
        if errors[i] is not None:
            continue
        if clip is None:
            errors[i] = error  # failed if any seed fails, as evaluate_mean
            continue
        clips.append(clip)
        owners.append(i)
    t2 = time.perf_counter()
    embeddings = np.asarray(pipeline.embedder.embed_many(clips)) if clips else np.empty((0, 0))
    embed_s = (time.perf_counter() - t2) / max(len(clips), 1)
    distances: list[list[float]] = [[] for _ in params]
    for i, embedding in zip(owners, embeddings, strict=True):
        timings[i]["embed"] += embed_s
        distances[i].append(squared_distance(embedding, target_embedding))
    results = []
    for i in range(len(params)):
        distance = None if errors[i] is not None else float(np.mean(distances[i]))
        if distance is not None and not np.isfinite(distance):
            distance, errors[i] = None, NON_FINITE_DISTANCE
        results.append((distance, errors[i], timings[i]))
    return results


def make_clips(
    pipeline: Pipeline,
    params: Sequence[Mapping[str, float]],
    seeds: Sequence[int],
    render_params: Mapping[str, Any],
) -> list[tuple[Clip | None, str | None, dict[str, float]]]:
    """Simulate and render job ``j`` = ``(params[j], seeds[j])``: ``(clip, error, timings)``.

    On the pipeline's workers when it has them; otherwise all jobs in one
    :func:`simulate_many` call (each job's simulate time is its share of the batch) and
    rendered here one by one. A failed simulation gives ``(None, reason, timings)``.
    """
    if pipeline.workers is not None:
        return pipeline.workers.clips(params, seeds, render_params)
    t0 = time.perf_counter()
    simulated = simulate_many(pipeline.simulator, params, seeds)
    simulate_s = (time.perf_counter() - t0) / max(len(params), 1)
    made: list[tuple[Clip | None, str | None, dict[str, float]]] = []
    for trajectory, error in simulated:
        if trajectory is None:
            made.append((None, error, {"simulate": simulate_s}))
            continue
        t1 = time.perf_counter()
        clip = pipeline.renderer.render(trajectory, render_params)
        made.append((clip, None, {"simulate": simulate_s, "render": time.perf_counter() - t1}))
    return made
