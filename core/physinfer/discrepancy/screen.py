"""Screening: the candidates no fit could name on this target, found before any is refined.

A diagnosis refines one augmented model per candidate effect (a full search, its selection
and two gaps: on an 8-s flag about 100 s each). The detection-limit ladder
(:mod:`physinfer.discrepancy.limits`) can tell beforehand that some cannot be named at any
strength in their range, and its cheap half suffices: the rungs' *shifts* (their clips
against θ̂'s own re-simulations, already measured by the baseline's gap), with no refit. The
rule's bound runs one way:

- a refit of the base parameters only lowers a rung's gap (it is never worse than θ̂), so a
  rung whose shift does not clear its threshold does not clear it after any refit; and
- a larger null scale only raises every threshold, and the null scale is held at least at
  the noise floor (:func:`physinfer.discrepancy.decide.null_scale`).

So when no rung's shift clears its threshold at the noise floor (each rung's threshold raised
by its own seed noise, as in :mod:`physinfer.discrepancy.limit_rule`), the effect's detection
limit lies beyond its range whatever the calibration finds, and its model is not refined: the
candidate is *screened out*, reported with the reason ("no signature", "hidden by its own
randomness") in ``diagnosis.json`` (``screened``) and counted as not significant. On 8-s
flags that is wind shear on every target measured and often the gusts — the two effects no
stored diagnosis ever named.

What it changes (docs/discrepancy.md, "Screening"): the stages that are refined have the
trials they had; a screened candidate is never significant (no stored table named shear or gusts);
the effect test's Bonferroni divisor still counts it (the other candidates' levels are
unchanged); and the best baseline fit no longer includes its ablated fit (its best θ with the
effect off), so the tested gap and the baseline distances every candidate is compared with
can only grow — the decisions can only lean towards "misspecified", never away. The screen
reads θ̂ of the baseline stage (not yet the control's), with the ladder's seeds, two per rung.
A deterministic phenomenon (noise floor 0) is never screened: any shift clears a zero
threshold. ``diagnose --no-screen`` refines every candidate.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.discrepancy.candidates import augmented_pipeline
from physinfer.discrepancy.clip_jobs import concurrently, pooled_probes
from physinfer.discrepancy.ladder import (
    Ladder,
    Probe,
    cross_median,
    ladder_seeds,
    pairwise,
    pairwise_median,
    run_ladder,
)
from physinfer.discrepancy.limit_rule import Threshold
from physinfer.evaluation import fixed_by_user
from physinfer.io import atomic_write_json, read_keyed_json

if TYPE_CHECKING:
    from physinfer.discrepancy.parallel import WorkerPool
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.evaluation import Pipeline

Log = Callable[[str], None]

#: Seeds per rung: the fewest the ladder uses on a chaotic phenomenon (two clips give a floor).
SCREEN_SEEDS = 2
SCREEN_FILE = "screen.json"


def judge_rungs(
    rungs: Sequence[np.ndarray], base_embeddings: np.ndarray, threshold: Threshold
) -> dict[str, Any]:
    """Whether any rung's shift clears its threshold (each raised by the rung's own noise).

    Returns:
        ``screened`` (no rung clears it), ``reason`` (when screened) and ``rungs`` (each
        rung's ``shift``, own ``floor`` and ``threshold``).
    """
    floor = pairwise_median(base_embeddings)
    base_pairs = pairwise(base_embeddings)
    floor_q95 = float(np.quantile(base_pairs, 0.95)) if base_pairs else 0.0
    records = []
    for emb in rungs:
        own = pairwise_median(emb)
        # The rung's own noise counts only beyond θ̂'s spread, as in the limit rule.
        records.append({
            "shift": cross_median(emb, base_embeddings),
            "floor": own,
            "threshold": threshold.at(own - floor if own > floor_q95 else 0.0),
        })  # fmt: skip
    # A rung that failed to simulate (NaN shift) says nothing: only a ladder measured throughout screens.
    screened = bool(records) and all(r["shift"] <= r["threshold"] for r in records)
    reason = None
    if screened:
        top, tau = records[-1], threshold.at()
        if top["shift"] > tau:
            reason = (
                f"hidden by its own randomness: at the top of its range its clips differ by {top['floor']:.3g} "
                f"({top['floor'] / max(floor, 1e-300):.2g} x the baseline's noise floor), more than its shift "
                f"{top['shift']:.3g} can beat (threshold {top['threshold']:.3g} at the noise floor)"
            )
        else:
            reason = (
                f"no signature within its range: at its top the shift is {top['shift']:.3g}, "
                f"{top['shift'] / tau:.2f} x the threshold {tau:.3g} at the noise floor"
            )
    return {"screened": screened, "reason": reason, "rungs": records}


def screen_effects(
    settings: DiagnoseSettings,
    base: Pipeline,
    render_params: Mapping[str, Any],
    theta: Mapping[str, float],
    base_embeddings: np.ndarray,
    effect_objs: Mapping[str, Any],
    say: Log,
    pool: WorkerPool | None = None,
    n_candidates: int | None = None,
) -> dict[str, dict[str, Any]]:
    """Each candidate's screen at θ̂ (cached in ``screen.json``): effect name → :func:`judge_rungs`'s
    record with the rungs' ``fraction`` and ``values``.

    ``n_candidates``: the candidates the rule counts (``None``: ``effect_objs``; more when
    some are not screened at all). Nothing is simulated for a deterministic phenomenon or
    with too few re-simulations of θ̂ (every candidate is kept)."""
    base_emb = np.asarray(base_embeddings, dtype=np.float64)
    floor = pairwise_median(base_emb) if base_emb.ndim == 2 and len(base_emb) >= 2 else 0.0
    if floor <= 0.0 or not effect_objs:
        return {}
    counted = len(effect_objs) if n_candidates is None else n_candidates
    fractions = tuple(settings.limit_config.fractions)
    seeds = tuple(ladder_seeds(settings.seed, SCREEN_SEEDS))
    space = base.simulator.parameter_space
    theta = {k: float(v) for k, v in space.complete(theta).items()}
    key = {"theta": theta, "floor": floor, "effects": sorted(effect_objs), "fractions": list(fractions),
           "seeds": list(seeds), "rule": dataclasses.asdict(settings.rule), "floor_samples": settings.floor_samples,
           "candidates": counted}  # fmt: skip
    path = settings.out / SCREEN_FILE
    if (stored := read_keyed_json(path, key)) is not None:
        return stored["effects"]
    say(f"      screening {len(effect_objs)} candidates: each effect's signature at the baseline's fit")
    # The strongest rung first: an effect whose top clears its threshold is refined, and only
    # the others' weaker rungs (whose own noise, and so threshold, may be smaller) are simulated.
    top = _simulate(settings, base, render_params, theta, effect_objs, list(effect_objs), fractions[-1:], seeds,
                    say, pool)  # fmt: skip
    thresholds = {
        name: Threshold.of(floor, len(effect.parameter_space), settings.rule, counted, settings.floor_samples)
        for name, effect in effect_objs.items()
    }
    doubtful = [name for name in effect_objs if judge_rungs(top[name].embeddings, base_emb, thresholds[name])["screened"]]
    lower = _simulate(settings, base, render_params, theta, effect_objs, doubtful, fractions[:-1], seeds, say, pool)
    result = {}
    for name in effect_objs:
        ladders = [lower[name], top[name]] if name in doubtful else [top[name]]
        record = judge_rungs([e for ladder in ladders for e in ladder.embeddings], base_emb, thresholds[name])
        fractions_values = [(f, v) for ladder in ladders for f, v in zip(ladder.fractions, ladder.values, strict=True)]
        for rung, (fraction, values) in zip(record["rungs"], fractions_values, strict=True):
            rung.update(fraction=fraction, values=values)
        result[name] = record
        say(f"      {name}: " + (f"screened out ({record['reason']})" if record["screened"] else "refined"))
    atomic_write_json(path, {"key": key, "effects": result})
    return json.loads(path.read_text())["effects"]


def refined_already(out: Path, name: str) -> bool:
    """Whether ``out`` holds the finished stage of effect ``name`` (both its gaps measured): a
    resumed diagnosis uses it rather than screen the effect out (its cost is paid)."""
    stage = out / f"effect-{name}"
    return (stage / "gap.json").is_file() and (stage / "gap_effect_off.json").is_file()


def _simulate(
    settings: DiagnoseSettings,
    base: Pipeline,
    render_params: Mapping[str, Any],
    theta: dict[str, float],
    effect_objs: Mapping[str, Any],
    names: Sequence[str],
    fractions: tuple[float, ...],
    seeds: tuple[int, ...],
    say: Log,
    pool: WorkerPool | None,
) -> dict[str, Ladder]:
    """The rungs at ``fractions`` of each effect in ``names``: all at once, each clip a job on
    the pool's workers when it has two or more; an effect whose clips fail there (or every
    effect without them) is simulated here."""
    fixed = fixed_by_user(base, settings.fixed)
    models = {name: augmented_pipeline(base, [effect_objs[name]], settings.duration_s, fixed) for name in names}

    def rungs(name: str, probe: Probe) -> Ladder:
        space = effect_objs[name].parameter_space
        return run_ladder(probe, models[name], theta, space, fractions, seeds)

    pooled = pooled_probes(pool, base, render_params)
    ladders: list[Ladder | None] = [None] * len(names)
    if pooled is not None:
        ladders = concurrently(lambda name: rungs(name, pooled(False)), list(names),
                               [f"{name}'s screen" for name in names], say)  # fmt: skip
    return {
        name: ladder if ladder is not None else rungs(name, Probe(base, render_params))
        for name, ladder in zip(names, ladders, strict=True)
    }
