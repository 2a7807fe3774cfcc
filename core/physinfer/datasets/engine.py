"""The generation engine: plan, skip what is complete, run the rest on an executor.

One code path serves every executor: a :class:`concurrent.futures.Executor` runs
:func:`~physinfer.datasets.worker.run_unit` per unit. ``workers=0`` runs in this process
(:class:`InlineExecutor`), ``workers=K`` in ``K`` spawned local processes, and a Dask
scheduler address through ``distributed.Client.get_executor()``. Re-running on the same
directory resumes: units whose record and files are intact are skipped, damaged ones
(missing, truncated, checksum mismatch) are deleted and generated again.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Iterator, Mapping
from concurrent.futures import FIRST_COMPLETED, Executor, Future, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from physinfer.datasets.generator import DatasetGenerator
from physinfer.datasets.plan import UnitPlan, plan_dataset
from physinfer.datasets.presets import SPLITS, DatasetPreset
from physinfer.datasets.storage import (
    DATASET_FILE,
    FORMAT_NAME,
    FORMAT_VERSION,
    directory_bytes,
    read_json,
    remove_stale_temporaries,
    remove_unit_files,
    unit_problems,
    unit_record_path,
    write_manifest,
    write_unit_record,
)
from physinfer.datasets.worker import UnitJob, run_unit, start_worker
from physinfer.errors import PhysinferError, UserInputError
from physinfer.io import atomic_write_json, check_output_dir, to_jsonable
from physinfer.locking import LOCK_FILE, exclusive_directory


class GenerateProgress(Protocol):
    """Receives progress: a phase starts with a total, then advances."""

    def start(self, phase: str, total: int, done: int = 0) -> None:
        """Phase ``"verify"`` (in units) or ``"generate"`` (in renders) begins."""

    def advance(self, n: int) -> None:
        """``n`` more units verified or renders written."""


class InlineExecutor(Executor):
    """An executor that runs each call at once in this process (``--workers 0``, debugging)."""

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> Future:
        """Run ``fn(*args, **kwargs)`` now; return a finished future."""
        future: Future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except Exception as exc:
            future.set_exception(exc)
        return future


@dataclass(frozen=True)
class ExecutorInfo:
    """What ran the units.

    Attributes:
        kind: ``"inline"``, ``"processes"``, ``"dask"``, ``"none"`` (nothing left to run) or
            the class name of an executor passed in.
        workers: Worker processes (Dask: workers known to the scheduler at start).
        threads: Thread cap per worker for numerical libraries (``None``: untouched).
        address: The Dask scheduler address, if any.
    """

    kind: str
    workers: int
    threads: int | None
    address: str | None = None


def default_workers() -> int:
    """Worker processes used when none are asked for: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


@contextmanager
def open_executor(
    *, workers: int | None = None, scheduler: str | None = None, threads_per_worker: int = 1
) -> Iterator[tuple[Executor, ExecutorInfo]]:
    """An executor for the units, closed on exit.

    Args:
        workers: Local worker processes; 0 runs in this process; ``None`` uses
            :func:`default_workers`. Ignored with ``scheduler``.
        scheduler: Address of a Dask scheduler (``tcp://host:8786``); its workers must
            have physinfer and the plugin installed and see the output directory.
        threads_per_worker: Thread cap per worker process for numerical libraries.

    Raises:
        UserInputError: for a negative worker count or an unreachable scheduler.
    """
    if scheduler:
        yield from _dask_executor(scheduler, threads_per_worker)
        return
    workers = default_workers() if workers is None else workers
    if workers < 0:
        raise UserInputError(f"--workers must be 0 (in this process) or more, got {workers}")
    if workers == 0:
        yield InlineExecutor(), ExecutorInfo("inline", 1, None)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    # spawn, not fork: EGL contexts and torch's thread pools do not survive a fork. The
    # workers die with this process, even when it is killed (start_worker).
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=start_worker,
        initargs=(threads_per_worker, os.getpid()),
    )
    try:
        yield pool, ExecutorInfo("processes", workers, threads_per_worker)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _dask_executor(address: str, threads_per_worker: int) -> Iterator[tuple[Executor, ExecutorInfo]]:
    try:
        from distributed import Client
    except ImportError:
        raise UserInputError("--scheduler needs Dask: pip install 'dask[distributed]'") from None
    try:
        client = Client(address, timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise UserInputError(
            f"cannot reach the Dask scheduler at {address!r} ({type(exc).__name__}: {exc}); "
            "start one with `dask scheduler` and workers with `dask worker ADDRESS`"
        ) from None
    try:
        n_workers = len(client.scheduler_info().get("workers", {}))
        executor = client.get_executor(pure=False)
        yield executor, ExecutorInfo("dask", n_workers, threads_per_worker, address)
        executor.shutdown(wait=False)
    finally:
        client.close()


@dataclass
class GenerateResult:
    """What a :func:`generate_dataset` call did.

    Attributes:
        root: The dataset directory.
        phenomenon: Phenomenon name.
        preset: The preset (after overrides).
        seed: Dataset seed.
        executor: What ran the units.
        units_total: Units in the dataset.
        units_generated: Units generated by this call (including regenerated ones).
        units_skipped: Units found complete and intact.
        units_regenerated: Units found damaged and generated again.
        renders: Renders in the finished dataset, per split.
        renders_generated: Renders written by this call.
        failed_sims: Simulations that failed (``{"sim", "params", "error"}``), skipped.
        seconds: Wall time of this call.
        worker_seconds: Summed per-unit worker time: ``simulate_s``, ``render_s``, ``total_s``.
        bytes: Size of the dataset directory.
    """

    root: Path
    phenomenon: str
    preset: DatasetPreset
    seed: int
    executor: ExecutorInfo
    units_total: int = 0
    units_generated: int = 0
    units_skipped: int = 0
    units_regenerated: int = 0
    renders: dict[str, int] = field(default_factory=dict)
    renders_generated: int = 0
    failed_sims: list[dict[str, Any]] = field(default_factory=list)
    seconds: float = 0.0
    worker_seconds: dict[str, float] = field(default_factory=dict)
    bytes: int = 0

    @property
    def renders_per_minute(self) -> float:
        """Renders written per minute of wall time by this call (0 when nothing was done)."""
        return 60.0 * self.renders_generated / self.seconds if self.renders_generated and self.seconds else 0.0

    def summary(self) -> dict[str, Any]:
        """JSON-ready summary (what ``--json`` prints)."""
        return to_jsonable(
            {
                "out": str(self.root),
                "phenomenon": self.phenomenon,
                "preset": self.preset.name,
                "seed": self.seed,
                "executor": self.executor.__dict__,
                "sims": self.preset.sims.to_dict(),
                "renders": self.renders,
                "renders_total": sum(self.renders.values()),
                "renders_generated": self.renders_generated,
                "units": {
                    "total": self.units_total,
                    "generated": self.units_generated,
                    "skipped": self.units_skipped,
                    "regenerated": self.units_regenerated,
                },
                "failed_sims": self.failed_sims,
                "clip": self.preset.clip.to_dict(),
                "seconds": self.seconds,
                "renders_per_minute": self.renders_per_minute,
                "worker_seconds": self.worker_seconds,
                "bytes": self.bytes,
            }
        )


def dataset_config(generator: DatasetGenerator, preset: DatasetPreset, seed: int) -> dict[str, Any]:
    """What determines a dataset's content; a resumed run must match it exactly.

    ``scene`` (``dataset generate --scene-set``) is recorded only when one was given, so
    datasets made before scenes existed still resume.
    """
    from physinfer.scene import scene_of

    described = preset.to_dict()
    described.pop("description")
    config: dict[str, Any] = {
        "phenomenon": generator.phenomenon,
        "generator": f"{type(generator).__module__}.{type(generator).__qualname__}",
        "seed": seed,
        "preset": described,
        "parameters": generator.parameter_space.to_dict(),
    }
    scene = scene_of(getattr(generator, "record", None))
    if scene is not None:
        config["scene"] = scene
    return json.loads(json.dumps(to_jsonable(config)))


def generate_dataset(
    generator: DatasetGenerator,
    root: str | Path,
    *,
    preset: DatasetPreset,
    seed: int = 0,
    executor: Executor | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    threads_per_worker: int = 1,
    verify: bool = True,
    progress: GenerateProgress | None = None,
) -> GenerateResult:
    """Generate (or finish) the dataset in ``root``.

    Args:
        generator: The phenomenon's generator.
        root: Output directory; created if missing, resumed if it holds this dataset.
        preset: Sizes and clip format.
        seed: Dataset seed; with the same seed and preset the data are identical
            whatever the executor or worker count.
        executor: Run units on this executor (a ``ClientExecutor`` of a Dask client, for
            instance); when ``None`` one is opened from ``workers`` / ``scheduler``.
        workers: Local worker processes (0: this process); see :func:`open_executor`.
        scheduler: Dask scheduler address.
        threads_per_worker: Thread cap per worker process (see
            :func:`~physinfer.datasets.worker.limit_threads`).
        verify: On resume, recompute the checksums of complete units (reads all data);
            ``False`` checks only that files exist with the right sizes.
        progress: Receives progress events.

    Returns:
        What was done.

    Raises:
        UserInputError: when ``root`` holds something else (another dataset, other files)
            or another run is writing it.
    """
    t0 = time.perf_counter()
    root = Path(root).expanduser().resolve()
    _check_directory(root)
    with exclusive_directory(root):
        config = dataset_config(generator, preset, seed)
        _start_dataset(root, config)
        remove_stale_temporaries(root)
        units = plan_dataset(generator, preset, seed)
        records, todo, regenerated = _resume_state(root, units, verify=verify, progress=progress)
        if not todo:  # nothing to run: start no processes and contact no scheduler
            info = ExecutorInfo("none", 0, None)
            new_records = _run_units(generator, root, preset, seed, todo, InlineExecutor(), info, progress, units)
        elif executor is not None:
            info = ExecutorInfo(type(executor).__name__, workers or 32, threads_per_worker)
            new_records = _run_units(generator, root, preset, seed, todo, executor, info, progress, units)
        else:
            with open_executor(
                workers=workers, scheduler=scheduler, threads_per_worker=threads_per_worker
            ) as (opened, info):
                new_records = _run_units(generator, root, preset, seed, todo, opened, info, progress, units)
        records.update(new_records)
        all_records = [records[u.unit] for u in units]
        write_manifest(root, all_records)
        result = _result(root, generator, preset, seed, info, units, all_records, new_records, regenerated)
        _finish_dataset(root, config, result)
        result.seconds = time.perf_counter() - t0
        result.bytes = directory_bytes(root)
        return result


def _check_directory(root: Path) -> None:
    check_output_dir(root)
    if root.is_dir() and not (root / DATASET_FILE).exists():
        others = [p.name for p in root.iterdir() if p.name != LOCK_FILE]
        if others:
            raise UserInputError(
                f"--out {root} is not empty and holds no dataset ({', '.join(sorted(others)[:3])}...); "
                "give a new or empty directory"
            )


def _start_dataset(root: Path, config: dict[str, Any]) -> None:
    path = root / DATASET_FILE
    if path.exists():
        existing = read_json(path)
        if not isinstance(existing, dict) or existing.get("format") != FORMAT_NAME:
            raise UserInputError(f"{path} is not a physinfer dataset description; give another --out")
        if existing.get("config") != config:
            diff = _config_difference(existing.get("config") or {}, config)
            raise UserInputError(
                f"{root} holds a different dataset ({diff}); resume it with the same options, "
                "or give another --out"
            )
        if existing.get("status") == "incomplete":
            return
    atomic_write_json(
        path, {"format": FORMAT_NAME, "version": FORMAT_VERSION, "config": config, "status": "incomplete"}
    )


def _config_difference(old: Mapping[str, Any], new: Mapping[str, Any], prefix: str = "") -> str:
    diffs: list[str] = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if a == b:
            continue
        if isinstance(a, dict) and isinstance(b, dict):
            diffs.append(_config_difference(a, b, f"{prefix}{key}."))
        else:
            diffs.append(f"{prefix}{key}: {json.dumps(a)} there, {json.dumps(b)} now")
    return "; ".join(d for d in diffs if d)


def _resume_state(
    root: Path, units: list[UnitPlan], *, verify: bool, progress: GenerateProgress | None
) -> tuple[dict[int, dict[str, Any]], list[UnitPlan], int]:
    """Records of intact units, the units still to run and how many were damaged."""
    records: dict[int, dict[str, Any]] = {}
    todo: list[UnitPlan] = []
    regenerated = 0
    recorded = {u.unit for u in units if unit_record_path(root, u.unit).exists()}
    if progress is not None and recorded:
        progress.start("verify", len(recorded))
    for unit in units:
        record = read_json(unit_record_path(root, unit.unit)) if unit.unit in recorded else None
        if unit.unit not in recorded:
            todo.append(unit)
            continue
        if _intact(root, unit, record, verify=verify):
            records[unit.unit] = record
        else:
            if isinstance(record, dict) and "shard" in record:
                remove_unit_files(root, record)
            unit_record_path(root, unit.unit).unlink(missing_ok=True)
            regenerated += 1
            todo.append(unit)
        if progress is not None:
            progress.advance(1)
    return records, todo, regenerated


def _intact(root: Path, unit: UnitPlan, record: Any, *, verify: bool) -> bool:
    """Whether a unit's record is readable, belongs to this plan and its files are intact."""
    try:
        return record["sims"] == [s.sim for s in unit.sims] and not unit_problems(root, record, verify=verify)
    except (TypeError, KeyError):  # an unreadable or foreign record
        return False


def _run_units(
    generator: DatasetGenerator,
    root: Path,
    preset: DatasetPreset,
    seed: int,
    todo: list[UnitPlan],
    executor: Executor,
    info: ExecutorInfo,
    progress: GenerateProgress | None,
    units: list[UnitPlan],
) -> dict[int, dict[str, Any]]:
    """Submit the units in ``todo``; write each record as its unit completes."""
    total = sum(u.n_renders for u in units)
    if progress is not None:
        progress.start("generate", total, total - sum(u.n_renders for u in todo))
    if not todo:
        return {}
    blob = _pickle_generator(generator)
    key = hashlib.sha256(blob).hexdigest()[:16]
    queue = list(reversed(todo))
    # A bounded window of submitted units keeps workers busy while an interruption
    # leaves little running, and lets the in-process executor report unit by unit.
    window = 1 if isinstance(executor, InlineExecutor) else max(2, 2 * info.workers)
    pending: dict[Future, UnitPlan] = {}
    done: dict[int, dict[str, Any]] = {}
    try:
        while queue or pending:
            while queue and len(pending) < window:
                unit = queue.pop()
                job = UnitJob(str(root), seed, preset.clip, unit, blob, key, info.threads)
                pending[executor.submit(run_unit, job)] = unit
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in sorted(finished, key=lambda f: pending[f].unit):
                unit = pending.pop(future)
                record = future.result()
                _check_visible(root, record)
                write_unit_record(root, record)
                done[record["unit"]] = record
                if progress is not None:
                    progress.advance(unit.n_renders)
    except BaseException:
        for future in pending:
            future.cancel()
        raise
    return done


def _pickle_generator(generator: DatasetGenerator) -> bytes:
    """Pickle the generator once; cloudpickle also carries lambdas and local classes."""
    try:
        import cloudpickle
    except ImportError:  # dask brings cloudpickle; plain pickle works for module-level code
        import pickle

        return pickle.dumps(generator)
    return cloudpickle.dumps(generator)


def _check_visible(root: Path, record: Mapping[str, Any]) -> None:
    shard = root / record["shard"]["file"]
    if not shard.is_file() or shard.stat().st_size != record["shard"]["bytes"]:
        raise PhysinferError(
            f"unit {record['unit']} was written by {record['timing']['worker']} but {shard} is not here: "
            "Dask workers write into the output directory, which must be storage they share with this machine"
        )


def _result(
    root: Path,
    generator: DatasetGenerator,
    preset: DatasetPreset,
    seed: int,
    info: ExecutorInfo,
    units: list[UnitPlan],
    records: list[dict[str, Any]],
    new_records: Mapping[int, dict[str, Any]],
    regenerated: int,
) -> GenerateResult:
    renders = {split: 0 for split in SPLITS}
    for record in records:
        renders[record["split"]] += len(record["rows"])
    worker_seconds = {"simulate_s": 0.0, "render_s": 0.0, "total_s": 0.0}
    for record in new_records.values():
        for name in worker_seconds:
            worker_seconds[name] += float(record["timing"][name])
    return GenerateResult(
        root=root,
        phenomenon=generator.phenomenon,
        preset=preset,
        seed=seed,
        executor=info,
        units_total=len(units),
        units_generated=len(new_records),
        units_skipped=len(units) - len(new_records),
        units_regenerated=regenerated,
        renders=renders,
        renders_generated=sum(len(r["rows"]) for r in new_records.values()),
        failed_sims=[f for record in records for f in record["failed"]],
        worker_seconds=worker_seconds,
    )


def _finish_dataset(root: Path, config: dict[str, Any], result: GenerateResult) -> None:
    """Mark the dataset complete, with its final counts (deterministic content only)."""
    atomic_write_json(
        root / DATASET_FILE,
        {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "config": config,
            "status": "complete",
            "renders": result.renders,
            "failed_sims": [f["sim"] for f in result.failed_sims],
        },
    )
