"""What runs inside a worker process: one work unit from θ to shard (:func:`run_unit`).

A job carries the generator pickled once by the engine; each process (and thread, since
a Dask worker may run several tasks at once and EGL contexts are per thread) unpickles
it on its first job and reuses it, so the simulator and renderer are built once per
worker rather than once per unit. Files are written straight into the dataset directory
(on a cluster it must be shared storage); the unit's record goes back to the engine,
which writes it last.
"""

from __future__ import annotations

import os
import pickle
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.datasets.executors import limit_threads
from physinfer.datasets.generator import DatasetGenerator
from physinfer.datasets.plan import SimulationPlan, UnitPlan, render_rng
from physinfer.datasets.presets import ClipFormat
from physinfer.datasets.storage import file_digest, npz_digest, shard_relpath, trajectory_relpath
from physinfer.errors import PhysinferError, SimulationFailed
from physinfer.io import atomic_path, to_jsonable
from physinfer.types import Clip, Trajectory
from physinfer.video import center_crop_resize, resample, to_gray
from physinfer.worker_cache import thread_cached


@dataclass(frozen=True)
class UnitJob:
    """Everything a worker needs to produce one unit.

    Attributes:
        root: Dataset directory, as the worker sees it (absolute).
        seed: Dataset seed (ζ streams are derived from it).
        clip: Stored clip format.
        unit: The unit's simulations.
        generator_blob: The generator, pickled (cloudpickle) by the engine.
        generator_key: A digest of ``generator_blob`` identifying it in the worker cache.
        threads: Threads each worker process may use for numerical libraries; ``None``
            leaves the process as it is (in-process runs).
    """

    root: str
    seed: int
    clip: ClipFormat
    unit: UnitPlan
    generator_blob: bytes
    generator_key: str
    threads: int | None = 1


def cached_generator(blob: bytes, key: str) -> DatasetGenerator:
    """This thread's unpickled generator for ``key`` (one kept per thread; older ones closed)."""
    return thread_cached(
        "datasets.generators", key, lambda: pickle.loads(blob), only_latest=True, close=lambda old: old.close()
    )


def run_unit(job: UnitJob) -> dict[str, Any]:
    """Simulate, render and write one unit; returns its record (JSON-ready).

    Simulations that fail (raise :class:`SimulationFailed` or produce NaN) are listed
    under ``"failed"`` and get no renders; the rest of the unit is kept.
    """
    if job.threads is not None:
        limit_threads(job.threads)
    generator = cached_generator(job.generator_blob, job.generator_key)
    root = Path(job.root)
    t0 = time.perf_counter()
    trajectories, failed = simulate_unit(generator, job.unit.sims, job.clip)
    t1 = time.perf_counter()
    traj_entries = [
        save_trajectory(root, sim, traj) for sim, traj in zip(job.unit.sims, trajectories, strict=True) if traj is not None
    ]
    kept = [(sim, traj) for sim, traj in zip(job.unit.sims, trajectories, strict=True) if traj is not None]
    shard_file = shard_relpath(job.unit.unit)
    n_clips = sum(sim.n_renders for sim, _ in kept)
    rows: list[dict[str, Any]] = []
    render_s = 0.0
    with atomic_path(root / shard_file, suffix=".npy") as tmp:
        if n_clips == 0:
            np.save(tmp, np.zeros((0, *job.clip.shape), dtype=np.uint8))
        else:
            shard = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.uint8, shape=(n_clips, *job.clip.shape))
            index = 0
            for sim, traj in kept:
                for r in range(sim.n_renders):
                    zeta = generator.sample_render_params(render_rng(job.seed, sim.split, sim.local, r))
                    t_r = time.perf_counter()
                    scene_generator = generator if sim.scene is None else generator.in_scene(sim.scene)
                    shard[index] = to_stored(scene_generator.render(traj, zeta, clip=job.clip), job.clip)
                    render_s += time.perf_counter() - t_r
                    rows.append(_row(sim, r, zeta, shard_file, index))
                    index += 1
            shard.flush()
            del shard
    shard_path = root / shard_file
    checksum = file_digest(shard_path)
    for row in rows:
        row["checksum"] = checksum
    return {
        "unit": job.unit.unit,
        "split": job.unit.split,
        "sims": [sim.sim for sim in job.unit.sims],
        "failed": failed,
        "shard": {
            "file": shard_file,
            "bytes": shard_path.stat().st_size,
            "checksum": checksum,
            "shape": [n_clips, *job.clip.shape],
        },
        "trajectories": traj_entries,
        "rows": rows,
        "timing": {
            "simulate_s": t1 - t0,
            "render_s": render_s,
            "total_s": time.perf_counter() - t0,
            "worker": f"{socket.gethostname()}:{os.getpid()}",
        },
    }


def simulate_unit(
    generator: DatasetGenerator, sims: Sequence[SimulationPlan], clip: ClipFormat
) -> tuple[list[Trajectory | None], list[dict[str, Any]]]:
    """Simulate a unit's batch; on failure, one simulation at a time to find the culprits.

    Simulations with scenes of their own (``--scene-range``) run one at a time, each in
    its scene (their meshes differ).

    Returns:
        One trajectory per simulation (``None`` where it failed) and the failures as
        ``{"sim": id, "error": message}``.
    """
    if any(s.scene is not None for s in sims):
        batch: list[Trajectory | None] = [_simulate_one(generator, s, clip) for s in sims]
    else:
        batch = _simulate_batch(generator, sims, clip)
    return _checked(sims, batch)


def _simulate_batch(
    generator: DatasetGenerator, sims: Sequence[SimulationPlan], clip: ClipFormat
) -> list[Trajectory | None]:
    params, seeds = [s.params for s in sims], [s.seed for s in sims]
    try:
        batch: list[Trajectory | None] = list(generator.simulate_batch(params, seeds, clip=clip))
    except SimulationFailed:
        batch = [_simulate_one(generator, s, clip) for s in sims]
    return batch


def _checked(
    sims: Sequence[SimulationPlan], batch: list[Trajectory | None]
) -> tuple[list[Trajectory | None], list[dict[str, Any]]]:
    """The batch with non-finite trajectories dropped, and the failures."""
    if len(batch) != len(sims):
        raise PhysinferError(f"simulate_batch returned {len(batch)} trajectories for {len(sims)} simulations")
    failed: list[dict[str, Any]] = []
    for i, (sim, traj) in enumerate(zip(sims, batch, strict=True)):
        if traj is None or not traj.is_finite():
            batch[i] = None
            failed.append({"sim": sim.sim, "params": sim.params, "error": "simulation failed or produced NaN"})
    return batch, failed


def _simulate_one(generator: DatasetGenerator, sim: SimulationPlan, clip: ClipFormat) -> Trajectory | None:
    if sim.scene is not None:
        generator = generator.in_scene(sim.scene)
    try:
        return generator.simulate_batch([sim.params], [sim.seed], clip=clip)[0]
    except SimulationFailed:
        return None


def save_trajectory(root: Path, sim: SimulationPlan, trajectory: Trajectory) -> dict[str, Any]:
    """Write one trajectory (atomically) and return its entry ``{"sim", "file", "checksum"}``."""
    rel = trajectory_relpath(sim.sim)
    trajectory.save(root / rel)
    return {"sim": sim.sim, "file": rel, "checksum": npz_digest(root / rel)}


def to_stored(clip: Clip, fmt: ClipFormat) -> np.ndarray:
    """Convert a rendered clip to the stored format.

    Resamples to ``fmt.fps`` (nearest frame), keeps the first ``fmt.n_frames`` frames,
    converts colour and centre-crops and resizes to ``(fmt.height, fmt.width)``.

    Args:
        clip: Rendered clip ``(T', H', W', C)`` uint8.
        fmt: The stored format.

    Returns:
        ``fmt.shape`` uint8: ``(T, H, W)`` or ``(T, H, W, 3)``.

    Raises:
        PhysinferError: when the clip is too short for ``fmt.n_frames``.
    """
    resampled = resample(clip, fmt.fps)
    if resampled.n_frames < fmt.n_frames:
        raise PhysinferError(
            f"rendered clips have {clip.n_frames} frames at {clip.fps:g} fps "
            f"({resampled.n_frames} at {fmt.fps:g} fps); the dataset stores {fmt.n_frames}: "
            "choose fewer frames or make the phenomenon simulate longer"
        )
    frames = resampled.frames[: fmt.n_frames]
    if fmt.channels == 1:
        frames = frames[..., 0] if frames.shape[-1] == 1 else np.rint(to_gray(frames) * 255.0).astype(np.uint8)
    elif frames.shape[-1] == 1:
        frames = np.repeat(frames, 3, axis=-1)
    return center_crop_resize(frames, (fmt.height, fmt.width))


def _row(sim: SimulationPlan, render: int, zeta: dict[str, Any], shard_file: str, index: int) -> dict[str, Any]:
    return {
        "render": sim.first_render + render,
        "sim": sim.sim,
        "split": sim.split,
        "render_index": render,
        "params": dict(sim.params),
        "render_params": to_jsonable(zeta),
        "sim_seed": sim.seed,
        "file": shard_file,
        "index": index,
        "trajectory": trajectory_relpath(sim.sim),
        **({"scene": dict(sim.scene)} if sim.scene is not None else {}),
    }
