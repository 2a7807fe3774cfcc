"""The discrepancy workflow: refine, measure the gap, localise, try every effect, name one.

Stages, each a resumable refinement in its own run directory under ``--out``::

    baseline/            the baseline model refined from the centre (``steps`` trials)
    calibration-<r>/     r = 0 … R−1: the baseline refined against a synthetic target made
                         at its own best θ (self-consistency), each run with its own target
                         seed and optimizer seed (skipped with ``calibrate=False``); a
                         ``calibration/`` left by an older version is renamed ``calibration-0/``
    calibration-<r>-control/  with ``calibration_control``: run r refined ``effect_steps``
                         more trials from its best θ, as ``control/`` continues the baseline
    control/             the baseline refined ``effect_steps`` more trials from its best θ
    effect-<name>/       the baseline with <name> switched in, the same budget and warm start
    limits.json          each candidate's detection limit at the best baseline fit
                         (:mod:`physinfer.diagnose.limits`; skipped with ``limits=False``)
    diagnosis.json, model.json, maps.png, gaps.png, side_by_side.mp4

Step 2's gap is each model's best θ re-simulated under the same ``K`` fresh seeds (see
:mod:`physinfer.diagnose.gap`); the decisions are in :mod:`physinfer.diagnose.decide`.
Re-running with the same ``--out`` continues where it stopped.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.diagnose.candidates import augmented_pipeline, warm_start
from physinfer.diagnose.decide import (
    DecisionRule,
    effect_significance,
    final_verdict,
    misspecification,
    name_effect,
    null_scale,
    self_consistency_gap,
)
from physinfer.diagnose.gap import gap_numbers, measure_gap
from physinfer.diagnose.limits import LimitConfig
from physinfer.diagnose.localise import LocaliseConfig, localise
from physinfer.diagnose.warmstart import warm_start_factory
from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json, check_output_dir
from physinfer.locking import LOCK_FILE, exclusive_directory
from physinfer.noise import NoiseFloor, noise_seeds
from physinfer.parameters import refuse_repeats
from physinfer.refine import Pipeline, RefineConfig, RefineResult, run_refinement
from physinfer.registry import Registry
from physinfer.roles import Target
from physinfer.rundir import RUN_FILE, RunDirectory
from physinfer.session import fixed_by_user, full_parameter_space, optional_settings

Log = Callable[[str], None]


@dataclass(frozen=True)
class DiagnoseSettings:
    """Everything a diagnosis needs besides the registry.

    Attributes:
        plugin: Phenomenon name.
        out: Directory of the diagnosis (created; stages are sub-directories).
        target_path: Video to diagnose; ``None``: the phenomenon's embedded target.
        fps: Frame rate of ``target_path`` when the file does not say.
        truth: ``NAME=VALUE`` known values (reported, never used by the decisions).
        render_set: ζ overrides for the simulations.
        steps: Baseline budget (``None``: the phenomenon's default).
        effect_steps: Budget of the control and of each augmented model (``None``: ``steps``).
        optimizer: Registered optimizer name.
        embedder: Embedder name (``None``: the phenomenon's default).
        embedder_frames: Frames a parameter-free embedder reads (``None``: its default).
        duration_s: Seconds every simulation of every stage records (``None``: the
            phenomenon's default); see :func:`physinfer.session.build_pipeline`.
        fixed: ``NAME=VALUE`` items (patterns allowed) held fixed in every model and left
            out of every search: values the user knows (see :mod:`physinfer.fixed`).
        weights: Embedder weights.
        device: torch device of the embedder.
        seed: Seed of optimizers and simulations.
        effects: Effects to try (empty: every effect registered for the phenomenon).
        floor_samples: ``K``, re-simulations per gap measurement (at least 4 for the rank test).
        select_top: Every stage re-simulates its best ``M`` trials under ``select_seeds``
            fresh seeds and keeps the lowest mean (0: the lowest logged distance; see
            :func:`physinfer.refine.select_best`). For chaotic phenomena it keeps the
            winner's curse out of every stage's best fit, the calibration runs' included.
        select_seeds: Fresh seeds per finalist.
        batch_size: Trials per optimizer step of every stage, simulated as one batch (see
            :class:`physinfer.refine.RefineConfig`).
        calibrate: Run the self-consistency refinements (the null scale's optimizer part).
        calibration_runs: ``R``, self-consistency refinements; ``rule.calibration_summary``
            (the maximum by default) makes their gaps one (see :mod:`physinfer.diagnose.decide`).
        calibration_control: Follow each calibration run with its own control
            (``effect_steps`` trials warm-started from its best θ), so that a self-consistency
            gap has the budget of the best baseline fit it is compared with; the
            misspecification test then uses that best fit's gap (``gap_before``) instead of
            the baseline stage's.
        rule: Decision thresholds.
        localise: Localisation settings.
        videos: Write the side-by-side video.
        limits: Estimate each candidate's detection limit (``detectable_from``).
        limit_config: The detection-limit ladder's settings (``reveal``: also try another
            view and a longer clip).
    """

    plugin: str
    out: Path
    target_path: Path | None = None
    fps: float | None = None
    truth: tuple[str, ...] = ()
    render_set: Mapping[str, Any] = field(default_factory=dict)
    steps: int | None = None
    effect_steps: int | None = None
    optimizer: str = "ax"
    embedder: str | None = None
    embedder_frames: int | None = None
    duration_s: float | None = None
    fixed: tuple[str, ...] = ()
    weights: Path | None = None
    device: str | None = None
    seed: int = 0
    effects: tuple[str, ...] = ()
    floor_samples: int = 6
    select_top: int = 0
    select_seeds: int = 3
    batch_size: int = 1
    calibrate: bool = True
    calibration_runs: int = 3
    calibration_control: bool = True
    rule: DecisionRule = field(default_factory=DecisionRule)
    localise: LocaliseConfig = field(default_factory=LocaliseConfig)
    videos: bool = True
    limits: bool = True
    limit_config: LimitConfig = field(default_factory=LimitConfig)

    def validate(self) -> None:
        """Raise :class:`UserInputError` naming the first bad setting."""
        refuse_repeats(self.effects, "--effect")
        for name, value in (("--steps", self.steps), ("--effect-steps", self.effect_steps)):
            if value is not None and value < 1:
                raise UserInputError(f"{name} must be at least 1, got {value}")
        if self.floor_samples < 4:
            raise UserInputError(
                f"--floor-samples must be at least 4 (the rank test needs them), got {self.floor_samples}"
            )
        RefineConfig(select_top=self.select_top, select_seeds=self.select_seeds, batch_size=self.batch_size).validate()
        if self.calibration_runs < 1:
            raise UserInputError(
                f"--calibration-runs must be at least 1, got {self.calibration_runs} "
                "(use --no-calibrate to skip the self-consistency refinements)"
            )
        self.rule.validate()
        try:
            self.localise.validate()
        except ValueError as exc:
            raise UserInputError(f"localisation settings: {exc}") from None


@dataclass
class Stage:
    """One refined model of the diagnosis and its gap."""

    label: str
    pipeline: Pipeline
    result: RefineResult
    gap: NoiseFloor
    n_params: int = 0
    params: dict[str, float] | None = None

    @property
    def best_params(self) -> dict[str, float]:
        """The θ this stage stands for (the refinement's best, or its ablated version)."""
        return dict(self.params) if self.params is not None else dict(self.result.best_params)


def run_stage(
    name: str,
    pipeline: Pipeline,
    target: Target,
    *,
    registry: Registry,
    settings: DiagnoseSettings,
    steps: int,
    start: Mapping[str, float] | None,
    target_label: str,
    seed: int | None = None,
) -> RefineResult:
    """Refine ``pipeline`` in ``out/name`` (continuing a run already there).

    Args:
        name: Sub-directory of the stage.
        pipeline: The model.
        target: What to match.
        registry: For the optimizer.
        settings: The diagnosis settings (optimizer, seed, embedder).
        steps: Trials in all.
        start: Physical warm-start values (``None``: the centre).
        target_label: Stored in ``run.json``.
        seed: Optimizer and simulation seed (``None``: the diagnosis seed).
    """
    seed = settings.seed if seed is None else seed
    space = pipeline.simulator.parameter_space
    factory = registry.get("optimizers", settings.optimizer).load()
    if start is not None:
        factory = warm_start_factory(factory, space.to_unit(space.complete(start)))
    run_dir = RunDirectory(settings.out / name)
    run_info = {
        "plugin": settings.plugin,
        "optimizer": settings.optimizer,
        "seed": seed,
        "steps": steps,
        "effects": [e.name for e in pipeline.effects],
        "embedder": settings.embedder or pipeline.phenomenon.default_embedder,
        "parameters": space.to_dict(),
        "target": target_label,
        "render_params": dict(target.render_params),
        "truth": target.truth,
        "start": None if start is None else {k: float(v) for k, v in start.items()},
        "stage": name,
        **optional_settings(fixed_by_user(pipeline, settings.fixed), settings.duration_s, settings.embedder_frames),
    }
    config = RefineConfig(
        steps=steps, optimizer=settings.optimizer, seed=seed,
        select_top=settings.select_top, select_seeds=settings.select_seeds, batch_size=settings.batch_size,
    )
    resume = run_dir.run_file.is_file()
    return run_refinement(pipeline, target, factory, run_dir, config, run_info=run_info, resume=resume)


def _load(registry: Registry, settings: DiagnoseSettings) -> tuple[Pipeline, Target]:
    from physinfer.session import EffectParameterError, build_pipeline, load_target

    try:
        pipeline = build_pipeline(
            registry, settings.plugin, embedder=settings.embedder, weights=settings.weights, device=settings.device,
            duration_s=settings.duration_s, embedder_frames=settings.embedder_frames, fixed=settings.fixed,
        )  # fmt: skip
    except EffectParameterError as exc:  # diagnose switches effects in itself: no --effect to add
        raise UserInputError(
            f"{exc.name} (in --fix) belongs to the effect {exc.effect}, which diagnose tries itself: "
            "--fix only parameters of the model without effects"
        ) from None
    target = load_target(
        pipeline, settings.target_path, fps=settings.fps, truth=settings.truth, render_set=settings.render_set,
        fixed=settings.fixed,
    )
    return pipeline, target


def _clip(pipeline: Pipeline, params: Mapping[str, float], target: Target, seed: int) -> Any:
    return pipeline.renderer.render(pipeline.simulator.simulate(params, seed=seed), target.render_params)


def _calibration_target(
    pipeline: Pipeline, params: Mapping[str, float], target: Target, seed: int, encode_dir: Path | None
) -> Target:
    """A synthetic target made by the baseline model itself at its best θ (another seed).

    With ``encode_dir`` the clip makes a round trip through the video encoder, as a target
    read from a file did: compression changes the pixels, and a self-consistency target
    without it would be easier to match than the real one.
    """
    clip = _clip(pipeline, params, target, seed)
    if encode_dir is not None:
        from physinfer.video import read_video, write_video

        encode_dir.mkdir(parents=True, exist_ok=True)
        path = write_video(encode_dir / "self_target.mp4", clip)
        clip = read_video(path, fps=clip.fps)
    return Target(clip, dict(params), dict(target.render_params), "self-consistency target at the baseline fit")


#: Step between the optimizer seeds of successive calibration runs: any step keeps them
#: apart from the baseline's seed; a large one also keeps them off the seeds of a diagnosis
#: run with a neighbouring ``--seed`` (the benchmark's next case).
CALIBRATION_SEED_STRIDE = 7919


def calibration_seeds(seed: int, runs: int) -> list[tuple[int, int]]:
    """``(target simulation seed, optimizer seed)`` of each self-consistency run.

    Run 0 has the seeds of the single calibration of earlier versions, so an old
    ``calibration/`` directory continues as ``calibration-0/``. The optimizer seed differs
    from the baseline's: with the same seed the optimizer would propose the baseline's first
    trials again, one of which made the target (too easy a test).

    Args:
        seed: The diagnosis seed.
        runs: ``R``.

    Returns:
        ``R`` pairs, all target seeds distinct.
    """
    return [(t, seed + 1 + CALIBRATION_SEED_STRIDE * r) for r, t in enumerate(noise_seeds(seed + 7, runs))]


def _adopt_single_calibration(out: Path) -> None:
    """Rename the ``calibration/`` stage of an older diagnosis to ``calibration-0/``."""
    old, new = out / "calibration", out / "calibration-0"
    if (old / RUN_FILE).is_file() and not new.exists():
        old.rename(new)


def run_calibration(
    base: Pipeline,
    params: Mapping[str, float],
    target: Target,
    *,
    registry: Registry,
    settings: DiagnoseSettings,
    steps: int,
    effect_steps: int,
    seeds: Sequence[int],
) -> list[dict[str, Any]]:
    """Refine the baseline ``R`` times against targets it made itself at ``params``; their gaps.

    Each run ``r`` is the stage ``calibration-<r>/`` (resumable), with its own target seed
    and optimizer seed from :func:`calibration_seeds` and the baseline's budget; its gap is
    measured under the diagnosis' re-simulation ``seeds`` like every other model's. With
    ``settings.calibration_control`` the run continues in ``calibration-<r>-control/`` for
    ``effect_steps`` trials from its best θ (the same seeds), mirroring ``control/``; the
    run's gap is then the smaller of the two stages' gaps, as ``gap_before`` is the best of
    the real target's baseline fits.

    Args:
        base: The baseline model.
        params: The baseline's best θ.
        target: The real target (its ζ; whether it came from a file).
        registry: For the optimizer.
        settings: The diagnosis settings (``calibration_runs``, ``out``).
        steps: Trials per run (the baseline's).
        effect_steps: Trials of each run's control (the control's).
        seeds: Re-simulation seeds of the gap measurements.

    Returns:
        One record per run, in run order: ``gap`` (the run's self-consistency gap),
        ``gap_run`` and ``gap_control`` (``None`` without a control), ``target_seed``,
        ``optimizer_seed``.
    """
    _adopt_single_calibration(settings.out)
    runs = []
    for r, (target_seed, optimizer_seed) in enumerate(calibration_seeds(settings.seed, settings.calibration_runs)):
        name = f"calibration-{r}"
        encode_dir = settings.out / name if settings.target_path is not None else None
        cal_target = _calibration_target(base, params, target, target_seed, encode_dir)
        cal = run_stage(
            name, base, cal_target, registry=registry, settings=settings, steps=steps, start=None,
            target_label="self-consistency", seed=optimizer_seed,
        )
        cal_embedding = base.embedder.embed(cal_target.clip)
        gap = float(
            measure_gap(
                base, cal.best_params, target.render_params, cal_embedding, seeds=seeds, cache_dir=settings.out / name
            ).gap
        )
        gap_control = None
        if settings.calibration_control:
            control = run_stage(
                f"{name}-control", base, cal_target, registry=registry, settings=settings, steps=effect_steps,
                start=cal.best_params, target_label="self-consistency", seed=optimizer_seed,
            )
            gap_control = float(
                measure_gap(
                    base, control.best_params, target.render_params, cal_embedding, seeds=seeds,
                    cache_dir=settings.out / f"{name}-control",
                ).gap
            )
        runs.append(
            {
                "gap": gap if gap_control is None else min(gap, gap_control),
                "gap_run": gap,
                "gap_control": gap_control,
                "target_seed": int(target_seed),
                "optimizer_seed": int(optimizer_seed),
            }
        )
    return runs


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
    base, target = _load(registry, settings)
    phenomenon = base.phenomenon
    effect_names = list(settings.effects) or registry.effects_of(phenomenon.name)
    if not effect_names:
        raise UserInputError(f"no effects are registered for {phenomenon.name!r}: nothing to try")
    effect_objs = {name: registry.effect(name, phenomenon=phenomenon.name) for name in effect_names}
    # Everything is checked: only now is --out created, and held against a second writer.
    with exclusive_directory(settings.out):
        report = _diagnose(registry, settings, base, target, effect_objs, log or (lambda _msg: None))
        report["wall_time_s"] = time.perf_counter() - start_time
        atomic_write_json(settings.out / "diagnosis.json", report)
        from physinfer.report import write_report_quietly  # report.html; a failure only warns

        write_report_quietly(settings.out)
    return report


def check_diagnosis_out(out: Path) -> None:
    """Refuse a ``diagnose --out`` that is a file or holds files that are not a diagnosis's.

    Raises:
        UserInputError: naming what is there and what to give instead.
    """
    check_output_dir(out)
    if not out.is_dir() or (out / "baseline" / RUN_FILE).is_file() or (out / "diagnosis.json").is_file():
        return
    # A lock file and an empty baseline/ are what a diagnosis killed at its start leaves.
    others = sorted(p.name for p in out.iterdir() if p.name not in (LOCK_FILE, "baseline"))
    if others:
        shown = ", ".join(others[:3]) + (", ..." if len(others) > 3 else "")
        raise UserInputError(
            f"--out {out} is not empty ({shown}) and holds no diagnosis; a diagnosis would mix its files "
            f"with yours: give a new or empty directory, e.g. --out {out / 'diagnosis'}"
        )


def _diagnose(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    effect_objs: Mapping[str, Any],
    say: Log,
) -> dict[str, Any]:
    """The stages and the decision of :func:`run_diagnosis`, with ``--out`` locked; returns the report."""
    steps = settings.steps or base.phenomenon.default_steps
    effect_steps = settings.effect_steps or steps
    target_label = str(settings.target_path) if settings.target_path else "default"
    target_embedding = base.embedder.embed(target.clip)
    seeds = noise_seeds(settings.seed + 2, settings.floor_samples)
    common = {"registry": registry, "settings": settings}

    def gap_of(pipeline: Pipeline, params: Mapping[str, float], stage: str, cache_name: str = "gap.json") -> NoiseFloor:
        return measure_gap(
            pipeline, params, target.render_params, target_embedding, seeds=seeds, cache_dir=settings.out / stage,
            cache_name=cache_name,
        )

    # 1. The baseline.
    say(f"[1/6] refining the baseline ({steps} trials)")
    baseline = run_stage("baseline", base, target, steps=steps, start=None, target_label=target_label, **common)
    gap0 = gap_of(base, baseline.best_params, "baseline")

    # 2. The self-consistency runs (the null scale's optimizer part).
    calibration: list[dict[str, Any]] = []
    if settings.calibrate:
        per_run = f"{steps} + {effect_steps}" if settings.calibration_control else f"{steps}"
        say(
            f"[2/6] self-consistency: refining the baseline against its own fit "
            f"({settings.calibration_runs} × {per_run} trials)"
        )
        calibration = run_calibration(
            base, baseline.best_params, target, steps=steps, effect_steps=effect_steps, seeds=seeds, **common
        )
    self_gaps = [run["gap"] for run in calibration]
    self_gap = self_consistency_gap(self_gaps, settings.rule.calibration_summary)
    scale = null_scale(gap0.floor, gap0.floor_q95, self_gap)

    # 4. Equal-budget control and one augmented model per effect, all warm-started.
    say(f"[3/6] control: the baseline refined {effect_steps} more trials from its fit")
    control = run_stage(
        "control", base, target, steps=effect_steps, start=baseline.best_params, target_label=target_label, **common
    )
    base_space = base.simulator.parameter_space
    stages = [Stage("baseline", base, control, gap_of(base, control.best_params, "control"))]
    for name, effect in effect_objs.items():
        say(f"[4/6] effect {name}: {effect.description} ({effect_steps} trials, warm start)")
        pipeline = augmented_pipeline(base, [effect], settings.duration_s, fixed_by_user(base, settings.fixed))
        result = run_stage(
            f"effect-{name}",
            pipeline,
            target,
            steps=effect_steps,
            start=warm_start(baseline.best_params, [effect]),
            target_label=target_label,
            **common,
        )
        stages.append(
            Stage(name, pipeline, result, gap_of(pipeline, result.best_params, f"effect-{name}"),
                  n_params=len(effect.parameter_space))
        )

    # An augmented run may owe its better fit to its base parameters, not to its effect:
    # its best θ with the effect switched off is a baseline fit too, and the best baseline
    # fit found by any stage is what an effect must beat (ablation).
    ablated = []
    for stage in stages[1:]:
        off = {k: v for k, v in warm_start(stage.result.best_params, stage.pipeline.effects).items() if k in base_space}
        ablated.append(
            Stage(f"{stage.label} off", base, stage.result,
                  gap_of(base, off, f"effect-{stage.label}", cache_name="gap_effect_off.json"), params=off)
        )
    before = min([stages[0], *ablated], key=lambda s: float(s.gap.gap))
    gap_before = float(before.gap.gap)
    # The misspecification test compares like with like: with calibration controls the
    # self-consistency gaps had the budget of the best baseline fit, without them the
    # baseline stage's.
    tested = gap_before if settings.calibrate and settings.calibration_control else float(gap0.gap)
    gap_verdict = misspecification(tested, scale, settings.rule)
    say(
        f"      gap {tested:.4g}, noise floor {gap0.floor:.4g}, null scale {scale:.4g} → "
        + ("misspecified" if gap_verdict["misspecified"] else "within what a correct model leaves")
    )
    candidates = []
    for stage in stages[1:]:
        decision = effect_significance(
            distances=stage.gap.to_target or [],
            baseline_distances=before.gap.to_target or [],
            gap=float(stage.gap.gap),
            gap_before=gap_before,
            n_params=stage.n_params,
            scale=scale,
            rule=settings.rule,
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
    verdict = final_verdict(gap_verdict, candidates, settings.rule)
    if verdict["evidence"] == ["effect"]:
        say("      an effect's significant improvement shows the baseline misspecified (the gap test alone did not)")
    named = name_effect(candidates, verdict["misspecified"])
    after = next((s for s in stages if s.label == named), before)
    say("[5/6] " + (f"named: {named}" if named else "no effect explains the gap"))
    limits = None
    if settings.limits:
        n_sims = _diagnosis_simulations(settings, [baseline, control, *(s.result for s in stages[1:])], calibration,
                                        n_gaps=2 + len(calibration) * (2 if settings.calibration_control else 1)
                                        + 2 * len(effect_objs))
        limits = _limits(registry, settings, base, target, before, effect_objs, scale, n_sims, say)
        for cand in candidates:
            lim = limits["effects"][cand["effect"]]
            cand["detectable_from"] = lim["detectable_from"]
            cand["limit"] = {k: v for k, v in lim.items() if k != "detectable_from"}
    say("[6/6] localising and writing outputs")

    report = _outputs(
        settings, target, stages, before, after, named, candidates, verdict, scale, gap0, self_gap, calibration,
        baseline,
    )
    report["limits"] = None if limits is None else {k: v for k, v in limits.items() if k != "effects"}
    base.renderer.close()
    return report


def _diagnosis_simulations(settings: DiagnoseSettings, results: Sequence[RefineResult],
                           calibration: Sequence[Mapping[str, Any]], n_gaps: int) -> int:
    """Simulations a diagnosis costs: trials, selection re-simulations, gap measurements (the ladder's budget)."""
    stages = len(results) + len(calibration) * (2 if settings.calibration_control else 1)
    per_stage_trials = sum(r.n_trials for r in results) / max(len(results), 1)
    steps = settings.steps or per_stage_trials
    effect_steps = settings.effect_steps or steps
    calibration_trials = len(calibration) * (steps + (effect_steps if settings.calibration_control else 0))
    select = settings.select_top * settings.select_seeds * stages
    return int(sum(r.n_trials for r in results) + calibration_trials + select + n_gaps * settings.floor_samples)


def _limits(
    registry: Registry,
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    before: Stage,
    effect_objs: Mapping[str, Any],
    scale: float,
    n_sims: int,
    say: Log,
) -> dict[str, Any]:
    """Every candidate's detection limit at the best baseline fit, cached in ``limits.json``."""
    import dataclasses
    import json

    from physinfer.diagnose.limits import LimitInputs, detection_limits

    theta = before.best_params
    fixed = fixed_by_user(base, settings.fixed)
    key = {"theta": {k: float(v) for k, v in theta.items()}, "scale": float(scale),
           "effects": sorted(effect_objs), "config": settings.limit_config.to_dict(), "seed": settings.seed,
           "rule": dataclasses.asdict(settings.rule), "floor_samples": settings.floor_samples}
    path = settings.out / "limits.json"
    if path.is_file():
        stored = json.loads(path.read_text())
        if stored.get("key") == key:
            return stored["limits"]
    embeddings = np.asarray(before.gap.embeddings)
    if embeddings.ndim != 2 or len(embeddings) < 2:  # a gap measured before embeddings were kept
        seeds = noise_seeds(settings.seed + 2, settings.floor_samples)
        embeddings = measure_gap(base, theta, target.render_params, np.zeros(1), seeds=seeds).embeddings
    augmented = {name: augmented_pipeline(base, [effect], settings.duration_s, fixed)
                 for name, effect in effect_objs.items()}

    def make_longer(seconds: float) -> tuple[Any, dict[str, Any], Any]:
        from physinfer.session import build_pipeline

        frames = settings.embedder_frames or getattr(base.embedder, "n_frames", None)
        longer = build_pipeline(
            registry, settings.plugin, embedder=settings.embedder, weights=settings.weights, device=settings.device,
            duration_s=2 * seconds, embedder_frames=None if frames is None else 2 * int(frames), fixed=settings.fixed,
        )  # fmt: skip
        sims = {name: augmented_pipeline(longer, [e], 2 * seconds, fixed).simulator for name, e in effect_objs.items()}
        return longer.simulator, sims, longer.embedder

    say(f"      detection limits: a ladder of {len(settings.limit_config.fractions)} strengths per effect "
        "at the best baseline fit")
    inputs = LimitInputs(
        base=base, augmented=augmented, theta=theta, base_embeddings=embeddings, render_params=target.render_params,
        scale=scale, rule=settings.rule, floor_samples=settings.floor_samples, seed=settings.seed,
        diagnosis_simulations=n_sims, make_longer=make_longer,
    )
    limits = detection_limits(inputs, settings.limit_config, log=say)
    atomic_write_json(path, {"key": key, "limits": limits})
    return json.loads(path.read_text())["limits"]  # as a resumed diagnosis reads it (NaN as null)


def _outputs(
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
    from physinfer.diagnose.figures import plot_gaps, plot_maps
    from physinfer.diagnose.model import write_model

    out = settings.out
    fit_before = _clip(before.pipeline, before.best_params, target, settings.seed)
    numbers, t_maps, b_maps = localise(target.clip, fit_before, settings.localise)
    rows = [("target", t_maps), ("baseline fit", b_maps)]
    clips = [target.clip, fit_before]
    after_numbers = None
    if named:
        fit_after = _clip(after.pipeline, after.best_params, target, settings.seed)
        after_numbers, _, a_maps = localise(target.clip, fit_after, settings.localise)
        rows.append((f"+ {named}", a_maps))
        clips.append(fit_after)
    figures = {
        "maps": str(plot_maps(rows, out / "maps.png")),
        "gaps": str(
            plot_gaps(
                [
                    {"label": s.label if s is not before else "baseline (best)", "gap": float(s.gap.gap),
                     "distances": list(s.gap.to_target or [])}
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
        space=full_parameter_space(after.pipeline, settings.fixed),  # every parameter, the fixed ones at their values
        values={**after.best_params, **fixed},
        gap=float(after.gap.gap),
        source=after.result.run_dir,
        **optional_settings(fixed, settings.duration_s, settings.embedder_frames),  # what the values were fitted under
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
        "control": {"best_params": stages[0].best_params, **gap_numbers(stages[0].gap), "run_dir": stages[0].result.run_dir},
        "best_baseline": {"source": before.label, "best_params": before.best_params, **gap_numbers(before.gap)},
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
