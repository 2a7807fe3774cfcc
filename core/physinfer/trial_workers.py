"""Simulate and render refinement trials on worker processes or a Dask cluster.

``physinfer refine --workers K`` (local processes) or ``--scheduler ADDRESS`` (a Dask
cluster) sends every simulation of a step — its ``--batch-size`` trials times
``--seeds-per-trial`` seeds — to the dataset engine's executor
(:func:`physinfer.datasets.open_executor`) as one job each. A worker builds the
phenomenon's simulator and renderer from a :class:`PipelineSpec` through its own plugin
registry, once per process and thread (EGL contexts belong to a thread, and a Dask worker
runs tasks in several), then simulates and renders and returns the clip. Embedding stays
in the refinement's process: the embedder (torch, weights) is loaded once there and
embeds the whole batch together, and only clips cross the wire.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import Executor
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from typing import Any

from physinfer.datasets.executors import limit_threads, open_executor
from physinfer.evaluation import build_pipeline, simulate_one
from physinfer.plugins import load_registry
from physinfer.types import Clip
from physinfer.worker_cache import thread_cached


@dataclass(frozen=True)
class PipelineSpec:
    """What a worker needs to rebuild a phenomenon's simulator and renderer.

    Attributes:
        plugin: Phenomenon name (installed on every worker).
        effects: Effect names switched in.
        fixed: ``NAME=VALUE`` items held fixed (``refine --fix``).
        duration_s: Seconds each simulation records (``refine --duration``; ``None``:
            the phenomenon's default).
        scene: The scene's settings as ``(name, value)`` pairs (``refine --scene-set``,
            :func:`scene_items`; ``None``: the phenomenon's default scene).
        threads: Thread cap per worker process for numerical libraries and llvmpipe
            (``None``: leave the process as it is).
    """

    plugin: str
    effects: tuple[str, ...] = ()
    fixed: tuple[str, ...] = ()
    duration_s: float | None = None
    scene: tuple[tuple[str, Any], ...] | None = None
    threads: int | None = 1


def scene_items(scene: Mapping[str, Any] | None) -> tuple[tuple[str, Any], ...] | None:
    """A scene as hashable ``(name, value)`` pairs for :class:`PipelineSpec` (``None`` stays)."""
    return None if scene is None else tuple(sorted(scene.items()))


def worker_pipeline(spec: PipelineSpec) -> Any:
    """The simulator and renderer of ``spec`` in this worker thread, built on first use."""

    def build() -> Any:
        if spec.threads is not None:
            limit_threads(spec.threads)
        registry, _ = load_registry()
        return build_pipeline(
            registry, spec.plugin, effects=spec.effects, embedder="", fixed=spec.fixed, duration_s=spec.duration_s,
            scene_set=dict(spec.scene) if spec.scene is not None else None,
        )  # fmt: skip

    return thread_cached("refine.trial_pipelines", spec, build)


def simulate_and_render(
    spec: PipelineSpec, params: Mapping[str, float], seed: int, render_params: Mapping[str, Any]
) -> tuple[Clip | None, str | None, dict[str, float]]:
    """One job, run in a worker: ``(clip, None, timings)`` or ``(None, reason, timings)``.

    A failing simulation is a property of θ and comes back as its reason; a render error
    is not and raises (in the refinement, through the future).
    """
    pipeline = worker_pipeline(spec)
    t0 = time.perf_counter()
    trajectory, error = simulate_one(pipeline.simulator, params, seed)
    t1 = time.perf_counter()
    if trajectory is None:
        return None, error, {"simulate": t1 - t0}
    clip = pipeline.renderer.render(trajectory, render_params)
    return clip, None, {"simulate": t1 - t0, "render": time.perf_counter() - t1}


class TrialWorkers:
    """Runs a refinement's simulate-and-render jobs on an executor.

    Args:
        executor: A :class:`concurrent.futures.Executor` (local processes, a Dask
            client's executor, or an inline one for tests).
        spec: The pipeline every job runs.
    """

    def __init__(self, executor: Executor, spec: PipelineSpec) -> None:
        self.executor = executor
        self.spec = spec

    def clips(
        self,
        params: Sequence[Mapping[str, float]],
        seeds: Sequence[int],
        render_params: Mapping[str, Any],
    ) -> list[tuple[Clip | None, str | None, dict[str, float]]]:
        """Simulate and render job ``j`` = ``(params[j], seeds[j])``; results in order."""
        zeta = dict(render_params)
        futures = [
            self.executor.submit(simulate_and_render, self.spec, dict(p), int(s), zeta)
            for p, s in zip(params, seeds, strict=True)
        ]
        return [future.result() for future in futures]


@contextmanager
def trial_workers(
    pipeline: Any, spec: PipelineSpec, *, workers: int | None, scheduler: str | None
) -> Iterator[dict[str, Any] | None]:
    """Attach :class:`TrialWorkers` to ``pipeline`` for the block; yield what runs them.

    Nothing is attached when neither ``workers`` nor ``scheduler`` is given (the trials
    run in this process, as by default). ``workers=0`` sends the jobs through the same
    path in this process (debugging).

    Yields:
        ``{"kind", "workers", "threads", "address"}`` of the executor, or ``None``.
    """
    if workers is None and scheduler is None:
        yield None
        return

    with open_executor(workers=workers, scheduler=scheduler, threads_per_worker=spec.threads or 1) as (
        executor,
        info,
    ):
        if info.kind == "inline":  # this very process: its thread settings are not the worker's to cap
            spec = replace(spec, threads=None)
        pipeline.workers = TrialWorkers(executor, spec)
        try:
            yield asdict(info)
        finally:
            pipeline.workers = None
