"""The refinement loop: the paper's method, for any phenomenon.

Embed the target once; then, each step, ask the optimizer for θ in ``[-1, 1]^D`` (the
first trial is the centre, 0), denormalise, simulate, render with fixed render
parameters ζ, embed, and tell the optimizer the squared Euclidean distance. A
simulation that raises, returns NaN or blows up is a failed trial and the run goes on.
Every trial is appended to the run directory as it completes, so an interrupted run
continues with ``resume=True``.

With ``batch_size`` q > 1 each step asks the optimizer for q trials at once (Ax proposes
them jointly, as a batch acquisition), simulates all of them in one call of
:meth:`~physinfer.roles.Simulator.simulate_batch` (the flag runs a batch in parallel
compiled threads), renders each and embeds them together. Same budget, fewer optimizer
rounds, more of the machine busy per round. A pipeline with ``workers``
(:mod:`physinfer.trial_workers`) simulates and renders the batch on worker processes or a
Dask cluster instead.

The loop's re-simulations are its own steps, at the end of this module: before the trials,
the observation noise told to the optimizer (the centre under extra seeds); after them, the
selection of the best fit among the finalists (each under fresh seeds) and the noise floor
at it.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.errors import SimulationFailed, UserInputError
from physinfer.evaluation import (
    evaluate,
    evaluate_batch,
    measure_noise_floor,
    noise_seeds,
    squared_distance,
)
from physinfer.io import atomic_write_json, read_keyed_json
from physinfer.moved import moved_names
from physinfer.refinement import FitPlace, NoiseReport, RefineResult, SearchSpec
from physinfer.roles import Optimizer, Target, Trial
from physinfer.rundir import (
    NOISE_PRIOR_FILE,
    RESUME_KEYS,
    SELECTION_FILE,
    TrialRecord,
    embedding_fingerprint,
)
from physinfer.threads import refinement_torch_threads, torch_threads

if TYPE_CHECKING:
    from physinfer.evaluation import ClipEmbedder, Pipeline
    from physinfer.rundir import RunDirectory

#: The evaluation and run-file names that moved out of the loop, still found here with a
#: warning (:data:`physinfer.moved.MOVED`).
__getattr__ = moved_names(__name__)


def _replay(optimizer: Optimizer, records: Sequence[TrialRecord], config: SearchSpec, sem: float | None) -> None:
    """Feed logged trials back to a fresh optimizer so it continues where the run stopped."""
    for rec in records:
        trial = optimizer.attach(np.asarray(rec.x, dtype=float))
        optimizer.tell(trial.index, config.objective(rec.distance), sem if rec.distance is not None else None)


def next_trials(optimizer: Optimizer, step: int, n: int, dim: int) -> list[Trial]:
    """The next ``n`` trials: the centre first (attached, at step 0), then the optimizer's.

    An optimizer may propose fewer than asked (Ax holds back while its initial design
    awaits data); the loop then runs a smaller batch. It must propose at least one.
    """
    trials = [optimizer.attach(np.zeros(dim))] if step == 0 else []
    if n > len(trials):
        trials += optimizer.ask(n - len(trials))[: n - len(trials)]
    if not trials:
        raise RuntimeError(f"optimizer {type(optimizer).__name__} proposed no trial at step {step}")
    return trials


def run_refinement(
    pipeline: Pipeline,
    target: Target,
    optimizer_factory: Callable[..., Optimizer],
    run_dir: RunDirectory,
    config: SearchSpec,
    *,
    run_info: dict[str, Any],
    resume: bool = False,
    on_trial: Callable[[TrialRecord, float], None] | None = None,
    embed_clips: ClipEmbedder | None = None,
) -> RefineResult:
    """Run (or continue) a refinement and log every trial to ``run_dir``.

    Args:
        pipeline: Simulator, renderer and embedder of the phenomenon.
        target: The clip to match, its oracle ζ and truth if known.
        optimizer_factory: Builds the optimizer with ``dim``, ``seed``, ``names``.
        run_dir: Where trials are logged.
        config: How to search: budget (resolved: :meth:`~physinfer.refinement.SearchSpec.with_budget`),
            optimizer, seed, noise handling and selection.
        run_info: What is stored in ``run.json`` (checked on resume).
        resume: Continue the trials already logged.
        on_trial: Called after each trial with the record and the best distance so far.
        embed_clips: Where the selection's re-simulations run (``None``: here), e.g. a
            diagnosis's workers, idle while its baseline refines; the same numbers.

    Returns:
        The :class:`RefineResult` (the refine command writes it out:
            :func:`physinfer.session.write_outputs`).
    """
    if config.steps is None:  # the command resolves it: the default depends on the start
        raise ValueError("run_refinement needs a budget: pass search.with_budget(phenomenon, from_posterior=...)")
    config.validate()
    with torch_threads(refinement_torch_threads()):
        return _run_refinement(
            pipeline, target, optimizer_factory, run_dir, config, run_info, resume, on_trial, embed_clips
        )


def _run_refinement(
    pipeline: Pipeline,
    target: Target,
    optimizer_factory: Callable[..., Optimizer],
    run_dir: RunDirectory,
    config: SearchSpec,
    run_info: dict[str, Any],
    resume: bool,
    on_trial: Callable[[TrialRecord, float], None] | None,
    embed_clips: ClipEmbedder | None = None,
) -> RefineResult:
    """The body of :func:`run_refinement` (torch threads already limited)."""
    start = time.perf_counter()
    space = pipeline.simulator.parameter_space
    # Embed first: a target the embedder refuses (too short, unreadable) leaves no run behind.
    target_embedding = pipeline.embedder.embed(target.clip)
    # Part of the run's identity: it changes with the embedder's weights, shipped ones included.
    run_info = {**run_info, "embedder_fingerprint": embedding_fingerprint(target_embedding)}
    if resume:
        run_dir.check_compatible(run_info, RESUME_KEYS)
        records = run_dir.read_trials()
    else:
        run_dir.create(run_info, overwrite=bool(run_info.get("overwrite")))
        records = []
    sem = observation_noise(pipeline, target, target_embedding, run_dir, config)
    if len(records) < config.steps:  # a finished run (read back by diagnose) needs no optimizer
        optimizer = optimizer_factory(dim=len(space), seed=config.seed, names=space.names)
        _replay(optimizer, records, config, sem)
    best = min((r.distance for r in records if r.distance is not None), default=float("inf"))
    while len(records) < config.steps:
        for record in _step(optimizer, pipeline, target, target_embedding, len(records), config, sem):
            run_dir.append_trial(record)
            records.append(record)
            if record.distance is not None:
                best = min(best, record.distance)
            if on_trial is not None:
                on_trial(record, best)
    selection = None
    if config.select_top:
        selection = select_best(records, pipeline, target, target_embedding, run_dir, config, embed_clips)
    chosen = None if selection is None else selection["chosen_step"]
    result = summarise(records, space.names, target, run_dir.path, time.perf_counter() - start, chosen_step=chosen)
    result.place = _fit_place(result.best_params, pipeline)
    if selection is not None:
        result.selection = {k: v for k, v in selection.items() if k != "key"}
    floor = final_noise_floor(result, pipeline, target, target_embedding, config) if config.floor_samples else None
    result.noise = NoiseReport(observation_sem=sem, floor=floor)
    return result


def _step(
    optimizer: Optimizer,
    pipeline: Pipeline,
    target: Target,
    target_embedding: np.ndarray,
    step: int,
    config: SearchSpec,
    sem: float | None,
) -> list[TrialRecord]:
    """One optimizer step from trial ``step`` on: ask for its trials, simulate and embed them
    as one batch, tell the optimizer their objectives; the trials' records, in order."""
    space = pipeline.simulator.parameter_space
    t0 = time.perf_counter()
    trials = next_trials(optimizer, step, min(config.batch_size, config.steps - step), len(space))
    t_ask = time.perf_counter() - t0
    params = [space.from_unit(trial.x) for trial in trials]
    outcomes = evaluate_batch(pipeline, params, target_embedding, target.render_params, config.trial_seeds())
    t1 = time.perf_counter()
    for trial, (distance, _, _) in zip(trials, outcomes, strict=True):
        optimizer.tell(trial.index, config.objective(distance), sem if distance is not None else None)
    optimizer_s = (t_ask + time.perf_counter() - t1) / len(trials)
    return [
        TrialRecord(
            step=step + offset,
            index=trial.index,
            x=[float(v) for v in trial.x],
            params=theta,
            distance=distance,
            status="ok" if distance is not None else "failed",
            error=error,
            timings={**timings, "optimizer": optimizer_s},
        )
        for offset, (trial, theta, (distance, error, timings)) in enumerate(zip(trials, params, outcomes, strict=True))
    ]


def _fit_place(best_params: dict[str, float], pipeline: Pipeline) -> FitPlace:
    """Where the best fit lies: its nuisance values (reported apart from the physics) and
    the parameters at a bound of their range."""
    space = pipeline.simulator.parameter_space
    nuisance = [name for name in getattr(pipeline.phenomenon, "nuisance", ()) if name in best_params]
    # Reported apart; a bound of a nuisance (a phase of 0 or 1 cycle) says nothing.
    return FitPlace(
        at_bounds={name: bound for name, bound in space.at_bounds(best_params).items() if name not in nuisance},
        nuisance={name: best_params[name] for name in nuisance},
    )


def summarise(
    records: Sequence[TrialRecord],
    names: Sequence[str],
    target: Target,
    run_dir: Path,
    wall_time_s: float,
    *,
    chosen_step: int | None = None,
) -> RefineResult:
    """Best trial (the lowest distance, or the trial of ``chosen_step``), errors against
    truth, and timing totals of a list of trials."""
    ok = [r for r in records if r.distance is not None]
    if not ok:
        raise UserInputError(
            f"every one of the {len(records)} trials failed (first error: {records[0].error if records else 'none'}); "
            "nothing to report. Check the parameter bounds and the simulator settings."
        )
    best = min(ok, key=lambda r: r.distance)
    if chosen_step is not None:
        best = next(r for r in ok if r.step == chosen_step)
    truth = dict(target.truth) if target.truth else None
    abs_errors = (
        {n: abs(best.params[n] - truth[n]) for n in names if n in truth and n in best.params} if truth else None
    )
    phases = ("simulate", "render", "embed", "optimizer")
    timings = {f"{p}_s": float(sum(r.timings.get(p, 0.0) for r in records)) for p in phases}
    return RefineResult(
        best_params=dict(best.params),
        best_distance=float(best.distance),
        best_step=best.step,
        ground_truth=truth,
        abs_errors=abs_errors,
        n_trials=len(records),
        n_failed=len(records) - len(ok),
        wall_time_s=wall_time_s,
        timings=timings,
        run_dir=str(run_dir),
        trials=list(records),
    )


# The loop's re-simulations: the observation noise told to the optimizer (the centre under
# extra seeds), the selection of the best fit among the finalists (each under fresh seeds), and
# the noise floor at the best fit.

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
