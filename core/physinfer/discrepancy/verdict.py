"""The verdict of a diagnosis: every candidate judged, the model called misspecified or not,
an effect named or none, and the notes that say what is left.

:func:`judge_stages` applies the rules of :mod:`physinfer.discrepancy.decide` to the refined
stages at one null scale; :mod:`physinfer.discrepancy.workflow` calls it at the scales the
self-consistency runs leave possible (:mod:`physinfer.discrepancy.self_consistency`) and at
the one it reports. :func:`verdict_notes` then adds what a user reads beside the decision:

- *Misspecified and nothing named* (:func:`closest_unnamed`). A diagnosis that finds the
  model misspecified but names no effect leaves the user with two readings: the missing term
  is none of the registered effects, or one of them is but its search did not find it (an
  effect that trades off with a base parameter hides along a ridge:
  :mod:`physinfer.discrepancy.ridge`). The report's ``unnamed`` tells them apart as far as the
  diagnosis can: the closest candidate (the smallest gap ratio), the checks it failed, and
  whether its best θ is the baseline's fit with the effect off — its search then never left
  the baseline's basin, and the name is undecided rather than refused. What would settle it
  is said in options: more trials, holding a measured base parameter (the one the effect
  trades off with: the detection limit's ``mimicked_by`` or the largest ``reveal``, else the
  base parameter the effect's search moved most), a longer clip.
- *Not misspecified, but a lead* (:func:`closest_lead`): a candidate whose search switched
  its effect on and took a large share of the gap, but whose improvement stays within the
  null scale of this clip. On a short clip that is how an effect above the documented limit
  of longer clips shows (the flag's 32° yaw on the default 2.4-s clip); the report names the
  lead and what would settle it, without naming it.
- *What the named model still leaves* (``named_leaves``,
  :func:`physinfer.discrepancy.decide.remainder_after_naming`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from physinfer.discrepancy.candidates import warm_start
from physinfer.discrepancy.decide import (
    DecisionRule,
    effect_significance,
    final_verdict,
    misspecification,
    name_effect,
)
from physinfer.discrepancy.records import Candidate, Note, Verdict
from physinfer.discrepancy.stages import Stage
from physinfer.parameters import ParameterSpace

#: A search "ended at the baseline" when its best θ lies this close to θ̂ with the effect
#: off, in normalised units (a fiftieth of each range).
AT_START = 0.04

#: A candidate that left at most this share of the gap is a lead (:func:`closest_lead`).
#: Measured (2026-11-26): on 15 clean targets (pendulum 5, flag_lite 10, stored tables) and 5
#: clean bouncing-ball targets the closest candidate left x0.98 or more; on hidden effects the
#: gap test missed (flag yaw ±32° on 2.4-s clips, a flag_lite 8-s yaw) it left x0.29-0.57.
LEAD_RATIO = 0.75

_CHECK_WORDS = {
    "beats_seed_noise": "its distances do not beat the baseline's by the rank test",
    "beats_null_scale": "its improvement is within the null scale",
    "pays_for_parameters": "its improvement does not pay for its parameters",
}


def judge_stages(
    stages: list[Stage],
    before: Stage,
    tested: float,
    scale: float,
    rule: DecisionRule,
    effect_objs: Mapping[str, Any],
) -> tuple[list[Candidate], Verdict, str | None]:
    """Every decision at null scale ``scale``: the candidates' records, the verdict, the named effect."""
    gap_before = float(before.gap.gap)
    candidates = [_candidate(stage, before, gap_before, scale, rule, effect_objs[stage.label]) for stage in stages[1:]]
    # Candidates screened out count in the effect test's divisor: the others' levels do not change.
    tests = final_verdict(misspecification(tested, scale, rule), candidates, rule, n_candidates=len(effect_objs))
    named = name_effect(candidates, tests.misspecified)
    after = next((s for s in stages if s.label == named), before)
    verdict = dataclasses.replace(tests, named_effect=named, gap_before=gap_before, gap_after=float(after.gap.gap))
    return candidates, verdict, named


def _candidate(stage: Stage, before: Stage, gap_before: float, scale: float, rule: DecisionRule, effect: Any) -> Candidate:
    """One effect's stage judged against the best baseline fit ``before``."""
    decision = effect_significance(
        distances=stage.gap.to_target or [],
        baseline_distances=before.gap.to_target or [],
        gap=float(stage.gap.gap),
        gap_before=gap_before,
        n_params=stage.n_params,
        scale=scale,
        rule=rule,
    )
    return Candidate(
        effect=stage.label,
        description=effect.description,
        gap=float(stage.gap.gap),
        n_params=stage.n_params,
        **decision,
        best_params=stage.result.best_params,
        effect_params={k: stage.result.best_params[k] for k in effect.parameter_space.names},
        at_bounds=stage.result.place.at_bounds if stage.result.place is not None else {},
        distances=tuple(stage.gap.to_target or []),
        floor=stage.gap.floor,
        run_dir=stage.result.run_dir,
    )


def verdict_notes(
    verdict: Verdict,
    stages: Sequence[Stage],
    candidates: Sequence[Candidate],
    remainder: dict[str, Any] | None,
    *,
    baseline_best: Mapping[str, float],
    before_best: Mapping[str, float],
    effect_steps: int,
    clip_seconds: float | None,
    user_video: bool,
) -> tuple[Verdict, dict[str, dict[str, Any] | None]]:
    """The verdict with its notes, and the notes as the report writes them.

    Args:
        verdict: The verdict :func:`judge_stages` returned at the reported null scale.
        stages: The refined stages (the control first, then each effect's).
        candidates: The candidates' records (with their detection limits where measured).
        remainder: What the named model still leaves
            (:func:`physinfer.discrepancy.decide.remainder_after_naming`).
        baseline_best: The baseline stage's best fit (where each effect's search started).
        before_best: The best baseline fit of any stage (the values ``--fix`` would hold).
        effect_steps: The effect searches' budget.
        clip_seconds: The clip's length (``None``: not known).
        user_video: The target is a user's video.

    Returns:
        The verdict with ``named_leaves``, ``unnamed`` and ``lead`` set, and the same three
        as records (``None`` where there is none).
    """
    ends = {s.label: stage_end(s, baseline_best) for s in stages[1:]}
    misspecified, named = verdict.misspecified, verdict.named_effect
    unnamed = closest_unnamed(
        candidates, ends, misspecified=misspecified, named=named, baseline_best=before_best,
        effect_steps=effect_steps, clip_seconds=clip_seconds, user_video=user_video,
    )  # fmt: skip
    lead = closest_lead(candidates, ends, misspecified=misspecified, named=named, effect_steps=effect_steps,
                        clip_seconds=clip_seconds, user_video=user_video)  # fmt: skip
    notes = {"named_leaves": remainder, "unnamed": unnamed, "lead": lead}
    return dataclasses.replace(verdict, **{key: Note.from_dict(note) for key, note in notes.items()}), notes


def search_end(space: ParameterSpace, best: Mapping[str, float], start: Mapping[str, float],
               effect_names: Sequence[str]) -> dict[str, Any]:  # fmt: skip
    """Where an effect's search ended against θ̂ with the effect off (both physical θ of ``space``).

    Returns:
        ``moved`` (the largest normalised change of any parameter), ``effect_moved`` (of the
        effect's), ``at_baseline`` (``moved ≤ AT_START``), ``effect_off`` (``effect_moved ≤
        AT_START``) and ``base_moves`` (base parameter → normalised change).
    """
    u_best = space.to_unit(space.complete(best))
    u_start = space.to_unit(space.complete(start))
    delta = {name: float(b - s) for name, b, s in zip(space.names, u_best, u_start, strict=True)}
    moved = max((abs(v) for v in delta.values()), default=0.0)
    effect_moved = max((abs(delta[n]) for n in effect_names if n in delta), default=0.0)
    return {
        "moved": moved,
        "effect_moved": effect_moved,
        "at_baseline": moved <= AT_START,
        "effect_off": effect_moved <= AT_START,
        "base_moves": {n: v for n, v in delta.items() if n not in effect_names},
    }


def stage_end(stage: Any, baseline_best: Mapping[str, float]) -> dict[str, Any]:
    """:func:`search_end` of an effect's stage (:class:`physinfer.discrepancy.stages.Stage`)
    against the baseline's fit with its effect off."""
    effects = list(stage.pipeline.effects)
    names = [n for effect in effects for n in effect.parameter_space.names]
    start = warm_start(baseline_best, effects)
    return search_end(stage.pipeline.simulator.parameter_space, stage.result.best_params, start, names)


def closest_unnamed(
    candidates: Sequence[Mapping[str, Any]],
    ends: Mapping[str, Mapping[str, Any]],
    *,
    misspecified: bool,
    named: str | None,
    baseline_best: Mapping[str, float],
    effect_steps: int,
    clip_seconds: float | None = None,
    user_video: bool = False,
) -> dict[str, Any] | None:
    """The report's ``unnamed``: ``None`` unless the model is misspecified and nothing named.

    Args:
        candidates: The refined candidates (:class:`~physinfer.discrepancy.records.Candidate`
            records or their dicts: ``effect``, ``ratio``, ``checks``; ``limit`` where the
            detection limits ran).
        ends: Effect name → :func:`search_end`'s record of its search.
        misspecified: The verdict.
        named: The named effect.
        baseline_best: The baseline's best fit (the values ``--fix`` would hold).
        effect_steps: The effect searches' budget.
        clip_seconds: The clip's length (``None``: not known; no longer clip is proposed).
        user_video: The target is a user's video (a longer one must be filmed: :func:`longer_clip`).

    Returns:
        ``effect``, ``ratio``, ``failed`` (the checks it failed), ``ended_at_baseline``,
        ``effect_off``, ``trades_off_with`` (base parameters), ``settle`` (options that would
        settle it) and a one-line ``message``.
    """
    if not misspecified or named is not None or not candidates:
        return None
    best, name, failed = _closest(candidates)
    end = ends.get(name, {})
    partners = _partners(best.get("limit") or {}, end)
    trapped = bool(end.get("at_baseline") or end.get("effect_off"))
    settle = [f"more trials for the effects' searches (--effect-steps {2 * effect_steps})"]
    settle += [f"--fix {p}=<its measured value> (the baseline fit says {baseline_best[p]:.4g})"
               for p in partners[:1] if p in baseline_best]  # fmt: skip
    if clip_seconds:
        settle.append(longer_clip(clip_seconds, user_video))
    where = (
        "its search ended at the baseline's fit with the effect off (a trapped search: the name is undecided)"
        if end.get("at_baseline")
        else "its search ended with the effect off (a trapped search: the name is undecided)"
        if end.get("effect_off")
        else "its search left the baseline's fit"
    )
    trade = f"; {name} trades off with {' and '.join(partners)}" if partners else ""
    why = f" ({'; '.join(failed)})" if failed else ""
    message = (
        f"nothing named, though the model is misspecified: the closest candidate, {name}, left "
        f"x{float(best['ratio']):.2f} of the gap{why}; {where}{trade}. To settle it: " + "; ".join(settle)
    )
    return {
        "effect": name,
        "ratio": float(best["ratio"]),
        "failed": failed,
        "ended_at_baseline": bool(end.get("at_baseline")),
        "effect_off": bool(end.get("effect_off")),
        "trapped": trapped,
        "trades_off_with": partners,
        "settle": settle,
        "message": message,
    }


def closest_lead(
    candidates: Sequence[Mapping[str, Any]],
    ends: Mapping[str, Mapping[str, Any]],
    *,
    misspecified: bool,
    named: str | None,
    effect_steps: int,
    clip_seconds: float | None = None,
    user_video: bool = False,
) -> dict[str, Any] | None:
    """The report's ``lead``: a candidate worth a second look when the model is *not* found
    misspecified.

    ``None`` unless nothing is misspecified or named, and the closest candidate left at most
    :data:`LEAD_RATIO` of the gap with its effect switched on (its search did not end with the
    effect off). The decision is unchanged: a lead is not a name.

    Args:
        candidates: The refined candidates (:class:`~physinfer.discrepancy.records.Candidate`
            records or their dicts: ``effect``, ``ratio``, ``checks``, ``effect_params``).
        ends: Effect name → :func:`search_end`'s record of its search.
        misspecified: The verdict.
        named: The named effect.
        effect_steps: The effect searches' budget.
        clip_seconds: The clip's length (``None``: not known; no longer clip is proposed).
        user_video: The target is a user's video (a longer one must be filmed: :func:`longer_clip`).

    Returns:
        ``effect``, ``ratio``, ``effect_params``, ``failed`` (the checks it failed), ``settle``
        and a one-line ``message``.
    """
    if misspecified or named is not None or not candidates:
        return None
    best, name, failed = _closest(candidates)
    ratio = float(best.get("ratio", np.inf))
    if not ratio <= LEAD_RATIO or ends.get(name, {}).get("effect_off", False):
        return None
    values = {str(k): float(v) for k, v in (best.get("effect_params") or {}).items()}
    settle = [longer_clip(clip_seconds, user_video)] if clip_seconds else []
    settle.append(f"more trials for the effects' searches (--effect-steps {2 * effect_steps})")
    at = ", ".join(f"{k} = {v:.3g}" for k, v in values.items())
    why = f" ({'; '.join(failed)})" if failed else ""
    message = (
        f"not misspecified on this clip, but a lead: {name}{f' ({at})' if at else ''} left "
        f"x{ratio:.2f} of the gap, too little to name{why}. To settle it: " + "; ".join(settle)
    )
    return {"effect": name, "ratio": ratio, "effect_params": values, "failed": failed, "settle": settle,
            "message": message}  # fmt: skip


def longer_clip(clip_seconds: float, user_video: bool) -> str:
    """What a clip twice as long means: a longer video to film (``--duration`` cannot lengthen a
    user's video: the simulations last as long as it does), or ``--duration`` for a target the
    phenomenon renders itself."""
    if user_video:
        return f"a longer video of the same scene (about {2 * clip_seconds:.3g} s)"
    return f"a longer clip (--duration {2 * clip_seconds:.3g})"


def _closest(candidates: Sequence[Mapping[str, Any]]) -> tuple[Mapping[str, Any], str, list[str]]:
    """The candidate with the smallest gap ratio, its name and the checks it failed, in words."""
    best = min(candidates, key=lambda c: float(c.get("ratio", np.inf)))
    failed = [_CHECK_WORDS.get(k, k) for k, ok in (best.get("checks") or {}).items() if not ok]
    return best, str(best["effect"]), failed


def _partners(limit: Mapping[str, Any], end: Mapping[str, Any]) -> list[str]:
    """The base parameters the effect trades off with: the limit's ``mimicked_by``, else the
    parameter whose ``reveal`` lowers the limit most, else those its search moved most."""
    mimics = limit.get("mimicked_by") or []
    if mimics:
        return [str(m) for m in mimics]
    reveal = [r for r in limit.get("reveal") or [] if isinstance(r, Mapping) and r.get("kind") == "fix"]
    if reveal:  # the largest factor; a limit reached only by fixing it (factor None) first
        top = max(reveal, key=lambda r: np.inf if r.get("factor") is None else float(r["factor"]))
        return [str(top["parameter"])]
    moves = {k: abs(v) for k, v in (end.get("base_moves") or {}).items() if abs(v) > AT_START}
    return sorted(moves, key=lambda k: -moves[k])[:1]
