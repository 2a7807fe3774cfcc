"""A diagnosis' outputs: localisation maps, the gap figure, the side-by-side video, the
model file, and the report's numbers (``diagnosis.json``, described in docs/discrepancy.md)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.discrepancy.figures import plot_gaps, plot_maps
from physinfer.discrepancy.gap import gap_numbers
from physinfer.discrepancy.localise import localise
from physinfer.discrepancy.model import ModelFile, write_model
from physinfer.discrepancy.records import Candidate, Verdict
from physinfer.discrepancy.stages import Stage, clip_of
from physinfer.evaluation import NoiseFloor, fixed_by_user, full_parameter_space
from physinfer.refinement import RefineResult
from physinfer.roles import Target
from physinfer.rundir import optional_settings
from physinfer.scene import scene_of
from physinfer.video import side_by_side, write_video

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings


@dataclass(frozen=True)
class Findings:
    """What a diagnosis' stages found and decided: what its outputs show.

    Attributes:
        baseline: The baseline stage's refinement.
        gap0: The baseline's gap at its best fit.
        stages: The control, then one stage per refined effect.
        before: The best baseline fit any stage found (an effect must beat it).
        after: The named effect's stage (``before`` when nothing is named).
        named: The named effect, or ``None``.
        candidates: One record per refined candidate effect (its detection limit set once the
            limits ran); ``diagnosis.json`` holds their ``to_dict()``.
        verdict: The decision (misspecified, by which test, the effect named; the notes on it
            once the workflow added them).
        scale: The null scale the decisions are made at.
        self_gap: The self-consistency runs' summary gap (``None``: not every run refined).
        calibration: Each self-consistency run's record.
    """

    baseline: RefineResult
    gap0: NoiseFloor
    stages: Sequence[Stage]
    before: Stage
    after: Stage
    named: str | None
    candidates: list[Candidate]
    verdict: Verdict
    scale: float
    self_gap: float | None
    calibration: Sequence[Mapping[str, Any]]


def write_outputs(settings: DiagnoseSettings, target: Target, found: Findings) -> dict[str, Any]:
    """Localise, draw, write the model file and videos; assemble the report."""
    numbers, after_numbers, rows, clips = _localise_fits(settings, target, found)
    figures = _draw_figures(settings, rows, found)
    videos = {}
    if settings.videos:
        videos["side_by_side"] = str(write_video(settings.out / "side_by_side.mp4", side_by_side(clips)))
    model = _write_model_file(settings, found.after)
    return {
        **_decision_numbers(settings, target, found),
        "candidates": [c.to_dict() for c in found.candidates],
        "regions": numbers["regions"],
        "localisation": numbers["global"],
        "regions_after": None if after_numbers is None else after_numbers["regions"],
        "model_file": str(settings.out / "model.json"),
        "model": {"effects": list(model.effects), "values": model.values},
        "figures": figures,
        "videos": videos,
        "settings": _settings_numbers(settings, found),
        "seeds_checked": [int(s) for s in np.asarray(found.before.gap.seeds)],
    }


def _localise_fits(
    settings: DiagnoseSettings, target: Target, found: Findings
) -> tuple[dict[str, Any], dict[str, Any] | None, list[tuple[str, Any]], list[Any]]:
    """The best baseline fit (and the named effect's) simulated and compared with the target.

    Returns:
        The baseline fit's localisation numbers, the named fit's (``None``: nothing named),
        the maps' rows (label, maps) and the clips side by side (target first).
    """
    before, after, named = found.before, found.after, found.named
    fit_before = clip_of(before.pipeline, before.best_params, target, settings.seed)
    numbers, t_maps, b_maps = localise(target.clip, fit_before, settings.localise)
    rows = [("target", t_maps), ("baseline fit", b_maps)]
    clips = [target.clip, fit_before]
    after_numbers = None
    if named:
        fit_after = clip_of(after.pipeline, after.best_params, target, settings.seed)
        after_numbers, _, a_maps = localise(target.clip, fit_after, settings.localise)
        rows.append((f"+ {named}", a_maps))
        clips.append(fit_after)
    return numbers, after_numbers, rows, clips


def _draw_figures(settings: DiagnoseSettings, rows: list[tuple[str, Any]], found: Findings) -> dict[str, str]:
    """``maps.png`` (the localisation maps' ``rows``) and ``gaps.png`` (each model's gap)."""
    before = found.before
    models = [
        {"label": s.label if s is not before else "baseline (best)", "gap": float(s.gap.gap),
         "distances": list(s.gap.to_target or [])}  # fmt: skip
        for s in [before, *found.stages[1:]]
    ]
    return {
        "maps": str(plot_maps(rows, settings.out / "maps.png")),
        "gaps": str(
            plot_gaps(models, floor=before.gap.floor, scale=found.scale, threshold=found.verdict.threshold,
                      named=found.named, path=settings.out / "gaps.png")  # fmt: skip
        ),
    }


def _write_model_file(settings: DiagnoseSettings, after: Stage) -> ModelFile:
    """``model.json``: the chosen model's effects and every value, the fixed ones included."""
    fixed = fixed_by_user(after.pipeline, settings.fixed)
    return write_model(
        settings.out / "model.json",
        plugin=settings.plugin,
        effects=[e.name for e in after.pipeline.effects],
        space=full_parameter_space(after.pipeline, settings.fixed),  # every parameter, the fixed ones at their values
        values={**after.best_params, **fixed},
        gap=float(after.gap.gap),
        source=after.result.run_dir,
        **optional_settings(fixed, settings.duration_s, settings.embedder_frames),  # what the values were fitted under
        **({"scene": scene} if (scene := scene_of(after.pipeline.phenomenon)) is not None else {}),
    )  # fmt: skip


def _decision_numbers(settings: DiagnoseSettings, target: Target, found: Findings) -> dict[str, Any]:
    """The report's head: the decision, the gaps it compared and each baseline fit's numbers."""
    verdict, before, control, baseline = found.verdict, found.before, found.stages[0], found.baseline
    gap_after = float(found.after.gap.gap)
    gap_before = float(before.gap.gap)
    return {
        "plugin": settings.plugin,
        "target": str(settings.target_path) if settings.target_path else "default",
        "truth": target.truth,
        "misspecified": verdict.misspecified,
        "misspecified_by": list(verdict.evidence),
        "gap_test": verdict.gap_test,
        "named_effect": found.named,
        "gap_before": gap_before,
        "gap_after": gap_after,
        "gap_ratio": gap_after / gap_before if gap_before > 0 else None,
        "noise_floor": before.gap.floor,
        "null_scale": found.scale,
        "threshold": verdict.threshold,
        "self_consistency_gap": found.self_gap,
        "self_consistency_gaps": [run["gap"] for run in found.calibration],
        "calibration": [dict(run) for run in found.calibration],
        "tested_gap": verdict.tested_gap,
        "baseline": {
            "best_params": baseline.best_params,
            "best_distance": baseline.best_distance,
            **gap_numbers(found.gap0),
            "run_dir": baseline.run_dir,
        },
        "control": {"best_params": control.best_params, **gap_numbers(control.gap), "run_dir": control.result.run_dir},
        "best_baseline": {"source": before.label, "best_params": before.best_params, **gap_numbers(before.gap)},
    }


def _settings_numbers(settings: DiagnoseSettings, found: Findings) -> dict[str, Any]:
    """The report's ``settings``: the budgets and the rule the diagnosis ran with."""
    rule = settings.rule
    return {
        "steps": found.baseline.n_trials,
        "effect_steps": found.stages[0].result.n_trials,
        "optimizer": settings.optimizer,
        "seed": settings.seed,
        "floor_samples": settings.floor_samples,
        "select_top": settings.select_top,
        "select_seeds": settings.select_seeds,
        "batch_size": settings.batch_size,
        "calibrate": settings.calibrate,
        "calibration_runs": settings.calibration_runs if settings.calibrate else 0,
        "calibration_control": settings.calibrate and settings.calibration_control,
        "duration_s": settings.duration_s,
        "embedder_frames": settings.embedder_frames,
        "fixed": fixed_by_user(found.before.pipeline, settings.fixed),
        "rule": {
            "misspecified_factor": rule.misspecified_factor,
            "alpha": rule.alpha,
            "per_parameter_factor": rule.per_parameter_factor,
            "calibration_summary": rule.calibration_summary,
            "effect_evidence": rule.effect_evidence,
        },
    }
