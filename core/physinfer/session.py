"""Run a refinement end to end: the pipeline (:mod:`physinfer.pipeline`) and target
(:mod:`physinfer.target`), the run directory and its identity, the posterior's start, the
loop with a progress bar, and the outputs (result files, figures, videos, the report): the
refine command.

:mod:`physinfer.api` calls :func:`refine`; the pipeline builders and :func:`load_target` are
re-exported here for code written before they moved to :mod:`physinfer.pipeline` and
:mod:`physinfer.target`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.adequacy import assess_fit
from physinfer.conditioning import Conditioning
from physinfer.errors import UserInputError
from physinfer.evaluation import Pipeline
from physinfer.io import atomic_write_json
from physinfer.locking import exclusive_directory
from physinfer.loop import run_refinement
from physinfer.pipeline import (  # noqa: F401 - re-exported: the session's historical API
    EffectParameterError,
    build_pipeline,
    effect_parameters,
    fixed_by_user,
    full_parameter_space,
    make_simulator,
    naming_effects,
    target_duration,
)
from physinfer.refinement import RefineConfig, RefineResult
from physinfer.registry import Registry
from physinfer.roles import Target
from physinfer.rundir import TARGET_FILE, RunDirectory, TrialRecord, optional_settings
from physinfer.scene import scene_of
from physinfer.target import load_target
from physinfer.threads import with_refinement_threads


def resume_identity(target: Target, weights: Path | None) -> dict[str, Any]:
    """The ``run.json`` entries that tie a run to its target video and embedder weights.

    With :data:`~physinfer.rundir.IDENTITY`'s other entries they make the run's identity: a
    ``--resume`` with another video, or other ``--weights``, is refused.
    """
    from physinfer.rundir import array_sha256, path_sha256

    return {
        "target_sha256": array_sha256(target.clip.frames, float(target.clip.fps)),
        "weights_sha256": path_sha256(weights) if weights is not None and Path(weights).exists() else None,
    }


#: Narrowest search box per parameter, normalised (a tenth of the range).
MIN_BOX = 0.2


def start_from_video(pipeline: Pipeline, target: Target) -> tuple[Any, Any, dict[str, Any]] | None:
    """The search's start and box from what the target video tells directly
    (``Phenomenon.video_estimate``), or ``None`` when the phenomenon reads nothing.

    Returns:
        ``(start_x, (lo, hi), record)``: normalised start and box, and the estimate for
        ``run.json`` (``start``).
    """
    estimate_of = pipeline.phenomenon.video_estimate
    if estimate_of is None:
        return None
    space = pipeline.simulator.parameter_space
    estimate = {k: v for k, v in estimate_of(target.clip).items() if k in space.names}
    if not estimate:
        return None
    lo, hi = -np.ones(len(space.names)), np.ones(len(space.names))
    for i, spec in enumerate(space):
        if spec.name in estimate:
            low, high = sorted(np.clip(spec.to_unit(np.array(estimate[spec.name][1:])), -1.0, 1.0))
            # An estimate beyond the range leaves no box: search the edge it points to.
            lo[i], hi[i] = min(low, 1.0 - MIN_BOX), max(high, -1.0 + MIN_BOX)
    values = {spec.name: float(np.clip(estimate[spec.name][0], *spec.bounds)) for spec in space if spec.name in estimate}
    centre = np.clip(space.to_unit(space.complete(values)), lo, hi)  # the others start at their defaults
    record: dict[str, Any] = {"video_estimate": {k: [float(x) for x in v] for k, v in estimate.items()}}
    outside = {
        spec.name: ("below" if estimate[spec.name][0] < spec.bounds[0] else "above")
        for spec in space
        if spec.name in estimate and not spec.bounds[0] <= estimate[spec.name][0] <= spec.bounds[1]
    }
    if outside:  # the search stays in range; the answer must say the video points beyond it
        record["outside_range"] = {
            name: f"the video suggests {name} {side} {space[name].bounds[0 if side == 'below' else 1]:g} "
            f"{space[name].unit} ({estimate[name][0]:.3g} from the video alone)"
            for name, side in outside.items()
        }
    return centre, (lo, hi), record


def default_budget(phenomenon: Any, steps: int | None, *, from_posterior: bool) -> int:
    """The trials of a refinement: ``steps`` when given; otherwise the phenomenon's default,
    or its ``default_steps_with_posterior`` when the search starts from a posterior estimator."""
    if steps is not None:
        return steps
    if from_posterior and phenomenon.default_steps_with_posterior is not None:
        return int(phenomenon.default_steps_with_posterior)
    return int(phenomenon.default_steps)


@with_refinement_threads
def refine(
    registry: Registry,
    *,
    plugin: str,
    target_path: Path | None = None,
    fps: float | None = None,
    truth: Sequence[str] = (),
    steps: int | None = None,
    optimizer: str = "ax",
    embedder: str | None = None,
    weights: Path | None = None,
    device: str | None = None,
    effects: Sequence[str] = (),
    model: Path | None = None,
    render_set: Mapping[str, Any] | None = None,
    fixed: Sequence[str] = (),
    seed: int = 0,
    out: Path,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool | Callable[[int, int, float], None] = True,
    noise_samples: int = 3,
    seeds_per_trial: int = 1,
    floor_samples: int = 4,
    select_top: int = 0,
    select_seeds: int = 3,
    batch_size: int = 1,
    workers: int | None = None,
    scheduler: str | None = None,
    duration_s: float | None = None,
    embedder_frames: int | None = None,
    posterior: Path | None = None,
    use_posterior: bool = True,
    scene_set: Mapping[str, Any] | None = None,
    conditioning: Conditioning | None = None,
) -> RefineResult:
    """Run or continue a refinement end to end and write every output into ``out``.

    ``posterior`` is an estimator file from ``physinfer posterior train`` (``None``: the
    phenomenon's shipped one, where it applies; ``use_posterior=False``: none): the
    target's amortized posterior is reported beside the best fit (``result.json``
    ``posterior`` and ``correlations``) and the search starts at its median.

    ``model`` is a model file written by ``physinfer diagnose``: its effects are switched
    in and the refinement is warm-started from its values (and, unless ``duration_s`` or
    ``fixed`` are given, simulates clips as long as the diagnosis did and holds fixed what
    it held fixed). ``fixed`` holds parameters at
    given values (``NAME=VALUE``, patterns allowed) and refines the rest. ``workers``
    (local processes) or ``scheduler`` (a Dask scheduler address) simulate and render each
    step's trials there (:mod:`physinfer.trial_workers`); by default they run here.
    ``duration_s``, ``embedder_frames`` and ``scene_set``: see :func:`build_pipeline`; a
    scene is recorded in ``run.json`` (a resume key) and ``result.json`` (``scene``), and a
    posterior estimator trained under another scene is not used (``posterior_note`` says so).
    ``conditioning``: how a ``target_path`` video is framed and its ζ estimated
    (:mod:`physinfer.conditioning`; ``None``: used as it is); what was done is recorded in
    ``result.json`` (``target_conditions``).
    """
    registry.get("optimizers", optimizer)  # fail early, listing the installed ones
    if resume and overwrite:
        raise UserInputError(
            "--resume continues the run in --out and --overwrite starts it again: give one of them"
        )
    run_dir = RunDirectory(out)
    run_dir.check_out(overwrite=overwrite, target=target_path)
    model_file = None
    if model is not None:
        from physinfer.discrepancy.model import model_for_refine

        model_file = model_for_refine(model, plugin, effects)
        effects = model_file.effects
        if duration_s is None:  # the clip length the model was fitted on (diagnose --duration)
            duration_s = model_file.extra.get("duration_s")
        if not fixed:  # the values the diagnosis held fixed (diagnose --fix)
            fixed = [f"{name}={value!r}" for name, value in model_file.extra.get("fixed", {}).items()]
        if not scene_set:  # the scene the diagnosis fitted it on (diagnose --scene-set)
            scene_set = model_file.extra.get("scene") or {}
    pipeline = build_pipeline(
        registry, plugin, effects=effects, embedder=embedder, weights=weights, device=device, fixed=fixed,
        duration_s=duration_s, embedder_frames=embedder_frames, scene_set=scene_set,
    )  # fmt: skip
    scene = scene_of(pipeline.phenomenon)
    if model_file is not None:
        from physinfer.discrepancy.model import check_model_scene

        check_model_scene(model_file, model, pipeline.phenomenon, scene)
    fixed_values = fixed_by_user(pipeline, fixed)
    settings = {
        "optimizer": optimizer, "seed": seed, "noise_samples": noise_samples, "seeds_per_trial": seeds_per_trial,
        "floor_samples": floor_samples, "select_top": select_top, "select_seeds": select_seeds,
        "batch_size": batch_size,
    }  # fmt: skip
    # Checked before the target is read; the budget itself waits for the posterior (below).
    RefineConfig(steps=steps if steps is not None else pipeline.phenomenon.default_steps, **settings).validate()
    with naming_effects(registry, plugin, effects, "--truth"):
        target = load_target(
            pipeline, target_path, fps=fps, truth=truth, render_set=render_set or {}, fixed=fixed,
            conditioning=conditioning,
        )  # fmt: skip
    if duration_s is None and (duration_s := target_duration(pipeline, target)) is not None:
        pipeline = build_pipeline(
            registry, plugin, effects=effects, embedder=embedder, weights=weights, device=device, fixed=fixed,
            duration_s=duration_s, embedder_frames=embedder_frames, scene_set=scene_set,
        )  # fmt: skip
    amortized, amortized_note = None, None
    if use_posterior:
        from physinfer.posterior.workflow import posterior_for_refinement

        amortized, amortized_note = posterior_for_refinement(
            registry, plugin=plugin, parameter_space=pipeline.simulator.parameter_space, clip=target.clip,
            posterior=posterior, device=device, seed=seed, scene=scene,
        )  # fmt: skip
    budget = default_budget(pipeline.phenomenon, steps, from_posterior=amortized is not None and model_file is None)
    config = RefineConfig(steps=budget, **settings)
    if resume:
        stored = run_dir.load_run_info()
        if stored.get("target") not in (None, "default") and target_path is None:
            raise UserInputError(f"{out} was run against --target {stored['target']}; pass the same --target")
    run_info = {
        "plugin": plugin,
        "optimizer": optimizer,
        "seed": seed,
        "steps": budget,
        "effects": list(effects),
        "embedder": embedder or pipeline.phenomenon.default_embedder,
        "parameters": pipeline.simulator.parameter_space.to_dict(),
        "target": str(target_path) if target_path else "default",
        "render_params": dict(target.render_params),
        "truth": target.truth,
        "overwrite": overwrite,
        "seeds_per_trial": seeds_per_trial,
        "batch_size": batch_size,  # informative: a resumed run may use another q
    }
    run_info.update(optional_settings(fixed_values, duration_s, embedder_frames))
    if scene is not None:  # recorded only when given: runs from before scenes stay resumable
        run_info["scene"] = scene
    run_info.update(resume_identity(target, weights))
    factory = registry.get("optimizers", optimizer).load()
    start_x, post_start, video_start = None, None, None
    if model_file is not None:
        from physinfer.discrepancy.warmstart import warm_start_factory

        space = pipeline.simulator.parameter_space
        start = model_file.start_for(full_parameter_space(pipeline, fixed))  # fixed parameters dropped below
        start_x = space.to_unit({name: start[name] for name in space.names})
        factory = warm_start_factory(factory, start_x)
    elif (video_start := start_from_video(pipeline, target)) is not None:
        # What the whole video tells directly (a pendulum's period over 25 s) is sharper than
        # an estimator that reads its first seconds; the estimator's intervals are still reported.
        from physinfer.discrepancy.warmstart import warm_start_factory

        start_x, box, run_info["start"] = video_start
        factory = warm_start_factory(factory, start_x, box)
        run_info["search_box"] = [[float(v) for v in ends] for ends in box]
    elif amortized is not None:  # spend the budget where the video points
        from physinfer.discrepancy.warmstart import warm_start_factory
        from physinfer.posterior.refined import posterior_start

        post_start = posterior_start(amortized, pipeline.simulator.parameter_space)
        start_x = post_start.start_x
        factory = warm_start_factory(factory, start_x, post_start.box)
        run_info["start"] = {"posterior_median": str(amortized.estimator), "search_box": post_start.box_physical}
    # Every trial's coordinates depend on the warm start and the search box: part of the identity.
    run_info["start_x"] = None if start_x is None else [float(v) for v in start_x]
    if post_start is not None:
        run_info["search_box"] = [[float(v) for v in ends] for ends in post_start.box]
    from physinfer.trial_workers import PipelineSpec, scene_items, trial_workers

    spec = PipelineSpec(plugin, tuple(effects), tuple(fixed), duration_s=duration_s, scene=scene_items(scene))
    with exclusive_directory(out):  # one writer: a second refine of this --out is refused
        with (
            trial_workers(pipeline, spec, workers=workers, scheduler=scheduler) as executor,
            _progress(budget, enabled=progress) as on_trial,
        ):
            result = run_refinement(
                pipeline, target, factory, run_dir, config, run_info=run_info, resume=resume, on_trial=on_trial
            )
        from physinfer.video import write_video

        if np.isfinite(result.best_distance):  # the refine command's verdict (diagnose has its own tests)
            result.extra["adequacy"] = assess_fit(
                pipeline, result.best_params, result.best_distance, target, result.extra.get("noise_floor"), seed
            )
        if fixed_values:
            result.extra["fixed"] = fixed_values
        if scene is not None:
            result.extra["scene"] = scene
        if target.conditions:
            result.extra["target_conditions"] = target.conditions
        if video_start is not None:
            result.extra["video_estimate"] = video_start[2]
        if executor is not None:
            result.extra["executor"] = executor
        if amortized is not None:
            from physinfer.posterior.refined import report_posterior

            report_posterior(result, amortized, pipeline.simulator.parameter_space, post_start, run_dir.path, seed=seed)
        elif amortized_note:
            result.extra["posterior_note"] = amortized_note
        write_video(run_dir.path / TARGET_FILE, target.clip)
        write_outputs(result, pipeline, target, run_dir, seed)
    pipeline.renderer.close()
    return result


def write_outputs(result: RefineResult, pipeline: Pipeline, target: Target, run_dir: RunDirectory, seed: int) -> None:
    """Write ``result.json``, the refinement plot, the best trajectory and the side-by-side video,
    then ask the report for ``report.html``: the refine command's files (the loop writes only
    its run directory's trial log)."""
    from physinfer.plotting import plot_refinement
    from physinfer.video import side_by_side, write_video

    best_traj = pipeline.simulator.simulate(result.best_params, seed=seed)
    best_traj.save(run_dir.path / "best_trajectory.npz")
    best_clip = pipeline.renderer.render(best_traj, target.render_params)
    write_video(run_dir.path / "side_by_side.mp4", side_by_side([target.clip, best_clip]))
    plot_refinement(
        result.trials, result.ground_truth, run_dir.path / "refinement.png", bands=result.extra.get("posterior")
    )
    result.extra.setdefault("outputs", {})
    result.extra["outputs"] = {
        name: str(run_dir.path / name)
        for name in ("result.json", "trials.jsonl", "refinement.png", "side_by_side.mp4", "best_trajectory.npz")
    }
    atomic_write_json(run_dir.path / "result.json", result.summary())
    from physinfer.report import write_report_quietly  # report.html; a failure only warns

    write_report_quietly(run_dir.path)


class _progress:
    """A rich progress bar on stderr showing the best distance, or the caller's callback
    ``(done, total, best_distance)``; yields an ``on_trial`` callback."""

    def __init__(self, total: int, enabled: bool | Callable[[int, int, float], None]) -> None:
        self.total, self.enabled = total, enabled

    def __enter__(self):  # noqa: ANN204
        if callable(self.enabled):
            report = self.enabled
            return lambda record, best: report(record.step + 1, self.total, best)
        if not self.enabled:
            return None
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeRemainingColumn,
        )

        from physinfer.console import err_console

        self._bar = Progress(
            TextColumn("refining"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("best {task.fields[best]}"),
            TimeRemainingColumn(),
            console=err_console,
            transient=False,
        )
        self._bar.__enter__()
        self._task = self._bar.add_task("refine", total=self.total, best="-")

        def on_trial(record: TrialRecord, best: float) -> None:
            self._bar.update(self._task, completed=record.step + 1, best=f"{best:.4g}")

        return on_trial

    def __exit__(self, *exc: object) -> None:
        if self.enabled is True:
            self._bar.__exit__(*exc)
