"""One clip per job on the diagnosis' workers: the ladders' probe (:class:`PooledProbe`).

The screen and the detection limits simulate, at θ̂, each candidate's ladder and the base
parameters' refits to it: for each effect a chain of small batches (a rung's seeds, a
refit's points), each batch depending on the one before. Sent whole to a worker, one chain
per job, the longest chain ran alone at the end while the other worker idled — on a clean
flag target the detectable effect's (refits measured at three rungs) took 84 s of the
stage's 118 s after the other two had finished side by side in 29 s. Here each effect's
chain runs in a thread of this process (:func:`concurrently`) and every clip of it is a job
of its own (simulate, render and embed at ζ on a worker), so a worker takes whichever clip
comes next, from any chain.

The results are those of one process, bit for bit: a clip depends only on the model, θ and
its seed, and each is embedded on its own, as :class:`~physinfer.discrepancy.ladder.Probe`
does (checked: a batch's members equal single simulations, and an embedding does not
depend on the batch or torch's thread count).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from physinfer import video
from physinfer.discrepancy.candidates import augmented_pipeline
from physinfer.discrepancy.ladder import Probe, ProbeFactory, stack_rows
from physinfer.discrepancy.parallel import WorkerPool, worker_pipeline
from physinfer.evaluation import (
    ClipEmbedder,
    Pipeline,
    fixed_by_user,
    simulate_and_embed,
    simulate_many,
)
from physinfer.threads import refinement_torch_threads, torch_threads
from physinfer.worker_cache import thread_cached

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings

Log = Callable[[str], None]
T = TypeVar("T")
R = TypeVar("R")


@dataclass(frozen=True)
class ClipJob:
    """One clip for a worker (plain data: it rebuilds the model once and keeps it).

    Attributes:
        settings: The diagnosis settings (the worker's baseline model).
        render_params: ζ.
        effects: Names of the effects switched in (empty: the baseline).
        params: θ, with the effects' parameters.
        seed: The simulation seed.
        keep_trajectory: Send the trajectory back too (another view's what-if re-renders it).
        as_embedded: Send the embedding back as the embedder gave it (else as float64).
        encoded: Send the clip through the video encoder and back before it is embedded
            (:meth:`~physinfer.discrepancy.ladder.Probe.encoded_clips`).
    """

    settings: DiagnoseSettings
    render_params: Mapping[str, Any]
    effects: tuple[str, ...]
    params: Mapping[str, float]
    seed: int
    keep_trajectory: bool = False
    as_embedded: bool = False
    encoded: bool = False


def run_clip_job(job: ClipJob) -> tuple[np.ndarray | None, Any, float | None]:
    """Simulate, render and embed one clip in this (worker) process: its embedding (``None``
    for a failed simulation), its trajectory (when kept) and the seconds it records."""
    registry, base = worker_pipeline(job.settings)
    model = _model(registry, base, job.settings, job.effects)
    trajectory, _ = simulate_many(model.simulator, [dict(job.params)], [int(job.seed)])[0]
    if trajectory is None:
        return None, None, None
    with torch_threads(refinement_torch_threads()):
        clip = base.renderer.render(trajectory, job.render_params)
        clip = video.round_trip(clip) if job.encoded else clip
        embedding = np.asarray(base.embedder.embed(clip), dtype=None if job.as_embedded else np.float64)
    return embedding, trajectory if job.keep_trajectory else None, trajectory.duration


def _model(registry: Any, base: Pipeline, settings: DiagnoseSettings, effects: tuple[str, ...]) -> Pipeline:
    """``base`` with ``effects`` switched in, built once per worker thread."""
    if not effects:
        return base

    def build() -> Pipeline:
        # Effects are registered under the phenomenon's own name (bench_diagnose's flag_lite is "flag").
        objs = [registry.effect(name, phenomenon=base.phenomenon.name) for name in effects]
        return augmented_pipeline(base, objs, settings.duration_s, fixed_by_user(base, settings.fixed))

    return thread_cached("diagnose.effect_models", (id(base), effects), build)


class PooledProbe(Probe):
    """A :class:`Probe` whose clips are simulated, rendered and embedded on ``executor``'s
    workers, one job per clip (its other methods still run here).

    Args:
        base: The baseline pipeline (here: its parameter space; on the workers: rebuilt).
        render_params: ζ.
        executor: The diagnosis pool's executor.
        settings: What the workers rebuild the models from.
        keep_trajectories: Bring every trajectory back (another view's what-if needs them).
    """

    def __init__(
        self,
        base: Pipeline,
        render_params: Mapping[str, Any],
        executor: Executor,
        settings: DiagnoseSettings,
        keep_trajectories: bool = False,
    ) -> None:
        super().__init__(base, render_params)
        self.executor = executor
        self.settings = settings
        self.keep_trajectories = keep_trajectories

    def clips(
        self, model: Pipeline, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
    ) -> tuple[np.ndarray, list[Any]]:
        """As :meth:`Probe.clips`, on the workers; a job that fails there raises here."""
        return self._on_workers(model, params, seeds, encoded=False)

    def encoded_clips(
        self, model: Pipeline, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
    ) -> tuple[np.ndarray, list[Any]]:
        """As :meth:`Probe.encoded_clips`, on the workers (this process' threads must not
        render: an OpenGL context made current in one stays bound to it)."""
        return self._on_workers(model, params, seeds, encoded=True)

    def _on_workers(
        self, model: Pipeline, params: Sequence[Mapping[str, float]], seeds: Sequence[int], *, encoded: bool
    ) -> tuple[np.ndarray, list[Any]]:
        effects = tuple(effect.name for effect in model.effects)
        futures = [
            self.executor.submit(
                run_clip_job,
                ClipJob(self.settings, self.render_params, effects, dict(p), int(s), self.keep_trajectories,
                        encoded=encoded),
            )
            for p, s in zip(params, seeds, strict=True)
        ]  # fmt: skip
        results = [future.result() for future in futures]
        self.simulations += len(params)
        if self.clip_seconds is None:
            self.clip_seconds = next((sec for _, _, sec in results if sec is not None), None)
        return stack_rows([emb for emb, _, _ in results]), [traj for _, traj, _ in results]


def pooled_probes(pool: WorkerPool | None, base: Pipeline, render_params: Mapping[str, Any]) -> ProbeFactory | None:
    """Probes whose clips run on the pool's workers, one job per clip (``None``: it has one
    worker or fewer)."""
    if pool is None or pool.size < 2:
        return None
    executor, settings = pool.executor(), pool.settings
    return lambda keep: PooledProbe(base, render_params, executor, settings, keep_trajectories=keep)


def pooled_clip_embedder(
    pool: WorkerPool | None, base: Pipeline, render_params: Mapping[str, Any], say: Log
) -> ClipEmbedder | None:
    """The baseline model's clips at ζ made on the pool's workers, one job per clip (``None``:
    it has one worker or fewer): the baseline's selection and gap, which would otherwise
    run one clip at a time here while the workers wait for the first round.

    The numbers are those made here (a clip depends only on θ and its seed, and the
    embedding comes back as the embedder gave it); if the workers fail, the clips are made
    here instead.
    """
    if pool is None or pool.size < 2:
        return None
    executor, settings = pool.executor(), pool.settings

    def embed(params: Sequence[Mapping[str, float]], seeds: Sequence[int]) -> list[np.ndarray | None]:
        jobs = [ClipJob(settings, render_params, (), dict(p), int(s), as_embedded=True) for p, s in zip(params, seeds, strict=True)]
        try:
            return [future.result()[0] for future in [executor.submit(run_clip_job, job) for job in jobs]]
        except Exception as exc:  # noqa: BLE001 - made here instead, as without workers
            say(f"      re-simulations failed on a worker ({type(exc).__name__}: {exc}); running them here")
            return [simulate_and_embed(base, p, render_params, s)[0] for p, s in zip(params, seeds, strict=True)]

    return embed


def concurrently(
    function: Callable[[T], R], items: Sequence[T], labels: Sequence[str], say: Log
) -> list[R | None]:
    """``function(item)`` for every item, each in a thread of its own (their clips go to the
    workers as they come); ``None`` for an item whose call raised (its ``label`` is said),
    for the caller to run again without the workers."""
    if not items:
        return []
    with ThreadPoolExecutor(max_workers=len(items), thread_name_prefix="physinfer-chain") as threads:
        futures = [threads.submit(function, item) for item in items]
        results: list[R | None] = []
        for label, future in zip(labels, futures, strict=True):
            try:
                results.append(future.result())
            except Exception as exc:  # noqa: BLE001 - the caller runs it here instead
                say(f"      {label} failed on a worker ({type(exc).__name__}: {exc}); running it here")
                results.append(None)
    return results
