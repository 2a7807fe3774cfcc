"""Every decision of a diagnosis at one null scale, from its refined stages.

:mod:`physinfer.discrepancy.workflow` calls :func:`judge_stages` at the scales the
self-consistency runs leave possible (:mod:`physinfer.discrepancy.needed_calibration`) and at
the one it reports; the rules themselves are in :mod:`physinfer.discrepancy.decide`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from physinfer.discrepancy.decide import (
    DecisionRule,
    effect_significance,
    final_verdict,
    misspecification,
    name_effect,
)
from physinfer.discrepancy.records import Candidate, Verdict
from physinfer.discrepancy.stages import Stage


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
