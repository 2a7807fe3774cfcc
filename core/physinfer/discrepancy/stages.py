"""The stages of a diagnosis: each a resumable refinement in its own directory, and its gap.

:mod:`physinfer.discrepancy.workflow` runs them in order and decides; the stages after the
baseline do not depend on one another, so :mod:`physinfer.discrepancy.parallel` may run them
first on worker processes with these same functions. Every stage writes its trials,
selection and gap measurements to its directory, and a stage that finds them there
continues from them — so the workflow's sequential pass then reads a stage a worker
finished instead of running it again, and the decisions cannot depend on who ran it.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer import video
from physinfer.discrepancy.candidates import augmented_pipeline, warm_start
from physinfer.discrepancy.gap import measure_gap
from physinfer.discrepancy.refit import polished_start
from physinfer.discrepancy.starts import (
    baseline_video_start,
    check_resumed_start,
    search_starts,
    stage_optimizer,
    video_start_identity,
)
from physinfer.errors import ResumeMismatch, UserInputError
from physinfer.evaluation import (
    EffectParameterError,
    NoiseFloor,
    Pipeline,
    build_pipeline,
    fixed_by_user,
    noise_seeds,
)
from physinfer.io import atomic_write_json
from physinfer.loop import run_refinement
from physinfer.refinement import RefineResult, SearchSpec
from physinfer.registry import Registry
from physinfer.roles import Effect, Target
from physinfer.rundir import RUN_FILE, RunDirectory, TrialRecord, optional_settings
from physinfer.scene import scene_of
from physinfer.target import VideoStart

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.evaluation import ClipEmbedder

#: Called after each trial of a stage with its name, the trials done and the stage's budget.
OnTrial = Callable[[str, int, int], None]


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


@dataclass(frozen=True)
class GapContext:
    """What every gap measurement of one diagnosis shares: the target's embedding and ζ,
    the re-simulation seeds and the diagnosis directory (the caches live in its stages)."""

    target: Target
    target_embedding: np.ndarray
    seeds: tuple[int, ...]
    out: Path

    def measure(
        self,
        pipeline: Pipeline,
        params: Mapping[str, float],
        stage: str,
        cache_name: str = "gap.json",
        embed_clips: ClipEmbedder | None = None,
    ) -> NoiseFloor:
        """The gap of ``params`` under ``pipeline``, cached in the stage's directory
        (``embed_clips``: its re-simulations made there)."""
        return measure_gap(
            pipeline, params, self.target.render_params, self.target_embedding, seeds=self.seeds,
            cache_dir=self.out / stage, cache_name=cache_name, embed_clips=embed_clips,
        )  # fmt: skip


def build_base(registry: Registry, settings: DiagnoseSettings) -> Pipeline:
    """The baseline model (no effects) the diagnosis' settings describe."""
    try:
        return build_pipeline(
            registry, settings.plugin, embedder=settings.embedder, weights=settings.weights, device=settings.device,
            duration_s=settings.duration_s, embedder_frames=settings.embedder_frames, fixed=settings.fixed,
        )  # fmt: skip
    except EffectParameterError as exc:  # diagnose switches effects in itself: no --effect to add
        raise UserInputError(
            f"{exc.name} (in --fix) belongs to the effect {exc.effect}, which diagnose tries itself: "
            "--fix only parameters of the model without effects"
        ) from None


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
    on_trial: OnTrial | None = None,
    embed_clips: ClipEmbedder | None = None,
    extra_starts: Sequence[Mapping[str, float]] = (),
    video_start: VideoStart | None = None,
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
        on_trial: Progress: called with ``(name, trials done, steps)`` after each trial.
        embed_clips: Where the selection's re-simulations run (``None``: here).
        extra_starts: Physical points tried right after ``start``, before the optimizer's
            own proposals (an effect's ridge starts, :mod:`physinfer.discrepancy.ridge`).
        video_start: Without a ``start``, where the target video points, and its box
            (:mod:`physinfer.discrepancy.starts`).
    """
    seed = settings.seed if seed is None else seed
    video_start = None if start is not None else video_start
    factory = stage_optimizer(registry, settings.optimizer, pipeline, start, extra_starts, video_start)
    run_dir = RunDirectory(settings.out / name)
    run_info = {
        "plugin": settings.plugin,
        "optimizer": settings.optimizer,
        "seed": seed,
        "steps": steps,
        "effects": [e.name for e in pipeline.effects],
        "embedder": settings.embedder or pipeline.phenomenon.default_embedder,
        "parameters": pipeline.simulator.parameter_space.to_dict(),
        "target": target_label,
        "render_params": dict(target.render_params),
        "truth": target.truth,
        "start": None if start is None else {k: float(v) for k, v in start.items()},
        **video_start_identity(video_start),
        "stage": name,
        **({"extra_starts": [{k: float(v) for k, v in p.items()} for p in extra_starts]} if extra_starts else {}),
        **optional_settings(
            fixed_by_user(pipeline, settings.fixed), settings.duration_s, settings.embedder_frames
        ),
    }
    scene = scene_of(pipeline.phenomenon)
    if scene is not None:  # recorded only when given: diagnoses from before scenes stay resumable
        run_info["scene"] = scene
    # No noise measured in the loop: the stage's gap and its noise floor are measured apart.
    config = SearchSpec(
        steps=steps, optimizer=settings.optimizer, seed=seed, noise_samples=0, floor_samples=0,
        select_top=settings.select_top, select_seeds=settings.select_seeds, batch_size=settings.batch_size,
    )  # fmt: skip
    resume = run_dir.run_file.is_file()
    check_resumed_start(run_dir.run_file, video_start)
    report = None if on_trial is None else _trial_reporter(name, steps, on_trial)
    try:
        return run_refinement(
            pipeline, target, factory, run_dir, config,
            run_info=run_info, resume=resume, on_trial=report, embed_clips=embed_clips,
        )  # fmt: skip
    except ResumeMismatch as exc:  # refine's remedy names --overwrite, which diagnose lacks
        raise UserInputError(
            f"{run_dir.path.parent} holds a diagnosis made otherwise (its {name} stage: {exc.shown})",
            remedy="diagnose with the settings it was made with to continue it, or give another --out "
            f"(or delete {run_dir.path.parent} to diagnose again)",
        ) from None


def _trial_reporter(
    name: str, steps: int, on_trial: OnTrial
) -> Callable[[TrialRecord, float], None]:
    return lambda record, _best: on_trial(name, record.step + 1, steps)


def clip_of(pipeline: Pipeline, params: Mapping[str, float], target: Target, seed: int) -> Any:
    """``params`` simulated under ``seed`` and rendered with the target's ζ."""
    return pipeline.renderer.render(
        pipeline.simulator.simulate(params, seed=seed), target.render_params
    )


def calibration_target(
    pipeline: Pipeline,
    params: Mapping[str, float],
    target: Target,
    seed: int,
    encode_dir: Path | None,
) -> Target:
    """A synthetic target made by the baseline model itself at its best θ (another seed).

    With ``encode_dir`` the clip makes a round trip through the video encoder, as a target
    read from a file did: compression changes the pixels, and a self-consistency target
    without it would be easier to match than the real one. The encoded target is kept
    (``self_target.mp4`` with its key in ``self_target.json``) and read back by whoever
    makes it again — the main process reading a worker's stage, a resumed diagnosis: the
    encoder does not repeat itself (:func:`physinfer.video.write_video`), and a target
    encoded anew gave the stage another embedding, which its resume refused.
    """
    if encode_dir is None:
        clip = clip_of(pipeline, params, target, seed)
    else:
        clip = _encoded_once(encode_dir, pipeline, params, target, seed)
    return Target(
        clip,
        dict(params),
        dict(target.render_params),
        "self-consistency target at the baseline fit",
    )


def _encoded_once(
    encode_dir: Path, pipeline: Pipeline, params: Mapping[str, float], target: Target, seed: int
) -> Any:
    """The calibration target's clip after its round trip through the encoder, made once."""

    path, key_path = encode_dir / "self_target.mp4", encode_dir / "self_target.json"
    key = {"params": {k: float(v) for k, v in params.items()}, "seed": int(seed),
           "render_params": dict(target.render_params)}  # fmt: skip
    if path.is_file() and key_path.is_file():
        stored = json.loads(key_path.read_text())
        if stored.get("key") == json.loads(json.dumps(key)):
            return video.read_video(path, fps=stored["fps"])
    clip = clip_of(pipeline, params, target, seed)
    encode_dir.mkdir(parents=True, exist_ok=True)
    video.write_video(path, clip)
    atomic_write_json(key_path, {"key": key, "fps": float(clip.fps)})
    return video.read_video(path, fps=clip.fps)


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
    return [
        (t, seed + 1 + CALIBRATION_SEED_STRIDE * r)
        for r, t in enumerate(noise_seeds(seed + 7, runs))
    ]


def adopt_single_calibration(out: Path) -> None:
    """Rename the ``calibration/`` stage of an older diagnosis to ``calibration-0/``."""
    old, new = out / "calibration", out / "calibration-0"
    if (old / RUN_FILE).is_file() and not new.exists():
        old.rename(new)


def calibration_stage_names(run: int, settings: DiagnoseSettings) -> list[str]:
    """The directories self-consistency run ``run`` writes (the run, and its control)."""
    name = f"calibration-{run}"
    return [name, f"{name}-control"] if settings.calibration_control else [name]


def calibration_run(
    run: int,
    base: Pipeline,
    params: Mapping[str, float],
    target: Target,
    *,
    registry: Registry,
    settings: DiagnoseSettings,
    steps: int,
    effect_steps: int,
    seeds: Sequence[int],
    on_trial: OnTrial | None = None,
    with_control: bool = True,
) -> dict[str, Any]:
    """Self-consistency run ``run`` (and its control): refine the baseline against a target
    it made itself at ``params``; the run's gap record (see :func:`run_calibration`).

    ``with_control=False`` refines the run's own stage only (its control, if the settings
    ask for one, is left for a later call: ``gap_control`` is then ``None`` and ``gap`` the
    run's own, an upper bound; see :mod:`physinfer.discrepancy.self_consistency`)."""
    target_seed, optimizer_seed = calibration_seeds(settings.seed, settings.calibration_runs)[run]
    name, *control_name = calibration_stage_names(run, settings)
    if not with_control:
        control_name = []
    encode_dir = settings.out / name if settings.target_path is not None else None
    cal_target = calibration_target(base, params, target, target_seed, encode_dir)
    cal = run_stage(
        name, base, cal_target, registry=registry, settings=settings, steps=steps, start=None,
        target_label="self-consistency", seed=optimizer_seed, on_trial=on_trial,
        video_start=baseline_video_start(settings.out),
    )  # fmt: skip
    gaps = GapContext(cal_target, base.embedder.embed(cal_target.clip), tuple(seeds), settings.out)
    gap = float(gaps.measure(base, cal.best_params, name).gap)
    gap_control = None
    if control_name:
        control = run_stage(
            control_name[0], base, cal_target, registry=registry, settings=settings, steps=effect_steps,
            start=cal.best_params, target_label="self-consistency", seed=optimizer_seed, on_trial=on_trial,
            extra_starts=polished_starts(settings, base, cal_target, cal.best_params, gaps, control_name[0]),
        )  # fmt: skip
        gap_control = float(gaps.measure(base, control.best_params, control_name[0]).gap)
    return {
        "run": run,
        "gap": gap if gap_control is None else min(gap, gap_control),
        "gap_run": gap,
        "gap_control": gap_control,
        "target_seed": int(target_seed),
        "optimizer_seed": int(optimizer_seed),
    }


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
    on_trial: OnTrial | None = None,
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
        on_trial: Progress of each stage.

    Returns:
        One record per run, in run order: ``gap`` (the run's self-consistency gap),
        ``gap_run`` and ``gap_control`` (``None`` without a control), ``target_seed``,
        ``optimizer_seed``.
    """
    adopt_single_calibration(settings.out)
    return [
        calibration_run(
            r,
            base,
            params,
            target,
            registry=registry,
            settings=settings,
            steps=steps,
            effect_steps=effect_steps,
            seeds=seeds,
            on_trial=on_trial,
        )  # fmt: skip
        for r in range(settings.calibration_runs)
    ]


def deterministic(out: Path) -> bool:
    """Whether the baseline's re-simulations were all alike (its noise floor is 0;
    ``baseline/gap.json``, measured before any control or self-consistency run starts)."""
    path = out / "baseline" / "gap.json"
    return path.is_file() and json.loads(path.read_text())["summary"]["floor"] == 0


def polished_starts(
    settings: DiagnoseSettings,
    base: Pipeline,
    target: Target,
    best: Mapping[str, float],
    gaps: GapContext,
    stage: str,
) -> list[dict[str, float]]:
    """A search's first point after its start: for a deterministic phenomenon the start's
    parameters (an effect's with the base's) refit by Gauss–Newton to the stage's target
    (:func:`physinfer.discrepancy.refit.polished_start`). Every search is polished alike —
    the real target's control, each self-consistency run's and each effect's — so that the
    tested gap, the null scale and what an effect leaves stay one procedure's residual (the
    controls alone polished made the ball's limits 4.2× optimistic: docs/benchmarks.md). None
    for a chaotic phenomenon (single clips too noisy to step on), and none without ridge
    starts (``--no-ridge-starts``)."""
    if not settings.ridge_starts or not deterministic(settings.out):
        return []
    found = polished_start(
        base, target.render_params, best, gaps.target_embedding, (settings.seed,),
        fixed_by_user(base, settings.fixed), settings.out / stage,
    )  # fmt: skip
    return [] if found is None else [found]


def control_stage(
    base: Pipeline,
    target: Target,
    baseline_best: Mapping[str, float],
    gaps: GapContext,
    *,
    registry: Registry,
    settings: DiagnoseSettings,
    effect_steps: int,
    target_label: str,
    on_trial: OnTrial | None = None,
) -> Stage:
    """The equal-budget control: the baseline refined ``effect_steps`` more trials from its fit
    (and, for a deterministic phenomenon, from its polished fit: :func:`polished_starts`)."""
    control = run_stage(
        "control", base, target, registry=registry, settings=settings, steps=effect_steps, start=baseline_best,
        target_label=target_label, on_trial=on_trial,
        extra_starts=polished_starts(settings, base, target, baseline_best, gaps, "control"),
    )  # fmt: skip
    return Stage("baseline", base, control, gaps.measure(base, control.best_params, "control"))


def effect_stage(
    name: str,
    effect: Effect,
    base: Pipeline,
    target: Target,
    baseline_best: Mapping[str, float],
    gaps: GapContext,
    *,
    registry: Registry,
    settings: DiagnoseSettings,
    effect_steps: int,
    target_label: str,
    on_trial: OnTrial | None = None,
) -> Stage:
    """The baseline with ``effect`` switched in, refined from the baseline's fit; its gap."""
    pipeline = augmented_pipeline(
        base, [effect], settings.duration_s, fixed_by_user(base, settings.fixed)
    )
    start, extra = warm_start(baseline_best, [effect]), []
    if (ridge := search_starts(settings.out, name, baseline_best, start, effect_steps)) is not None:
        start, extra = ridge  # where the video points along the effect's ridge (ridge.json)
    # the best start polished with the effect free, as the controls are (polished_starts)
    extra = [*polished_starts(settings, pipeline, target, start, gaps, f"effect-{name}"), *extra]
    result = run_stage(
        f"effect-{name}", pipeline, target, registry=registry, settings=settings, steps=effect_steps,
        start=start, target_label=target_label, on_trial=on_trial, extra_starts=extra,
    )  # fmt: skip
    gap = gaps.measure(pipeline, result.best_params, f"effect-{name}")
    return Stage(name, pipeline, result, gap, n_params=len(effect.parameter_space))


def ablated_stage(stage: Stage, base: Pipeline, gaps: GapContext) -> Stage:
    """An augmented stage's best θ with its effect switched off: a baseline fit too.

    An augmented run may owe its better fit to its base parameters, not to its effect; the
    best baseline fit found by any stage is what an effect must beat.
    """
    space = base.simulator.parameter_space
    off = {
        k: v
        for k, v in warm_start(stage.result.best_params, stage.pipeline.effects).items()
        if k in space
    }
    gap = gaps.measure(base, off, f"effect-{stage.label}", cache_name="gap_effect_off.json")
    return Stage(f"{stage.label} off", base, stage.result, gap, params=off)
