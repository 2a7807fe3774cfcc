"""The discrepancy workflow: refine, measure the gap, localise, try every effect, name one.

Stages, each a resumable refinement in its own run directory under ``--out``::

    baseline/            the baseline model refined from the centre (``steps`` trials)
    control/             the baseline refined ``effect_steps`` more trials from its best θ
    effect-<name>/       the baseline with <name> switched in, the same budget and warm start
    calibration-<r>/     r = 0 … R−1: the baseline refined against a synthetic target made
                         at its own best θ (self-consistency), each run with its own target
                         seed and optimizer seed (skipped with ``calibrate=False``); a
                         ``calibration/`` left by an older version is renamed ``calibration-0/``
    calibration-<r>-control/  with ``calibration_control``: run r refined ``effect_steps``
                         more trials from its best θ, as ``control/`` continues the baseline
    screen.json          the candidates screened out before the effects are refined: no fit
                         could name them here (:mod:`physinfer.discrepancy.screen`;
                         skipped with ``screen=False``)
    limits.json          each candidate's detection limit at the best baseline fit
                         (:mod:`physinfer.discrepancy.limits`; skipped with ``limits=False``)
    diagnosis.json, model.json, maps.png, gaps.png, side_by_side.mp4

The self-consistency runs come last and only as far as a decision depends on them
(:mod:`physinfer.discrepancy.self_consistency`; all of them with ``calibrate_all``): the
decisions are monotone in the null scale, and where they are the same over the range of
scales the unrefined runs allow, those runs are skipped.

Step 2's gap is each model's best θ re-simulated under the same ``K`` fresh seeds (see
:mod:`physinfer.discrepancy.gap`); the decisions are in :mod:`physinfer.discrepancy.decide`.
Re-running with the same ``--out`` continues where it stopped. The stages after the
baseline do not depend on each other: with ``workers`` (default: one per CPU) they run side
by side on worker processes or a Dask cluster first (:mod:`physinfer.discrepancy.parallel`),
and the pass through the stages below reads them back from disk.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.adequacy import DIAGNOSE_ADVICE, agreement_line, assess_fit, verdict_line
from physinfer.discrepancy.clip_jobs import pooled_clip_embedder
from physinfer.discrepancy.decide import remainder_after_naming, self_consistency_gap
from physinfer.discrepancy.limit_check import check_limits, checked_limit
from physinfer.discrepancy.limit_stage import diagnosis_simulations, run_limits
from physinfer.discrepancy.outputs import Findings, write_outputs
from physinfer.discrepancy.parallel import WorkerPool, run_on_workers, scene_registry, stage_jobs
from physinfer.discrepancy.progress import StageClock
from physinfer.discrepancy.records import Candidate, Screened, Verdict
from physinfer.discrepancy.ridge import ridge_starts
from physinfer.discrepancy.screen import refined_already, screen_effects
from physinfer.discrepancy.self_consistency import (
    first_self_consistency_jobs,
    limit_scale,
    run_self_consistency,
    scale_text,
)
from physinfer.discrepancy.stages import (
    GapContext,
    ablated_stage,
    adopt_single_calibration,
    build_base,
    control_stage,
    effect_stage,
    run_stage,
)
from physinfer.discrepancy.verdict import judge_stages, verdict_notes
from physinfer.errors import UserInputError
from physinfer.evaluation import NoiseFloor, Pipeline, noise_seeds, target_duration
from physinfer.io import atomic_write_json
from physinfer.locking import exclusive_directory
from physinfer.moved import moved_names
from physinfer.outputs import OutputFolder
from physinfer.progress import StageProgress
from physinfer.refinement import RefineResult
from physinfer.registry import Registry
from physinfer.report import write_report_quietly
from physinfer.roles import Target
from physinfer.scene import scene_of
from physinfer.target import load_target, start_from_video

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.discrepancy.stages import Stage

#: The settings and the stage record, defined below the stages that use them, still found here
#: with a warning (:data:`physinfer.moved.MOVED`).
__getattr__ = moved_names(__name__)

Log = Callable[[str], None]


def run_diagnosis(registry: Registry, settings: DiagnoseSettings, *, log: Log | None = None) -> dict[str, Any]:
    """Run (or continue) a diagnosis end to end; write its outputs; return the JSON report.

    Args:
        registry: Loaded plugin registry.
        settings: What to diagnose and how.
        log: Progress lines (stderr in the CLI); ``None``: silent.

    Returns:
        The report, also written to ``out/diagnosis.json`` (keys described in
        ``docs/discrepancy.md``).
    """
    settings.validate()
    check_diagnosis_out(settings.out)
    registry.get("optimizers", settings.optimizer)  # fail early, listing the installed ones
    start_time = time.perf_counter()

    registry = scene_registry(registry, settings)  # every model is built for the scene
    base, target, settings = _load(registry, settings)
    phenomenon = base.phenomenon
    if settings.batch_size is None:  # resolved once: every stage, here and on workers, alike
        if (batch := int(phenomenon.diagnose_batch_size)) < 1:
            raise UserInputError(
                f"the {phenomenon.name} plugin's diagnose_batch_size must be at least 1, got {batch}: "
                "pass --batch-size, or fix the plugin"
            )
        settings = dataclasses.replace(settings, batch_size=batch)
    effect_names = list(settings.effects) or registry.effects_of(phenomenon.name)
    if not effect_names:
        raise UserInputError(f"no effects are registered for {phenomenon.name!r}: nothing to try")
    effect_objs = {name: registry.effect(name, phenomenon=phenomenon.name) for name in effect_names}
    # Everything is checked: only now is --out created, and held against a second writer.
    with exclusive_directory(settings.out):
        diagnosis_folder(settings.out).claim()
        report = _diagnose(registry, settings, base, target, effect_objs, log or (lambda _msg: None))
        if (scene := scene_of(phenomenon)) is not None:
            report["scene"] = scene
        if target.conditions:
            report["target_conditions"] = target.conditions
        report["wall_time_s"] = time.perf_counter() - start_time
        atomic_write_json(settings.out / "diagnosis.json", report)
        write_report_quietly(settings.out)  # report.html; a failure only warns
    return report


def _load(registry: Registry, settings: DiagnoseSettings) -> tuple[Pipeline, Target, DiagnoseSettings]:
    base = build_base(registry, settings)
    target = load_target(
        base, settings.target_path, fps=settings.fps, truth=settings.truth, render_set=settings.render_set,
        fixed=settings.fixed, conditioning=settings.conditioning,
    )  # fmt: skip
    if settings.duration_s is None and (seconds := target_duration(base, target)) is not None:
        settings = dataclasses.replace(settings, duration_s=seconds)  # as long as the target lasts
        base = build_base(registry, settings)
    return base, target, settings


#: What ``diagnose`` writes atop its ``--out`` (its stages' run folders have manifests of their own).
DIAGNOSE_OUTPUTS = ("diagnosis.json", "baseline", "model.json", "maps.png", "gaps.png", "side_by_side.mp4",
                    "limits.json", "report.html")  # fmt: skip


def diagnosis_folder(out: Path) -> OutputFolder:
    """``diagnose --out`` as an output folder (:mod:`physinfer.outputs`); it resumes."""
    return OutputFolder(out, "diagnose", DIAGNOSE_OUTPUTS, noun="diagnosis", resumes=True, example="diagnosis")


def check_diagnosis_out(out: Path) -> None:
    """Refuse a ``diagnose --out`` that is a file or holds files that are not a diagnosis's
    (a diagnosis is recognised by the manifest it writes first, never by its file names).

    Raises:
        UserInputError: naming what is there and what to give instead.
    """
    diagnosis_folder(out).check()


def _diagnose(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    effect_objs: Mapping[str, Any],
    say: Log,
) -> dict[str, Any]:
    """The stages and the decision of :func:`run_diagnosis`, with ``--out`` locked; returns the report."""
    runs = settings.calibration_runs if settings.calibrate else 0
    with (
        StageProgress(settings.progress) as bars,
        WorkerPool(settings, list(effect_objs), 1 + len(effect_objs) + runs, say) as pool,
    ):
        return _diagnose_stages(registry, settings, base, target, effect_objs, say, bars, pool)


@dataclass(frozen=True)
class _Run:
    """One diagnosis as its stages read it: the inputs, the budgets, the target's embedding
    and re-simulation seeds, and where progress, timings and jobs go.

    Attributes:
        registry: The loaded plugin registry (every model built for the scene).
        settings: What to diagnose and how (the batch size and clip length resolved).
        base: The baseline pipeline.
        target: The target.
        effect_objs: Every candidate effect by name, screened-out ones included.
        say: Progress lines.
        bars: The trial progress bars.
        pool: The workers the stages after the baseline may run on.
        clock: Each stage's wall time.
        steps: The baseline's trials.
        effect_steps: The trials of the control and of each effect's model.
        target_label: How the stages' run records name the target.
        target_embedding: The target's embedding.
        seeds: The gap measurements' re-simulation seeds.
        gaps: What every gap measurement shares.
    """

    registry: Registry
    settings: DiagnoseSettings
    base: Pipeline
    target: Target
    effect_objs: Mapping[str, Any]
    say: Log
    bars: StageProgress
    pool: WorkerPool
    clock: StageClock
    steps: int
    effect_steps: int
    target_label: str
    target_embedding: np.ndarray
    seeds: list[int]
    gaps: GapContext

    @property
    def common(self) -> dict[str, Any]:
        """The keyword arguments every stage's refinement takes."""
        return {"registry": self.registry, "settings": self.settings, "on_trial": self.bars.update}


def _diagnose_stages(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    effect_objs: Mapping[str, Any],
    say: Log,
    bars: StageProgress,
    pool: WorkerPool,
) -> dict[str, Any]:
    """The stages and the decision of :func:`run_diagnosis`, in order; returns the report."""
    run = _start(registry, settings, base, target, effect_objs, say, bars, pool)
    # 1. The baseline (the workers start meanwhile, then make its re-simulations).
    baseline, gap0 = _refine_baseline(run)
    screened = _screen(run, baseline, gap0)
    refined = {name: effect for name, effect in effect_objs.items() if name not in screened}
    effects = list(refined)
    if settings.ridge_starts:
        _ridge_starts(run, baseline, gap0, refined)
    job_args, workers = _side_by_side(run, baseline, gap0, effects)
    # 2. Equal-budget control and one augmented model per effect, all warm-started.
    stages = _refine_models(run, baseline, refined)
    # 4. The self-consistency runs (the null scale's optimizer part), as many as decide.
    found, scale_range = _decide(run, baseline, gap0, stages, job_args, effects)
    say("[5/6] " + (f"named: {found.named}" if found.named else "no effect explains the gap"))
    remainder = remainder_after_naming(found.named, float(found.after.gap.gap), float(found.verdict.threshold))
    if remainder is not None:
        say("      " + remainder["message"])
    found, limits, limits_at = _limits(run, found, screened, refined, scale_range)
    clip_seconds = None if limits is None else limits.get("clip_seconds")
    verdict, notes = verdict_notes(
        found.verdict, stages, found.candidates, remainder, baseline_best=baseline.best_params,
        before_best=found.before.best_params, effect_steps=run.effect_steps, clip_seconds=clip_seconds,
        user_video=settings.target_path is not None,
    )  # fmt: skip
    for note in (notes["unnamed"], notes["lead"]):
        if note is not None:
            say("      " + note["message"])
    found = dataclasses.replace(found, verdict=verdict)
    with run.clock.stage("adequacy"):
        adequacy = _chosen_model_adequacy(found, target, settings.seed)
    say("[6/6] localising and writing outputs")
    with run.clock.stage("outputs"):
        report = write_outputs(settings, target, found)
    report["adequacy"] = adequacy
    report.update(notes)  # named_leaves, unnamed, lead
    report["null_scale_range"] = [scale_range[0], scale_range[1] if math.isfinite(scale_range[1]) else None]
    if limits is not None:  # the scale the limits assume, and whether it is the diagnosis' own
        limits = {k: v for k, v in limits.items() if k != "effects"}
        limits.update(null_scale=limits_at, null_scale_exact=scale_range[0] == scale_range[1])
    report["limits"] = limits
    report["screened"] = [
        Screened(name, effect_objs[name].description, record["reason"], record["rungs"]).to_dict()
        for name, record in screened.items()
    ]
    report["timing"] = {"stages_s": {k: round(v, 3) for k, v in run.clock.seconds.items()}, **workers}
    base.renderer.close()
    return report


def _chosen_model_adequacy(found: Findings, target: Target, seed: int) -> dict[str, Any]:
    """Whether the chosen model (the named effect's, else the best baseline fit) reproduces
    the video at all (:func:`physinfer.adequacy.assess_fit`, as ``refine`` says it): a name is
    no finding when even the model that carries it cannot make the video."""
    stage = found.after
    record = assess_fit(stage.pipeline, stage.best_params, float(stage.gap.gap), target, {"floor": stage.gap.floor}, seed)
    record["at"] = f"model with {found.named}" if found.named else "best baseline fit"
    said = verdict_line(record, DIAGNOSE_ADVICE) or agreement_line(record)
    return {**record, "message": said.strip() if said else None}


def _start(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    effect_objs: Mapping[str, Any],
    say: Log,
    bars: StageProgress,
    pool: WorkerPool,
) -> _Run:
    """The diagnosis' budgets, the target's embedding and the gap measurements' seeds, as a :class:`_Run`."""
    steps = settings.steps or base.phenomenon.default_steps
    target_embedding = base.embedder.embed(target.clip)
    seeds = noise_seeds(settings.seed + 2, settings.floor_samples)
    return _Run(
        registry, settings, base, target, effect_objs, say, bars, pool, StageClock(), steps,
        settings.effect_steps or steps, str(settings.target_path) if settings.target_path else "default",
        target_embedding, seeds, GapContext(target, target_embedding, tuple(seeds), settings.out),
    )  # fmt: skip


def _refine_baseline(run: _Run) -> tuple[RefineResult, NoiseFloor]:
    """The baseline refined from the centre and its gap at its best fit (re-simulated on the pool)."""
    run.pool.warm_up()
    resimulate = pooled_clip_embedder(run.pool, run.base, run.target.render_params, run.say)
    run.say(f"[1/6] refining the baseline ({run.steps} trials)")
    with run.clock.stage("baseline"):
        baseline = run_stage("baseline", run.base, run.target, steps=run.steps, start=None,
                             video_start=start_from_video(run.base, run.target), target_label=run.target_label,
                             embed_clips=resimulate, **run.common)  # fmt: skip
        gap0 = run.gaps.measure(run.base, baseline.best_params, "baseline", embed_clips=resimulate)
    return baseline, gap0


def _screen(run: _Run, baseline: RefineResult, gap0: NoiseFloor) -> dict[str, dict[str, Any]]:
    """The candidates screened out (no fit could name them here): name → the screen's record."""
    if not run.settings.screen:
        return {}
    unrefined = {name: e for name, e in run.effect_objs.items() if not refined_already(run.settings.out, name)}
    with run.clock.stage("screen"):
        screens = screen_effects(run.settings, run.base, run.target.render_params, baseline.best_params,
                                 gap0.embeddings, unrefined, run.say, run.pool,
                                 n_candidates=len(run.effect_objs))  # fmt: skip
    return {name: record for name, record in screens.items() if record["screened"]}


def _ridge_starts(run: _Run, baseline: RefineResult, gap0: NoiseFloor, refined: Mapping[str, Any]) -> None:
    """Each refined effect's ridge probe at the baseline's fit (the effects' searches start from it)."""
    with run.clock.stage("ridge"):
        ridge_starts(run.settings, run.base, run.target.render_params, baseline.best_params, run.target_embedding,
                     gap0.floor, refined, run.say, run.pool)  # fmt: skip


def _side_by_side(
    run: _Run, baseline: RefineResult, gap0: NoiseFloor, effects: list[str]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The stages after the baseline run on the workers first, if there are any.

    They start from the baseline's fit and not from each other; the pass through them here
    then reads them from disk.

    Returns:
        The stage jobs' shared arguments (the self-consistency runs take them too) and how
        the jobs ran.
    """
    adopt_single_calibration(run.settings.out)
    job_args = {
        "baseline_best": baseline.best_params, "target": run.target, "target_embedding": run.target_embedding,
        "seeds": run.seeds, "steps": run.steps, "effect_steps": run.effect_steps, "target_label": run.target_label,
    }  # fmt: skip
    first = first_self_consistency_jobs(run.settings, effects, run.pool.size, gap0.floor)
    jobs = stage_jobs(run.settings, effects, **job_args, calibration=first)
    return job_args, run_on_workers(run.pool, jobs, run.bars, run.clock, run.say)


def _refine_models(run: _Run, baseline: RefineResult, refined: Mapping[str, Any]) -> list[Stage]:
    """The control (the baseline refined ``effect_steps`` more), then each refined effect's model."""
    say, best = run.say, baseline.best_params
    say(f"[2/6] control: the baseline refined {run.effect_steps} more trials from its fit")
    with run.clock.stage("control"):
        stages = [
            control_stage(run.base, run.target, best, run.gaps, effect_steps=run.effect_steps,
                          target_label=run.target_label, **run.common)  # fmt: skip
        ]
    for name, effect in refined.items():
        say(f"[3/6] effect {name}: {effect.description} ({run.effect_steps} trials, warm start)")
        with run.clock.stage(f"effect-{name}"):
            stages.append(
                effect_stage(name, effect, run.base, run.target, best, run.gaps, effect_steps=run.effect_steps,
                             target_label=run.target_label, **run.common)  # fmt: skip
            )
    return stages


def _decide(
    run: _Run,
    baseline: RefineResult,
    gap0: NoiseFloor,
    stages: list[Stage],
    job_args: Mapping[str, Any],
    effects: list[str],
) -> tuple[Findings, tuple[float, float]]:
    """The self-consistency runs a decision needs, and the decision at their null scale.

    Returns:
        What was found and decided, and the null scale's range.
    """
    settings, say = run.settings, run.say
    # An augmented run may owe its better fit to its base parameters, not to its effect:
    # its best θ with the effect switched off is a baseline fit too, and the best baseline
    # fit found by any stage is what an effect must beat (ablation).
    ablated = [ablated_stage(stage, run.base, run.gaps) for stage in stages[1:]]
    before = min([stages[0], *ablated], key=lambda s: float(s.gap.gap))
    # The misspecification test compares like with like: with calibration controls the
    # self-consistency gaps had the budget of the best baseline fit, without them the
    # baseline stage's.
    tested = float(before.gap.gap) if settings.calibrate and settings.calibration_control else float(gap0.gap)

    def judged(scale: float) -> tuple[list[Candidate], Verdict, str | None]:
        return judge_stages(stages, before, tested, scale, settings.rule, run.effect_objs)

    calibration, scale, scale_range = run_self_consistency(
        settings, run.base, baseline.best_params, run.target, gap0, judged, job_args, effects, run.common, run.bars,
        run.clock, say, run.pool,
    )  # fmt: skip
    candidates, verdict, named = judged(scale)
    # The runs' summary only when every run was refined (otherwise the range says what is known).
    every_run = all("skipped" not in record for record in calibration)
    self_gap = self_consistency_gap([record["gap"] for record in calibration], settings.rule.calibration_summary) if (
        calibration and every_run) else None  # fmt: skip
    say(
        f"      gap {tested:.4g}, noise floor at the baseline fit {gap0.floor:.4g}, null scale {scale_text(scale_range)} → "
        + ("misspecified" if verdict.gap_test else "within what a correct model leaves")
    )
    if verdict.evidence == ("effect",):
        say("      an effect's significant improvement shows the baseline misspecified (the gap test alone did not)")
    after = next((s for s in stages if s.label == named), before)
    found = Findings(baseline, gap0, stages, before, after, named, candidates, verdict, scale, self_gap, calibration)
    return found, scale_range


def _limits(
    run: _Run, found: Findings, screened: Mapping[str, Any], refined: Mapping[str, Any], scale_range: tuple[float, float]
) -> tuple[Findings, dict[str, Any] | None, float | None]:
    """Each candidate's detection limit, checked by the search where asked.

    Returns:
        The findings with each candidate's limit set, the limits' record and the null scale
        they assume (the findings as they were, ``None`` and ``None`` without limits).
    """
    settings, effect_objs = run.settings, run.effect_objs
    if not settings.limits:
        return found, None, None
    runs = settings.calibration_runs if settings.calibrate else 0
    n_sims = diagnosis_simulations(settings, [found.baseline, *(s.result for s in found.stages)], runs,
                                    n_gaps=2 + runs * (2 if settings.calibration_control else 1)
                                    + 2 * len(effect_objs), unrefined=len(screened))  # fmt: skip
    limits_at = limit_scale(scale_range, found.gap0.floor_q95)
    low = scale_range[0] if limits_at != scale_range[0] else None  # read there too
    with run.clock.stage("limits"):
        limits = run_limits(run.registry, settings, run.base, run.target, found.before, refined, limits_at, n_sims,
                            run.say, run.pool, scale_low=low, n_candidates=len(effect_objs))  # fmt: skip
    candidates = [
        c.with_limit(lim["detectable_from"], {k: v for k, v in lim.items() if k != "detectable_from"})
        for c, lim in ((c, limits["effects"][c.effect]) for c in found.candidates)
    ]
    if settings.limit_config.search_check:
        with run.clock.stage("limit_check"):
            checked = check_limits(
                run.registry, settings, run.base, run.target, found.before.best_params, limits["effects"], refined,
                found.named, limits_at, len(effect_objs), run.steps, run.effect_steps, tuple(run.seeds), run.say)  # fmt: skip
        candidates = [c if (check := checked.get(c.effect)) is None
                      else c.with_limit(*checked_limit(c.detectable_from, c.limit or {}, check)) for c in candidates]  # fmt: skip
    return dataclasses.replace(found, candidates=candidates), limits, limits_at
