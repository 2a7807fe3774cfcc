"""A refinement's re-simulations: the observation noise told to the optimizer (the centre
under extra seeds), the selection of the best fit among the finalists (each under fresh
seeds), and the noise floor at the best fit: the loop's (:mod:`physinfer.loop`) re-simulations.
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from physinfer.errors import SimulationFailed
from physinfer.evaluation import ClipEmbedder, Pipeline, evaluate, squared_distance
from physinfer.io import atomic_write_json, read_keyed_json
from physinfer.noise import measure_noise_floor, noise_seeds
from physinfer.refinement import RefineResult, SearchSpec
from physinfer.roles import Target
from physinfer.rundir import NOISE_PRIOR_FILE, SELECTION_FILE, RunDirectory, TrialRecord

#: Salt of the selection's seeds, so they repeat neither the trials' nor the noise floor's.
SELECTION_SEED_SALT = 0x5E1EC7


def observation_noise(
    pipeline: Pipeline,
    target: Target,
    target_embedding: np.ndarray,
    run_dir: RunDirectory,
    config: SearchSpec,
) -> float | None:
    """The standard error told to the optimizer with every observation.

    ``config.noise_sem`` if given; else, with ``noise_samples`` > 0, the spread of the
    objective over re-simulations of the centre θ (measured once per run and stored in
    the run directory, so a resumed run tells the optimizer the same); else ``None``.
    Averaging over ``seeds_per_trial`` seeds divides the spread by their square root.
    """
    if config.noise_sem is not None:
        return config.noise_sem
    if config.noise_samples == 0:
        return None
    path = run_dir.path / NOISE_PRIOR_FILE
    if path.is_file():
        return json.loads(path.read_text())["sem"]
    space = pipeline.simulator.parameter_space
    centre = space.from_unit(np.zeros(len(space)))
    try:
        floor = measure_noise_floor(
            pipeline,
            centre,
            target.render_params,
            seeds=noise_seeds(config.seed + 1, config.noise_samples),
            target_embedding=target_embedding,
        )
    except SimulationFailed:
        return None  # the centre fails under other seeds: leave the noise to the optimizer
    if config.log_objective:
        spread = floor.log_std()
    else:
        spread = float(np.std(floor.to_target or floor.pairwise, ddof=1))
    # A deterministic phenomenon has no spread: leave the (numerical) noise to the optimizer.
    sem = (
        float(spread / np.sqrt(config.seeds_per_trial))
        if np.isfinite(spread) and spread > 1e-9
        else None
    )
    atomic_write_json(
        path, {"sem": sem, "at": "centre", "log_objective": config.log_objective, **floor.summary()}
    )
    return sem


def select_best(
    records: Sequence[TrialRecord],
    pipeline: Pipeline,
    target: Target,
    target_embedding: np.ndarray,
    run_dir: RunDirectory,
    config: SearchSpec,
    embed_clips: ClipEmbedder | None = None,
) -> dict[str, Any] | None:
    """Choose the best θ among the ``select_top`` best trials by re-simulating them.

    With a chaotic or stochastic phenomenon every logged distance is one noisy draw, and
    the lowest of many draws is biased towards a θ whose one seed happened to land close
    (the winner's curse): the trial with the lowest distance is often not the θ whose
    realisations come closest. Each finalist is simulated again under ``select_seeds``
    fresh seeds (the same for all, none used by a trial or by the noise floor), and the
    lowest *mean fresh distance* wins — an unbiased comparison, since the logged distance
    that made a trial a finalist is not part of its score. Stored in ``selection.json``
    (a resumed run with the same finalists does not re-simulate). ``embed_clips``: make
    the re-simulations there, all at once (the same numbers: each clip is seeded by itself).

    Returns:
        ``{"seeds", "finalists": [{"step", "distance", "resimulated", "score"}],
        "chosen_step", "selection_s"}``, or ``None`` when fewer than two distinct
        trials succeeded or every finalist failed under a fresh seed.
    """
    finalists: list[TrialRecord] = []
    seen: set[tuple[float, ...]] = set()
    for record in sorted((r for r in records if r.distance is not None), key=lambda r: r.distance):
        point = tuple(round(v, 12) for v in record.x)
        if point not in seen:
            seen.add(point)
            finalists.append(record)
        if len(finalists) == config.select_top:
            break
    if len(finalists) < 2:
        return None
    seeds = noise_seeds(config.seed, config.select_seeds, salt=SELECTION_SEED_SALT)
    key = {"steps": [r.step for r in finalists], "seeds": seeds}
    path = run_dir.path / SELECTION_FILE
    if (stored := read_keyed_json(path, key)) is not None:
        return stored
    t0 = time.perf_counter()
    fresh_by_step = _fresh_distances(finalists, seeds, pipeline, target, target_embedding, embed_clips)
    rows = []
    for record in finalists:
        fresh = fresh_by_step[record.step]
        ok = all(d is not None for d in fresh)  # a θ that fails under a fresh seed is no winner
        rows.append(
            {
                "step": record.step,
                "distance": record.distance,
                "resimulated": fresh,
                "score": float(np.mean(fresh)) if ok else None,
            }
        )
    scored = [row for row in rows if row["score"] is not None]
    if not scored:
        return None
    chosen = min(scored, key=lambda row: row["score"])["step"]
    selection = {
        "key": key,
        "seeds": seeds,
        "finalists": rows,
        "chosen_step": chosen,
        "selection_s": time.perf_counter() - t0,
    }
    atomic_write_json(path, selection)
    return selection


def _fresh_distances(
    finalists: Sequence[TrialRecord],
    seeds: Sequence[int],
    pipeline: Pipeline,
    target: Target,
    target_embedding: np.ndarray,
    embed_clips: ClipEmbedder | None,
) -> dict[int, list[float | None]]:
    """Each finalist's distance to the target under each seed (``None``: the simulation or
    its distance failed), by step: here one by one, or all through ``embed_clips``."""
    if embed_clips is None:
        return {
            r.step: [evaluate(pipeline, r.params, target_embedding, target.render_params, s)[0] for s in seeds]
            for r in finalists
        }
    embeddings = embed_clips([r.params for r in finalists for _ in seeds], [s for _ in finalists for s in seeds])
    distances = [None if e is None else squared_distance(e, target_embedding) for e in embeddings]
    finite = [d if d is not None and np.isfinite(d) else None for d in distances]
    return {r.step: finite[i * len(seeds) : (i + 1) * len(seeds)] for i, r in enumerate(finalists)}


def final_noise_floor(
    result: RefineResult,
    pipeline: Pipeline,
    target: Target,
    target_embedding: np.ndarray,
    config: SearchSpec,
) -> dict[str, Any] | None:
    """The noise floor at the best θ: how far its own re-simulations are from each other
    (``floor``) and from the target (``gap``); ``ratio`` near 1 means the fit is as good as
    the chaos of the phenomenon allows. ``None`` when the re-simulations fail."""
    try:
        floor = measure_noise_floor(
            pipeline,
            result.best_params,
            target.render_params,
            seeds=noise_seeds(config.seed + 2, config.floor_samples),
            target_embedding=target_embedding,
        )
    except SimulationFailed:
        return None
    return floor.summary()
