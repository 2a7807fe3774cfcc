"""The gap between a fitted model and the target, measured against the model's own noise.

A refinement's best distance is the minimum over many noisy evaluations, so it is biased
low (the winner's curse) and says nothing about how far the model's *other* realisations
are. :func:`measure_gap` therefore re-simulates the best θ under ``K`` fresh seeds with
:func:`physinfer.evaluation.measure_noise_floor`: the median distance from those
re-simulations to the target is the **gap**, the median distance among them the **noise
floor** (what a perfect model would leave). The same seeds are used for every model of a
diagnosis, so gaps are compared pairwise. Measurements are cached as JSON in the stage's
run directory, so an interrupted diagnosis does not redo them; the re-simulations'
embeddings are kept beside it (NPZ), for the detection limits' ladder to reuse
(:mod:`physinfer.discrepancy.limits`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.evaluation import NoiseFloor, measure_noise_floor
from physinfer.io import atomic_save_npz, atomic_write_json, read_keyed_json

if TYPE_CHECKING:
    from physinfer.evaluation import ClipEmbedder, Pipeline

GAP_FILE = "gap.json"


def _from_summary(params: Mapping[str, float], summary: Mapping[str, Any], embeddings: Path | None) -> NoiseFloor:
    """Rebuild a :class:`NoiseFloor` from its JSON summary (and its embeddings, when stored)."""
    stored = np.zeros((0, 0), dtype=np.float32)
    if embeddings is not None and embeddings.is_file():
        with np.load(embeddings, allow_pickle=False) as data:
            if [int(s) for s in data["seeds"]] == [int(s) for s in summary["seeds"]]:
                stored = np.asarray(data["embeddings"])
    return NoiseFloor(
        params={k: float(v) for k, v in params.items()},
        seeds=[int(s) for s in summary["seeds"]],
        embeddings=stored,
        pairwise=[float(d) for d in summary["pairwise"]],
        to_target=None if summary["to_target"] is None else [float(d) for d in summary["to_target"]],
        n_failed=int(summary.get("n_failed", 0)),
    )


def measure_gap(
    pipeline: Pipeline,
    params: Mapping[str, float],
    render_params: Mapping[str, Any],
    target_embedding: np.ndarray,
    *,
    seeds: Sequence[int],
    cache_dir: Path | None = None,
    cache_name: str = GAP_FILE,
    embed_clips: ClipEmbedder | None = None,
) -> NoiseFloor:
    """Re-simulate ``params`` under ``seeds``; distances among them and to the target.

    Args:
        pipeline: The model (simulator with its effects), renderer and embedder.
        params: θ, physical values by name (the model's full space).
        render_params: ζ of the target.
        target_embedding: ``(D,)`` embedding of the target.
        seeds: Re-simulation seeds (at least two).
        cache_dir: Directory for the cache file; a cached measurement of the same θ and
            seeds is returned instead of re-simulating.
        cache_name: Name of the cache file in ``cache_dir``.
        embed_clips: Make the re-simulations there (``None``: here); the same numbers.

    Returns:
        The :class:`~physinfer.evaluation.NoiseFloor`; its ``gap`` and ``floor`` are medians.

    Raises:
        SimulationFailed: when fewer than two re-simulations succeed.
    """
    key = {"params": {k: float(v) for k, v in params.items()}, "seeds": [int(s) for s in seeds]}
    path = None if cache_dir is None else Path(cache_dir) / cache_name
    npz = None if path is None else path.with_suffix(".npz")
    if path is not None and (stored := read_keyed_json(path, key)) is not None:
        return _from_summary(params, stored["summary"], npz)
    floor = measure_noise_floor(
        pipeline, params, render_params, seeds=seeds, target_embedding=target_embedding, embed_clips=embed_clips
    )
    if path is not None and npz is not None:
        atomic_save_npz(npz, embeddings=floor.embeddings, seeds=np.asarray(floor.seeds, dtype=np.int64))
        atomic_write_json(path, {"key": key, "summary": floor.summary()})
    return floor


def gap_numbers(floor: NoiseFloor) -> dict[str, Any]:
    """The numbers of one gap measurement for the report."""
    return {
        "gap": floor.gap,
        "floor": floor.floor,
        "floor_q95": floor.floor_q95,
        "to_target": list(floor.to_target or []),
        "pairwise": list(floor.pairwise),
        "n_failed": floor.n_failed,
    }
