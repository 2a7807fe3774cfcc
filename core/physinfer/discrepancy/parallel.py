"""Run a diagnosis' independent stages side by side on worker processes (or a Dask cluster).

After the baseline, a diagnosis refines the control, one augmented model per effect and the
self-consistency runs it needs (each followed by its control; see
:mod:`physinfer.discrepancy.self_consistency`). None needs another's result: all start
from the baseline's fit. :func:`prefetch_stages` sends them as jobs to
:func:`physinfer.datasets.open_executor` — ``workers`` local processes, or the workers of a
Dask scheduler — where :func:`run_job` runs the same stage functions
(:mod:`physinfer.discrepancy.stages`) the workflow runs, into the same directories. The
workflow then goes through its stages in order as before and finds each finished on disk,
so the decisions are those of a diagnosis run in one process (each stage's optimizer and
simulations are seeded by the stage alone).

A job that fails on a worker is only reported: the workflow runs that stage itself and
meets the failure (or not) where it would have without workers.

The screen's and the detection limits' ladders use the same workers one clip at a time
(:func:`physinfer.discrepancy.clip_jobs.pooled_probes`): every clip has its own seed,
so the limits do not depend on where they ran. One :class:`WorkerPool` serves every round of
a diagnosis (the stages, the self-consistency runs the decisions ask for, the ladders): its
processes start once and keep the models they built.

Workers build the plugins from their entry points (:func:`physinfer.plugins.load_registry`),
or with the settings' ``registry_factory`` when one is given: a registry assembled in code
(a notebook registering a phenomenon by hand) cannot be rebuilt otherwise, so
:func:`usable_workers` falls back to one process for a plugin not installed.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.datasets.executors import default_workers, open_executor
from physinfer.discrepancy.progress import StageClock
from physinfer.discrepancy.stages import (
    GapContext,
    ablated_stage,
    build_base,
    calibration_run,
    calibration_stage_names,
    control_stage,
    effect_stage,
)
from physinfer.plugins import load_registry
from physinfer.progress import StageProgress
from physinfer.roles import Target
from physinfer.scene import SceneRegistry
from physinfer.threads import refinement_torch_threads, torch_threads
from physinfer.worker_cache import thread_cached

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings

Log = Callable[[str], None]

#: Seconds between looks at the stages' trial logs for the progress display.
POLL_S = 0.5


@dataclass(frozen=True)
class StageJob:
    """One independent unit of a diagnosis: a calibration run (with its control), the
    control, or one effect's model.

    Attributes:
        kind: ``"calibration"``, ``"control"`` or ``"effect"``.
        key: The calibration run's index, or the effect's name (``""`` for the control).
        settings: The diagnosis settings.
        baseline_best: The baseline's best θ, where every job starts from.
        target: The target (clip, ζ, truth).
        target_embedding: Its embedding (the gaps are measured against it).
        seeds: The gap measurements' re-simulation seeds.
        steps: The baseline's budget (a calibration run's).
        effect_steps: The control's and each model's budget.
        target_label: Stored in each stage's ``run.json``.
        with_control: A calibration job refines the run's control too (when the settings
            give runs controls); ``False``: the run's own stage only.
    """

    kind: str
    key: int | str
    settings: DiagnoseSettings
    baseline_best: Mapping[str, float]
    target: Target
    target_embedding: np.ndarray
    seeds: tuple[int, ...]
    steps: int
    effect_steps: int
    target_label: str
    with_control: bool = True

    @property
    def stages(self) -> list[tuple[str, int]]:
        """``(directory, trials)`` of each stage the job writes, in order."""
        if self.kind == "calibration":
            names = calibration_stage_names(int(self.key), self.settings)[: None if self.with_control else 1]
            return [
                (name, self.steps if i == 0 else self.effect_steps) for i, name in enumerate(names)
            ]
        return [("control" if self.kind == "control" else f"effect-{self.key}", self.effect_steps)]


def stage_jobs(
    settings: DiagnoseSettings,
    effects: Sequence[str],
    *,
    baseline_best: Mapping[str, float],
    target: Target,
    target_embedding: np.ndarray,
    seeds: Sequence[int],
    steps: int,
    effect_steps: int,
    target_label: str,
    calibration: Sequence[tuple[int, bool]] | None = None,
    control_and_effects: bool = True,
) -> list[StageJob]:
    """The jobs after the baseline, the longest first (a calibration run and its control
    take two stages' time), so the last to finish is a short one.

    ``calibration``: ``(run, with_control)`` of the self-consistency jobs (``None``: every
    run with its control, as ``settings`` asks); ``control_and_effects``: also the control
    and one job per effect."""
    common = {
        "settings": settings, "baseline_best": dict(baseline_best), "target": target,
        "target_embedding": np.asarray(target_embedding), "seeds": tuple(int(s) for s in seeds),
        "steps": steps, "effect_steps": effect_steps, "target_label": target_label,
    }  # fmt: skip
    if calibration is None:
        calibration = [(r, True) for r in range(settings.calibration_runs)] if settings.calibrate else []
    jobs = [StageJob("calibration", r, **common, with_control=control) for r, control in calibration]
    if control_and_effects:
        jobs.append(StageJob("control", "", **common))
        jobs += [StageJob("effect", name, **common) for name in effects]
    return sorted(jobs, key=lambda job: -sum(trials for _, trials in job.stages))


def run_job(job: StageJob) -> dict[str, float]:
    """Run one job in this (worker) process; the seconds each of its stages took."""
    registry, base = worker_pipeline(job.settings)
    common = {"registry": registry, "settings": job.settings}
    gaps = GapContext(job.target, job.target_embedding, job.seeds, job.settings.out)
    start = time.perf_counter()
    with torch_threads(refinement_torch_threads()):
        if job.kind == "calibration":
            calibration_run(
                int(job.key), base, job.baseline_best, job.target, steps=job.steps, effect_steps=job.effect_steps,
                seeds=job.seeds, with_control=job.with_control, **common,
            )  # fmt: skip
        elif job.kind == "control":
            control_stage(base, job.target, job.baseline_best, gaps, effect_steps=job.effect_steps,
                          target_label=job.target_label, **common)  # fmt: skip
        else:
            # Effects are registered under the phenomenon's own name, which a phenomenon
            # registered under another (bench_diagnose's flag_lite is "flag") does not share.
            effect = registry.effect(str(job.key), phenomenon=base.phenomenon.name)
            stage = effect_stage(
                str(job.key), effect, base, job.target, job.baseline_best, gaps, effect_steps=job.effect_steps,
                target_label=job.target_label, **common,
            )  # fmt: skip
            ablated_stage(stage, base, gaps)
    # One figure for the job, under its first stage: a calibration run's control ran after it.
    return {job.stages[0][0]: time.perf_counter() - start}


def worker_pipeline(settings: DiagnoseSettings) -> tuple[Any, Any]:
    """The registry and baseline model of ``settings`` in this worker thread, built once."""
    key = (
        settings.plugin, settings.embedder, str(settings.weights), settings.device, settings.duration_s,
        settings.embedder_frames, settings.fixed, tuple(sorted(settings.scene_set.items())),
        repr(settings.registry_factory),
    )  # fmt: skip

    def build() -> tuple[Any, Any]:
        registry = scene_registry(_installed(settings), settings)
        return registry, build_base(registry, settings)

    return thread_cached("diagnose.baselines", key, build)


def warm_worker(settings: DiagnoseSettings) -> None:
    """Build this worker's model and one optimizer (the imports, the embedder's weights), so
    that its first job does not pay for them; what it builds, :func:`worker_pipeline` keeps."""
    registry, _ = worker_pipeline(settings)
    registry.get("optimizers", settings.optimizer).load()(dim=1, seed=0, names=["warm_up"])


def _installed(settings: DiagnoseSettings) -> Any:
    """The registry a worker can build: the settings' factory's, or the installed plugins'."""
    if settings.registry_factory is not None:
        return settings.registry_factory()

    return load_registry()[0]


def scene_registry(registry: Any, settings: DiagnoseSettings) -> Any:
    """``registry`` with the diagnosed phenomenon bound to the settings' scene, if any."""
    if not settings.scene_set:
        return registry

    return SceneRegistry(registry, settings.plugin, dict(settings.scene_set))


def usable_workers(
    settings: DiagnoseSettings, n_jobs: int, effects: Sequence[str]
) -> tuple[int, str | None]:
    """How many workers to use, and why not more (``None`` when nothing held them back).

    ``settings.workers`` ``None`` means one per CPU; never more than there are jobs. Workers
    need the plugin and every effect installed as entry points (see the module docstring).
    """
    if settings.scheduler:
        return max(1, n_jobs), None

    wanted = default_workers() if settings.workers is None else settings.workers
    workers = min(wanted, n_jobs)
    if workers < 2:
        return 1, None
    try:
        installed = _installed(settings)
        phenomenon = installed.phenomenon(settings.plugin).name
        for name in effects:
            installed.effect(name, phenomenon=phenomenon)
    except Exception:  # noqa: BLE001 - any failure means a worker could not rebuild the model
        return (
            1,
            f"{settings.plugin} or one of its effects is not installed as a plugin: stages run in this process",
        )
    return workers, None


class WorkerPool:
    """The worker processes of one diagnosis, started at their first job and kept until it
    ends, so each round of jobs (the stages after the baseline, the self-consistency runs
    asked for later, the detection limits' ladders) does not pay again for the processes'
    start: the imports and each worker's model (:func:`worker_pipeline` keeps it).

    Args:
        settings: The diagnosis settings (``workers``, ``scheduler``).
        effects: The candidate effects (workers must be able to build them).
        most_jobs: The most jobs any round sends: more workers than that would idle.
        say: Where a reason for one process is said.
    """

    def __init__(self, settings: DiagnoseSettings, effects: Sequence[str], most_jobs: int, say: Log) -> None:
        self.settings = settings
        self.size, why_not = usable_workers(settings, most_jobs, effects)
        if why_not:
            say(f"      {why_not}")
        self.why_one_process = why_not
        self._stack = ExitStack()
        self._executor: Executor | None = None

    def executor(self) -> Executor:
        """The pool's executor, started on the first call."""
        if self._executor is None:
            self._executor, _ = self._stack.enter_context(
                open_executor(workers=self.size, scheduler=self.settings.scheduler, threads_per_worker=1)
            )
        return self._executor

    def warm_up(self) -> list[Future]:
        """Start the local workers now, each building its model in the background: the
        baseline keeps one core busy, and the workers' start (a few seconds of imports and
        weights each) then costs the first round nothing. A failure here is left for the
        first real job to meet (and say); the futures are returned for a caller to wait on."""
        if self.size < 2 or self.settings.scheduler:
            return []
        executor = self.executor()
        return [executor.submit(warm_worker, self.settings) for _ in range(self.size)]

    def where(self) -> str:
        if self.settings.scheduler:
            return f"the Dask cluster at {self.settings.scheduler}"
        return f"{self.size} worker processes"

    def close(self) -> None:
        self._stack.close()
        self._executor = None

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def prefetch_stages(
    jobs: Sequence[StageJob],
    executor: Executor,
    *,
    on_progress: Callable[[str, int, int], None],
    say: Callable[[str], None],
) -> dict[str, float]:
    """Run ``jobs`` on ``executor`` (a :class:`WorkerPool`'s); the seconds each job's first
    stage took. Progress comes from counting each stage's logged trials. A failed job is
    said and left for the workflow to run again."""
    seconds: dict[str, float] = {}
    futures: dict[Future, StageJob] = {executor.submit(run_job, job): job for job in jobs}
    pending = set(futures)
    with _watching([stage for job in jobs for stage in job.stages], jobs[0].settings.out, on_progress):
        while pending:
            done, pending = wait(pending, timeout=POLL_S, return_when=FIRST_COMPLETED)
            for future in done:
                job = futures[future]
                try:
                    seconds.update(future.result())
                except Exception as exc:  # noqa: BLE001 - the workflow runs the stage again here
                    say(f"      {job.stages[0][0]} failed on a worker ({type(exc).__name__}: {exc}); "
                        "running it here")  # fmt: skip
    return seconds


def run_on_workers(
    pool: WorkerPool,
    jobs: Sequence[StageJob],
    bars: StageProgress,
    clock: StageClock,
    say: Log,
    label: str = "side_by_side",
) -> dict[str, Any]:
    """Run ``jobs`` (:func:`stage_jobs`) on the pool when it has more than one worker; how
    they ran. ``label``: the clock's name for the wall time of the jobs together (rounds
    under one label add up)."""
    if pool.size < 2:
        return {"workers": 1, "scheduler": None, **({"why_one_process": pool.why_one_process} if pool.why_one_process else {})}
    how = {"workers": pool.size, "scheduler": pool.settings.scheduler}
    if not jobs:
        return how
    say(f"      {len(jobs)} jobs run side by side on {pool.where()}")
    with clock.stage(label, add=True):
        clock.add(prefetch_stages(jobs, pool.executor(), on_progress=bars.update, say=say))
    return how


@contextmanager
def _watching(
    stages: Sequence[tuple[str, int]], out: Any, on_progress: Callable[[str, int, int], None]
) -> Iterator[None]:
    """Report every stage's logged trials every :data:`POLL_S` seconds while the block runs."""
    stop = threading.Event()

    def poll() -> None:
        while True:
            for name, trials in stages:
                on_progress(name, min(_logged_trials(out / name / "trials.jsonl"), trials), trials)
            if stop.wait(POLL_S):
                return

    thread = threading.Thread(target=poll, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()
        for name, trials in stages:  # the final counts
            on_progress(name, min(_logged_trials(out / name / "trials.jsonl"), trials), trials)


def _logged_trials(path: Any) -> int:
    try:
        with open(path, "rb") as fh:
            return sum(1 for _ in fh)
    except OSError:
        return 0
