"""A detection limit checked by the search the diagnosis runs (``diagnose --check-limits``).

The ladder (:mod:`physinfer.discrepancy.limits`) asks how well the base parameters mimic an
effect with a *local* refit from θ̂, and assumes the effect's model then fits as well as a
correct model does. A diagnosis runs neither: its baseline is a budget-limited search from
the centre, which can find a compensation along a ridge that a local refit misses (a ball's
drag made up by a lower restitution), and its effect model is a search from the baseline's
fit and the ridge starts (:mod:`physinfer.discrepancy.ridge`). On the bouncing ball the
local limits were several times lower than the strength a diagnosis named half the time.

So the limit of an effect that was not named is *checked*: a target is made at θ̂ with the
effect switched on at the stated limit, and the diagnosis' own stages run on it — the
baseline from the centre (``steps``), its control (``effect_steps`` from its fit), the
effect's ridge probe and its model's search (``effect_steps``), each gap from the same ``K``
re-simulation seeds — and decided by the diagnosis' rule at the null scale its limits
assume. Named: the limit stands, checked. Not named: the strength is doubled and checked
again, up to the far end of the range (at most :data:`MAX_CHECKS` strengths); where none is
named, the limit is ``None``: the local refit says the effect is visible, but this
diagnosis' search does not name it anywhere in its range. Where a doubling was named, the
limit lies between it and the strength before, and reading it at the top of that bracket
overstates it by up to twice (on the bouncing ball the checked limits were 2.5 times the
strength named half the time): the bracket is halved (:data:`BISECTIONS`, at its geometric
midpoint, as a ratio is what a limit is judged by) and the lowest strength named is the limit.

Each check is a small diagnosis of its own under ``limit-check/<effect>-<fraction>/``
(resumable); ``limit_check.json`` holds the records. It costs about one baseline, one
control and one effect search per strength checked, so it is off by default.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.discrepancy.candidates import augmented_pipeline, warm_start
from physinfer.discrepancy.decide import effect_significance, final_verdict, misspecification
from physinfer.discrepancy.ladder import moved_values, strength_path, values_at
from physinfer.discrepancy.ridge import ridge_starts
from physinfer.discrepancy.stages import (
    GapContext,
    ablated_stage,
    baseline_video_start,
    calibration_target,
    effect_stage,
    run_stage,
)
from physinfer.evaluation import fixed_by_user, noise_seeds
from physinfer.io import atomic_write_json, read_keyed_json

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.evaluation import Pipeline
    from physinfer.registry import Registry
    from physinfer.roles import Target

Log = Callable[[str], None]

CHECK_FILE = "limit_check.json"
#: The checks' optimizer seeds are the diagnosis seed plus this (never a stage's own).
SEED_OFFSET = 104729
#: Strengths checked at most: the stated limit, then doubled until named or at the far end.
MAX_CHECKS = 5
#: Halvings (geometric) of the bracket between the last strength not named and the first
#: named: one leaves the limit within a factor √2 of where this search begins to name it.
BISECTIONS = 1


def bracket_search(check: Callable[[float], dict[str, Any]], fraction: float) -> list[dict[str, Any]]:
    """The strengths checked for a limit stated at ``fraction`` of the range, in order.

    Doubled from ``fraction`` until one is named or the far end (1) is checked (at most
    :data:`MAX_CHECKS`); then, where a strength below the first named one was not named,
    their bracket is halved :data:`BISECTIONS` times at its geometric midpoint.

    Args:
        check: A strength (fraction of the range) → its record, with ``named`` and ``fraction``.
        fraction: The stated (local) limit, in ``(0, 1]``.

    Returns:
        Every check's record, in the order run.
    """
    ladder = [min(1.0, fraction * 2.0**i) for i in range(MAX_CHECKS)]
    tried: list[dict[str, Any]] = []
    for f in dict.fromkeys(ladder[: next((i + 1 for i, v in enumerate(ladder) if v >= 1.0), MAX_CHECKS)]):
        tried.append(check(f))
        if tried[-1]["named"]:
            break
    if len(tried) < 2 or not tried[-1]["named"]:
        return tried  # the stated limit named at once, or nothing named: no bracket
    low, high = tried[-2]["fraction"], tried[-1]["fraction"]
    for _ in range(BISECTIONS):
        tried.append(check(float(np.sqrt(low * high))))
        low, high = (low, tried[-1]["fraction"]) if tried[-1]["named"] else (tried[-1]["fraction"], high)
    return tried


def check_one(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    theta: Mapping[str, float],
    name: str,
    effect: Any,
    fraction: float,
    scale: float,
    n_candidates: int,
    steps: int,
    effect_steps: int,
    seeds: tuple[int, ...],
) -> dict[str, Any]:
    """The diagnosis' stages on a target made at θ̂ with ``effect`` at ``fraction``; its decision."""
    space = effect.parameter_space
    moved, held = strength_path(space)
    values = values_at(space, moved, held, fraction)
    sub = dataclasses.replace(settings, out=settings.out / "limit-check" / f"{name}-{fraction:.4g}",
                              seed=settings.seed + SEED_OFFSET)  # fmt: skip
    sub.out.mkdir(parents=True, exist_ok=True)
    model = augmented_pipeline(base, [effect], settings.duration_s, fixed_by_user(base, settings.fixed))
    target_seed = noise_seeds(settings.seed + 17, 1, salt=0xC4EC)[0]
    encode_dir = sub.out if settings.target_path is not None else None
    check_target = calibration_target(model, {**theta, **values}, target, target_seed, encode_dir)
    embedding = base.embedder.embed(check_target.clip)
    gaps = GapContext(check_target, embedding, seeds, sub.out)
    common = {"registry": registry, "settings": sub, "target_label": "limit check"}
    baseline = run_stage("baseline", base, check_target, steps=steps, start=None,
                         video_start=baseline_video_start(settings.out), **common)  # fmt: skip
    gap0 = gaps.measure(base, baseline.best_params, "baseline")
    control = run_stage("control", base, check_target, steps=effect_steps, start=baseline.best_params, **common)
    control_gap = gaps.measure(base, control.best_params, "control")
    if settings.ridge_starts:
        ridge_starts(sub, base, check_target.render_params, baseline.best_params, embedding, gap0.floor,
                     {name: effect}, lambda _msg: None)  # fmt: skip
    stage = effect_stage(name, effect, base, check_target, baseline.best_params, gaps, effect_steps=effect_steps,
                         **common)  # fmt: skip
    ablated = ablated_stage(stage, base, gaps)
    before = min([(float(control_gap.gap), control_gap), (float(ablated.gap.gap), ablated.gap)], key=lambda g: g[0])[1]
    decision = effect_significance(
        distances=stage.gap.to_target or [], baseline_distances=before.to_target or [], gap=float(stage.gap.gap),
        gap_before=float(before.gap), n_params=len(space), scale=scale, rule=settings.rule,
    )  # fmt: skip
    record = {"effect": name, "significant": decision["significant"], "p_value": decision["p_value"]}
    verdict = final_verdict(misspecification(float(before.gap), scale, settings.rule), [record], settings.rule,
                            n_candidates=n_candidates)  # fmt: skip
    named = bool(verdict.misspecified and decision["significant"])
    off = warm_start(baseline.best_params, [effect])
    return {
        "fraction": fraction,
        "values": {k: v for k, v in values.items() if k in moved},
        "named": named,
        "misspecified": bool(verdict.misspecified),
        "significant": bool(decision["significant"]),
        "gap_before": float(before.gap),
        "gap": float(stage.gap.gap),
        "p_value": float(decision["p_value"]),
        "fitted": {k: float(stage.result.best_params[k]) for k in space.names},
        "baseline_fit": {k: float(v) for k, v in off.items() if k not in space.names},
    }


def check_limits(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    theta: Mapping[str, float],
    limits: Mapping[str, Mapping[str, Any]],
    effect_objs: Mapping[str, Any],
    named: str | None,
    scale: float,
    n_candidates: int,
    steps: int,
    effect_steps: int,
    seeds: tuple[int, ...],
    say: Log,
) -> dict[str, dict[str, Any]]:
    """Each not-named candidate's limit checked by the diagnosis' search (cached in
    ``limit_check.json``): effect name → ``checks`` (one record per strength tried),
    ``detectable_from`` (the lowest strength named, or ``None``), ``local`` (the ladder's)
    and ``reason`` (where none was named)."""
    key = {"theta": {k: float(v) for k, v in theta.items()}, "scale": scale, "steps": steps, "checks": MAX_CHECKS,
           "bisections": BISECTIONS, "effect_steps": effect_steps, "seeds": list(seeds), "ridge": settings.ridge_starts,
           "limits": {n: limits[n].get("fraction") for n in sorted(limits)}}  # fmt: skip
    path = settings.out / CHECK_FILE
    if (stored := read_keyed_json(path, key)) is not None:
        return stored["effects"]
    result: dict[str, dict[str, Any]] = {}
    for name, limit in limits.items():
        fraction = limit.get("fraction")
        if name == named or fraction is None or not np.isfinite(fraction) or name not in effect_objs:
            continue

        def check(f: float, name: str = name) -> dict[str, Any]:
            say(f"      checking {name}'s limit: this diagnosis' stages on a target with it at {f:.3g} of its range")
            return check_one(registry, settings, base, target, theta, name, effect_objs[name], f, scale,
                             n_candidates, steps, effect_steps, seeds)  # fmt: skip

        tried = bracket_search(check, float(fraction))
        found = min((r for r in tried if r["named"]), key=lambda r: r["fraction"], default=None)
        local = moved_values(effect_objs[name].parameter_space, float(fraction))
        reason = None
        if found is None:
            where = " and ".join(", ".join(f"{k} = {v:.3g}" for k, v in r["values"].items()) for r in tried)
            reason = (f"the local refit puts it within reach, but this diagnosis' search did not name it at {where}: "
                      "reachable only from a start the diagnosis does not make, or not at this null scale")  # fmt: skip
        result[name] = {"checks": tried, "detectable_from": None if found is None else found["values"],
                        "fraction": None if found is None else found["fraction"], "local": local,
                        "reason": reason}  # fmt: skip
        say(f"      {name}: " + ("named by the search from " + ", ".join(f"{k} ≥ {v:.3g}" for k, v in
                                 found["values"].items()) if found else reason))  # fmt: skip
    atomic_write_json(path, {"key": key, "effects": result})
    return json.loads(path.read_text())["effects"]


def apply_checks(candidates: list[dict[str, Any]], checked: Mapping[str, Mapping[str, Any]]) -> None:
    """Put each checked limit in its candidate's dict record (in place; see :func:`checked_limit`)."""
    for cand in candidates:
        if (check := checked.get(cand["effect"])) is not None:
            cand["detectable_from"], cand["limit"] = checked_limit(cand["detectable_from"], cand["limit"], check)


def checked_limit(
    detectable_from: Mapping[str, float] | None, limit: Mapping[str, Any], check: Mapping[str, Any]
) -> tuple[Mapping[str, float] | None, dict[str, Any]]:
    """A candidate's limit once checked: ``detectable_from`` becomes the checked one, the
    ladder's is kept as ``limit.local_detectable_from``, the records as ``limit.search_check``
    (and the reason, where none was named, as ``limit.reason``).

    Returns:
        The new ``detectable_from`` and ``limit``.
    """
    limit = {**limit, "local_detectable_from": detectable_from, "search_check": dict(check)}
    if check["reason"]:
        limit["reason"] = check["reason"]
    return check["detectable_from"], limit
