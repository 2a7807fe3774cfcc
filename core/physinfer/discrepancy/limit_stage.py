"""A diagnosis' detection-limit stage: each candidate's ladder at the best baseline fit,
cached in ``limits.json`` (the method is :mod:`physinfer.discrepancy.limits`)."""

from __future__ import annotations

import dataclasses
import functools
import json
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.discrepancy.candidates import augmented_pipeline
from physinfer.discrepancy.clip_jobs import pooled_probes
from physinfer.discrepancy.gap import measure_gap
from physinfer.discrepancy.ladder import LimitInputs
from physinfer.discrepancy.limits import detection_limits
from physinfer.discrepancy.stages import Stage
from physinfer.evaluation import Pipeline, build_pipeline, fixed_by_user, noise_seeds
from physinfer.io import atomic_write_json, read_keyed_json
from physinfer.refinement import RefineResult
from physinfer.registry import Registry
from physinfer.roles import Target

if TYPE_CHECKING:
    from physinfer.discrepancy.parallel import WorkerPool
    from physinfer.discrepancy.settings import DiagnoseSettings

Log = Callable[[str], None]


def diagnosis_simulations(
    settings: DiagnoseSettings,
    results: Sequence[RefineResult],
    calibration_runs: int,
    n_gaps: int,
    unrefined: int = 0,
) -> int:
    """Simulations a diagnosis costs with all its ``calibration_runs`` and its ``unrefined``
    (screened-out) candidates (the ladder's budget: a share of this, whether or not the runs
    were needed or the candidates refined; trials, selection re-simulations, gap measurements)."""
    stages = len(results) + unrefined + calibration_runs * (2 if settings.calibration_control else 1)
    per_stage_trials = sum(r.n_trials for r in results) / max(len(results), 1)
    steps = settings.steps or per_stage_trials
    effect_steps = settings.effect_steps or steps
    calibration_trials = calibration_runs * (
        steps + (effect_steps if settings.calibration_control else 0)
    )
    select = settings.select_top * settings.select_seeds * stages
    return int(
        sum(r.n_trials for r in results)
        + unrefined * effect_steps
        + calibration_trials
        + select
        + n_gaps * settings.floor_samples
    )


def run_limits(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    before: Stage,
    effect_objs: Mapping[str, Any],
    scale: float,
    n_sims: int,
    say: Log,
    pool: WorkerPool | None = None,
    scale_low: float | None = None,
    n_candidates: int | None = None,
) -> dict[str, Any]:
    """Every candidate's detection limit at the best baseline fit, cached in ``limits.json``;
    the effects' ladders side by side on ``pool`` when it has workers. ``scale_low``: where
    the null scale is only known as a range (``scale`` its upper end), its lower end, at
    which each limit is read again from the same ladder (``at_lower_scale``).
    ``n_candidates``: the candidates the rule counts, screened-out ones included (``None``:
    ``effect_objs``)."""
    theta = before.best_params
    fixed = fixed_by_user(base, settings.fixed)
    key = _limits_key(settings, theta, scale, scale_low, effect_objs, n_candidates)
    path = settings.out / "limits.json"
    if (stored := read_keyed_json(path, key)) is not None:
        return stored["limits"]
    embeddings = _fit_embeddings(settings, base, target, before)
    augmented = {
        name: augmented_pipeline(base, [effect], settings.duration_s, fixed)
        for name, effect in effect_objs.items()
    }
    say(
        f"      detection limits: a ladder of {len(settings.limit_config.fractions)} strengths per effect "
        "at the best baseline fit"
    )
    inputs = LimitInputs(
        base=base,
        augmented=augmented,
        theta=theta,
        base_embeddings=embeddings,
        render_params=target.render_params,
        scale=scale,
        rule=settings.rule,
        floor_samples=settings.floor_samples,
        seed=settings.seed,
        diagnosis_simulations=n_sims,
        make_longer=functools.partial(_longer_models, registry, settings, base, effect_objs, fixed),
        scale_low=scale_low,
        n_candidates=n_candidates,
        encoded=settings.target_path is not None,
    )
    pooled = pooled_probes(pool, base, target.render_params)
    if pooled is not None:
        say(f"      the ladders' clips run on {pool.where()}")  # type: ignore[union-attr] - a pool
    limits = detection_limits(inputs, settings.limit_config, log=say, pooled=pooled)
    atomic_write_json(path, {"key": key, "limits": limits})
    return json.loads(path.read_text())["limits"]  # as a resumed diagnosis reads it (NaN as null)


def _limits_key(
    settings: DiagnoseSettings,
    theta: Mapping[str, float],
    scale: float,
    scale_low: float | None,
    effect_objs: Mapping[str, Any],
    n_candidates: int | None,
) -> dict[str, Any]:
    """What ``limits.json`` was computed for: a stored record is reused only under the same key."""
    return {
        "theta": {k: float(v) for k, v in theta.items()},
        "scale": float(scale),
        **({"scale_low": float(scale_low)} if scale_low is not None else {}),
        "effects": sorted(effect_objs),
        "config": settings.limit_config.to_dict(),
        "seed": settings.seed,
        "rule": dataclasses.asdict(settings.rule),
        "floor_samples": settings.floor_samples,
        **({"n_candidates": n_candidates} if n_candidates is not None else {}),
    }


def _fit_embeddings(settings: DiagnoseSettings, base: Pipeline, target: Target, before: Stage) -> np.ndarray:
    """``(K, D_e)``: the best baseline fit's re-simulations' embeddings, measured again where
    its gap was measured before embeddings were kept."""
    embeddings = np.asarray(before.gap.embeddings)
    if embeddings.ndim != 2 or len(embeddings) < 2:  # a gap measured before embeddings were kept
        seeds = noise_seeds(settings.seed + 2, settings.floor_samples)
        embeddings = measure_gap(
            base, before.best_params, target.render_params, np.zeros(1), seeds=seeds
        ).embeddings
    return embeddings


def _longer_models(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    effect_objs: Mapping[str, Any],
    fixed: Mapping[str, float],
    seconds: float,
) -> tuple[Any, dict[str, Any], Any]:
    """The baseline's simulator, each effect's and the embedder for a clip of ``2 · seconds``
    (the embedder reading twice the frames): the "a longer clip" what-if's models."""
    frames = settings.embedder_frames or getattr(base.embedder, "n_frames", None)
    longer = build_pipeline(
        registry, settings.plugin, embedder=settings.embedder, weights=settings.weights, device=settings.device,
        duration_s=2 * seconds, embedder_frames=None if frames is None else 2 * int(frames), fixed=settings.fixed,
    )  # fmt: skip
    sims = {
        name: augmented_pipeline(longer, [e], 2 * seconds, fixed).simulator
        for name, e in effect_objs.items()
    }
    return longer.simulator, sims, longer.embedder
