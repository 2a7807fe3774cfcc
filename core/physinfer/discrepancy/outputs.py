"""A diagnosis' outputs: localisation maps, the gap figure, the side-by-side video, the
model file, and the report's numbers (``diagnosis.json``, described in docs/discrepancy.md)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.discrepancy.gap import gap_numbers
from physinfer.discrepancy.localise import localise
from physinfer.discrepancy.stages import Stage, clip_of
from physinfer.noise import NoiseFloor
from physinfer.pipeline import fixed_by_user, full_parameter_space
from physinfer.refinement import RefineResult
from physinfer.roles import Target
from physinfer.rundir import optional_settings
from physinfer.scene import scene_of

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings


def write_outputs(
    settings: DiagnoseSettings,
    target: Target,
    stages: Sequence[Stage],
    before: Stage,
    after: Stage,
    named: str | None,
    candidates: list[dict[str, Any]],
    verdict: dict[str, Any],
    scale: float,
    gap0: NoiseFloor,
    self_gap: float | None,
    calibration: Sequence[Mapping[str, Any]],
    baseline: RefineResult,
) -> dict[str, Any]:
    """Localise, draw, write the model file and videos; assemble the report."""
    from physinfer.discrepancy.figures import plot_gaps, plot_maps
    from physinfer.discrepancy.model import write_model

    out = settings.out
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
    figures = {
        "maps": str(plot_maps(rows, out / "maps.png")),
        "gaps": str(
            plot_gaps(
                [
                    {
                        "label": s.label if s is not before else "baseline (best)",
                        "gap": float(s.gap.gap),
                        "distances": list(s.gap.to_target or []),
                    }
                    for s in [before, *stages[1:]]
                ],
                floor=before.gap.floor,
                scale=scale,
                threshold=verdict["threshold"],
                named=named,
                path=out / "gaps.png",
            )
        ),
    }
    videos = {}
    if settings.videos:
        from physinfer.video import side_by_side, write_video

        videos["side_by_side"] = str(write_video(out / "side_by_side.mp4", side_by_side(clips)))
    fixed = fixed_by_user(after.pipeline, settings.fixed)
    model = write_model(
        out / "model.json",
        plugin=settings.plugin,
        effects=[e.name for e in after.pipeline.effects],
        space=full_parameter_space(
            after.pipeline, settings.fixed
        ),  # every parameter, the fixed ones at their values
        values={**after.best_params, **fixed},
        gap=float(after.gap.gap),
        source=after.result.run_dir,
        **optional_settings(
            fixed, settings.duration_s, settings.embedder_frames
        ),  # what the values were fitted under
        **({"scene": scene} if (scene := scene_of(after.pipeline.phenomenon)) is not None else {}),
    )
    gap_after = float(after.gap.gap)
    gap_before = float(before.gap.gap)
    return {
        "plugin": settings.plugin,
        "target": str(settings.target_path) if settings.target_path else "default",
        "truth": target.truth,
        "misspecified": verdict["misspecified"],
        "misspecified_by": verdict["evidence"],
        "gap_test": verdict["gap_test"],
        "named_effect": named,
        "gap_before": gap_before,
        "gap_after": gap_after,
        "gap_ratio": gap_after / gap_before if gap_before > 0 else None,
        "noise_floor": before.gap.floor,
        "null_scale": scale,
        "threshold": verdict["threshold"],
        "self_consistency_gap": self_gap,
        "self_consistency_gaps": [run["gap"] for run in calibration],
        "calibration": [dict(run) for run in calibration],
        "tested_gap": verdict["tested_gap"],
        "baseline": {
            "best_params": baseline.best_params,
            "best_distance": baseline.best_distance,
            **gap_numbers(gap0),
            "run_dir": baseline.run_dir,
        },
        "control": {
            "best_params": stages[0].best_params,
            **gap_numbers(stages[0].gap),
            "run_dir": stages[0].result.run_dir,
        },
        "best_baseline": {
            "source": before.label,
            "best_params": before.best_params,
            **gap_numbers(before.gap),
        },
        "candidates": candidates,
        "regions": numbers["regions"],
        "localisation": numbers["global"],
        "regions_after": None if after_numbers is None else after_numbers["regions"],
        "model_file": str(out / "model.json"),
        "model": {"effects": list(model.effects), "values": model.values},
        "figures": figures,
        "videos": videos,
        "settings": {
            "steps": baseline.n_trials,
            "effect_steps": stages[0].result.n_trials,
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
            "fixed": fixed_by_user(before.pipeline, settings.fixed),
            "rule": {
                "misspecified_factor": settings.rule.misspecified_factor,
                "alpha": settings.rule.alpha,
                "per_parameter_factor": settings.rule.per_parameter_factor,
                "calibration_summary": settings.rule.calibration_summary,
                "effect_evidence": settings.rule.effect_evidence,
            },
        },
        "seeds_checked": [int(s) for s in np.asarray(before.gap.seeds)],
    }
