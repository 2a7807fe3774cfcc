"""Every decision of a diagnosis at one null scale, from its refined stages.

:mod:`physinfer.discrepancy.workflow` calls :func:`judge_stages` at the scales the
self-consistency runs leave possible (:mod:`physinfer.discrepancy.needed_calibration`) and at
the one it reports; the rules themselves are in :mod:`physinfer.discrepancy.decide`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from physinfer.discrepancy.decide import (
    DecisionRule,
    effect_significance,
    final_verdict,
    misspecification,
    name_effect,
)
from physinfer.discrepancy.stages import Stage


def judge_stages(
    stages: list[Stage],
    before: Stage,
    tested: float,
    scale: float,
    rule: DecisionRule,
    effect_objs: Mapping[str, Any],
) -> tuple[list[dict[str, Any]], dict[str, Any], str | None]:
    """Every decision at null scale ``scale``: the candidates' records, the verdict, the named effect."""
    gap_before = float(before.gap.gap)
    candidates = []
    for stage in stages[1:]:
        decision = effect_significance(
            distances=stage.gap.to_target or [],
            baseline_distances=before.gap.to_target or [],
            gap=float(stage.gap.gap),
            gap_before=gap_before,
            n_params=stage.n_params,
            scale=scale,
            rule=rule,
        )
        candidates.append(
            {
                "effect": stage.label,
                "description": effect_objs[stage.label].description,
                "gap": float(stage.gap.gap),
                "n_params": stage.n_params,
                **decision,
                "best_params": stage.result.best_params,
                "effect_params": {k: stage.result.best_params[k] for k in effect_objs[stage.label].parameter_space.names},
                "at_bounds": stage.result.extra.get("at_bounds", {}),
                "distances": list(stage.gap.to_target or []),
                "floor": stage.gap.floor,
                "run_dir": stage.result.run_dir,
            }
        )
    # Candidates screened out count in the effect test's divisor: the others' levels do not change.
    verdict = final_verdict(misspecification(tested, scale, rule), candidates, rule, n_candidates=len(effect_objs))
    return candidates, verdict, name_effect(candidates, verdict["misspecified"])
