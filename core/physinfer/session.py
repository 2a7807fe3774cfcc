"""The refine command: what a refinement is asked and the run end to end.

What it is asked comes as four small frozen specs built once: what the model is
(:class:`ModelSpec`), what the target is (:class:`TargetSpec`), how to search
(:class:`~physinfer.refinement.SearchSpec`, the engine's record: the loop reads it as it is) and
how to execute (:class:`ExecutionSpec`), bundled as a :class:`RefineRequest`. Each setting is
declared once, as a field of one spec; :func:`refine`'s keywords are those fields
(:meth:`RefineRequest.from_keywords`), and :mod:`physinfer.api` fills the specs from
:class:`~physinfer.api.RefineOptions` by name.

:func:`run` claims the run directory, builds the pipeline and reads the target (through the
specs), finds the posterior estimator and the search's start, records the run's identity,
runs the loop (:mod:`physinfer.loop`) with a progress bar, and writes the outputs (result
files, figures, videos, the report). The specs were :mod:`physinfer.specs` until 2026-11-30;
they, the pipeline builders, ``load_target`` and ``default_budget`` are found at their old
paths with a warning (:data:`physinfer.moved.MOVED`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.adequacy import assess_fit
from physinfer.conditioning import Conditioning
from physinfer.console import err_console
from physinfer.discrepancy.model import ModelFile, check_model_scene, model_for_refine
from physinfer.discrepancy.warmstart import warm_start_factory
from physinfer.errors import UserInputError
from physinfer.evaluation import (
    Pipeline,
    build_pipeline,
    fixed_by_user,
    full_parameter_space,
    naming_effects,
    target_duration,
)
from physinfer.io import atomic_write_json
from physinfer.locking import exclusive_directory
from physinfer.loop import run_refinement
from physinfer.moved import moved_names
from physinfer.plotting import plot_refinement  # imports matplotlib when it draws
from physinfer.posterior.refined import posterior_start, report_posterior
from physinfer.refinement import RefineResult, SearchSpec, TargetPosterior, TargetReport
from physinfer.registry import Registry
from physinfer.report import write_report_quietly
from physinfer.roles import Optimizer, Target
from physinfer.rundir import (
    TARGET_FILE,
    RunDirectory,
    TrialRecord,
    array_sha256,
    optional_settings,
    path_sha256,
)
from physinfer.scene import scene_of
from physinfer.target import load_target, start_from_video, start_identity
from physinfer.threads import with_refinement_threads
from physinfer.trial_workers import PipelineSpec, scene_items, trial_workers
from physinfer.video import side_by_side, write_video

__getattr__ = moved_names(__name__)


# What a refinement is asked.


def _as_tuples(spec: Any, *names: str) -> None:
    """Store the sequences ``names`` of a frozen ``spec`` as tuples (callers pass lists)."""
    for name in names:
        object.__setattr__(spec, name, tuple(getattr(spec, name)))


@dataclass(frozen=True)
class ModelSpec:
    """What the model is: the phenomenon, its effects and held parameters, and how its
    clips are simulated and seen.

    Attributes:
        plugin: Phenomenon name.
        effects: Effects switched in (``--effect``).
        embedder: Embedder name (``None``: the phenomenon's default).
        weights: Embedder weights file (``None``: the shipped default).
        device: torch device of the embedder (``None``: CUDA when present, else CPU).
        fixed: ``NAME=VALUE`` items (patterns allowed) held fixed and left out of the
            search (``--fix``).
        duration_s: Seconds every simulation records (``None``: the phenomenon's default,
            or the target's length where the phenomenon takes it from the target).
        embedder_frames: Frames a parameter-free embedder reads (``None``: its default).
        scene_set: The scene's known settings (``--scene-set``; ``None``: the default scene).
        model_file: A model file written by ``physinfer diagnose`` (``--model``; the
            keyword ``model``): its effects are switched in and the search starts at its
            values (see :meth:`with_model_file`).
    """

    plugin: str
    effects: tuple[str, ...] = ()
    embedder: str | None = None
    weights: Path | None = None
    device: str | None = None
    fixed: tuple[str, ...] = ()
    duration_s: float | None = None
    embedder_frames: int | None = None
    scene_set: Mapping[str, Any] | None = None
    model_file: Path | None = None

    def __post_init__(self) -> None:
        _as_tuples(self, "effects", "fixed")

    def with_model_file(self) -> tuple[ModelSpec, ModelFile | None]:
        """This spec completed from its model file, and the file (``None`` without one).

        The file's effects are the model's; the clip length, held values and scene the
        diagnosis fitted it with (``diagnose --duration``, ``--fix``, ``--scene-set``) fill
        those this spec leaves unset.

        Raises:
            UserInputError: the file is missing, of another plugin, or names other effects.
        """
        if self.model_file is None:
            return self, None
        model = model_for_refine(self.model_file, self.plugin, self.effects)
        fitted = model.extra
        completed = replace(
            self,
            effects=model.effects,
            duration_s=fitted.get("duration_s") if self.duration_s is None else self.duration_s,
            fixed=self.fixed or tuple(f"{name}={value!r}" for name, value in fitted.get("fixed", {}).items()),
            scene_set=self.scene_set or fitted.get("scene") or {},
        )
        return completed, model

    def pipeline(self, registry: Registry) -> Pipeline:
        """The model's simulator, renderer and embedder (:func:`~physinfer.evaluation.build_pipeline`)."""
        return build_pipeline(
            registry, self.plugin, effects=self.effects, embedder=self.embedder, weights=self.weights,
            device=self.device, fixed=self.fixed, duration_s=self.duration_s,
            embedder_frames=self.embedder_frames, scene_set=self.scene_set,
        )  # fmt: skip

    def worker_spec(self, scene: Mapping[str, Any] | None) -> PipelineSpec:
        """What a trial worker rebuilds the simulator and renderer from (``scene``: the
        resolved scene, :func:`~physinfer.scene.scene_of`)."""
        return PipelineSpec(self.plugin, self.effects, self.fixed, duration_s=self.duration_s, scene=scene_items(scene))


@dataclass(frozen=True)
class TargetSpec:
    """What the target is: the video to match and what is known about it.

    Attributes:
        target_path: Video file (``--target``; ``None``: the phenomenon's own target).
        fps: Its frame rate when the file does not say.
        truth: Known true values ``NAME=VALUE``, for error reporting only.
        render_set: Render settings ζ of the simulations, ``{NAME: VALUE}`` (over the
            default or the camera estimated from the video).
        conditioning: How a ``target_path`` video is framed and its ζ estimated
            (:mod:`physinfer.conditioning`; ``None``: used as it is).
    """

    target_path: Path | None = None
    fps: float | None = None
    truth: tuple[str, ...] = ()
    render_set: Mapping[str, Any] | None = None
    conditioning: Conditioning | None = None

    def __post_init__(self) -> None:
        _as_tuples(self, "truth")

    def load(self, registry: Registry, pipeline: Pipeline, model: ModelSpec) -> Target:
        """The target, read (and conditioned) for ``pipeline`` (:func:`~physinfer.target.load_target`);
        a ``--truth`` of an effect's parameter names the effect."""
        with naming_effects(registry, model.plugin, model.effects, "--truth"):
            return load_target(
                pipeline, self.target_path, fps=self.fps, truth=self.truth, render_set=self.render_set or {},
                fixed=model.fixed, conditioning=self.conditioning,
            )  # fmt: skip


@dataclass(frozen=True)
class ExecutionSpec:
    """How to execute: the run directory (new, continued or replaced) and where the trials run.

    Attributes:
        out: The run directory.
        resume: Continue the run in ``out``.
        overwrite: Replace the run in ``out``.
        workers: Local worker processes for each step's trials (``None``: in this process;
            :mod:`physinfer.trial_workers`).
        scheduler: A Dask scheduler address for the trials.
    """

    out: Path
    resume: bool = False
    overwrite: bool = False
    workers: int | None = None
    scheduler: str | None = None

    def run_directory(self, target_path: Path | None) -> RunDirectory:
        """The run directory, checked before any work (:meth:`~physinfer.rundir.RunDirectory.check_out`).

        Raises:
            UserInputError: both ``resume`` and ``overwrite``, or an ``out`` the run may not write.
        """
        if self.resume and self.overwrite:
            raise UserInputError(
                "--resume continues the run in --out and --overwrite starts it again: give one of them"
            )
        run_dir = RunDirectory(self.out)
        run_dir.check_out(overwrite=self.overwrite, target=target_path)
        return run_dir


@dataclass(frozen=True)
class RefineRequest:
    """A refinement as its four specs, each built once (:meth:`from_keywords`, or
    :mod:`physinfer.api` from its options) and read by :func:`physinfer.session.run`.

    Attributes:
        model: What the model is.
        target: What the target is.
        search: How to search.
        execution: How to execute.
    """

    model: ModelSpec
    target: TargetSpec
    search: SearchSpec
    execution: ExecutionSpec

    @classmethod
    def from_keywords(cls, **settings: Any) -> RefineRequest:
        """Each keyword to the spec whose field it names (``model`` is
        :attr:`ModelSpec.model_file`); ``plugin`` and ``out`` are needed.

        Raises:
            TypeError: a keyword no spec declares, or ``plugin`` or ``out`` missing.
        """
        if "model" in settings:
            settings["model_file"] = settings.pop("model")
        specs: dict[str, Any] = {}
        for name, kind in _SPECS.items():
            names = {f.name for f in dataclasses.fields(kind)}
            specs[name] = kind(**{key: settings.pop(key) for key in list(settings) if key in names})
        if settings:
            raise TypeError(f"refine() got unexpected keyword arguments: {', '.join(sorted(settings))}")
        return cls(**specs)


#: The specs of a :class:`RefineRequest`, by its field names.
_SPECS: dict[str, type] = {"model": ModelSpec, "target": TargetSpec, "search": SearchSpec, "execution": ExecutionSpec}


# The refine command.


#: ``progress``: ``True`` for a rich bar on stderr, ``False`` for none, or a callable
#: ``(done, total, best_distance)``.
Progress = bool | Callable[[int, int, float], None]


@with_refinement_threads  # as run is: the command's torch work outside the loop too
def refine(registry: Registry, *, progress: Progress = True, **settings: Any) -> RefineResult:
    """Run or continue a refinement end to end and write every output into ``out``.

    The keywords are the fields of the request's specs (:meth:`RefineRequest.from_keywords`):
    ``plugin`` and ``out`` are needed; the model (:class:`ModelSpec`:
    ``effects``, ``fixed``, ``model``, ...), the target (:class:`TargetSpec`:
    ``target_path``, ``truth``, ``conditioning``, ...), the search
    (:class:`~physinfer.refinement.SearchSpec`: ``steps``, ``select_top``, ``posterior``, ...) and
    the execution (:class:`ExecutionSpec`: ``resume``, ``workers``, ...).
    See :func:`run`.
    """
    return run(registry, RefineRequest.from_keywords(**settings), progress=progress)


@with_refinement_threads
def run(registry: Registry, request: RefineRequest, *, progress: Progress = True) -> RefineResult:
    """Run or continue the refinement ``request`` asks for; write every output into its run directory.

    A model file (``model``) switches its effects in and starts the search at its values;
    otherwise the search starts where the video itself points (``Phenomenon.video_estimate``)
    or at the posterior estimator's median (its intervals are reported beside the best fit,
    ``result.json`` ``posterior``; one trained under another scene is not used and
    ``posterior_note`` says why). With ``workers`` or ``scheduler`` each step's trials are
    simulated and rendered there (:mod:`physinfer.trial_workers`). What the target's
    conditioning did is recorded in ``result.json`` (``target_conditions``).
    """
    registry.get("optimizers", request.search.optimizer)  # fail early, listing the installed ones
    execution, search = request.execution, request.search
    run_dir = execution.run_directory(request.target.target_path)
    setup = _set_up(registry, request)
    try:  # the renderer's GL context is released even when the run fails
        amortized, amortized_note = _amortized_posterior(registry, setup, search, request.target.render_set)
        from_posterior = amortized is not None and setup.model_file is None
        search = search.with_budget(setup.pipeline.phenomenon, from_posterior=from_posterior)
        if execution.resume:
            _check_resumed_target(run_dir, request)
        start = _search_start(registry, setup, search.optimizer, amortized)
        run_info = _identity(request, setup, search.steps, start)
        with exclusive_directory(execution.out):  # one writer: a second refine of this --out is refused
            with (
                trial_workers(
                    setup.pipeline, setup.model.worker_spec(setup.scene), workers=execution.workers,
                    scheduler=execution.scheduler,
                ) as executor,
                _progress(search.steps, enabled=progress) as on_trial,
            ):  # fmt: skip
                result = run_refinement(
                    setup.pipeline, setup.target, start.factory, run_dir, search, run_info=run_info,
                    resume=execution.resume, on_trial=on_trial,
                )  # fmt: skip
            _report_beside(result, setup, start, (amortized, amortized_note), executor, run_dir, search.seed)
            write_video(run_dir.path / TARGET_FILE, setup.target.clip)
            write_outputs(result, setup.pipeline, setup.target, run_dir, search.seed)
    finally:
        setup.pipeline.renderer.close()
    return result


@dataclass(frozen=True)
class _SetUp:
    """What a refinement runs on, built from its request.

    Attributes:
        model: The model spec, completed from its model file and the target's length.
        model_file: The model file (``None``: none given).
        pipeline: The model's simulator, renderer and embedder.
        scene: The resolved scene (``None``: the default).
        fixed_values: The values ``--fix`` holds, by parameter.
        target: The target.
    """

    model: ModelSpec
    model_file: ModelFile | None
    pipeline: Pipeline
    scene: dict[str, Any] | None
    fixed_values: dict[str, float]
    target: Target


def _set_up(registry: Registry, request: RefineRequest) -> _SetUp:
    """The model (completed from its file), its pipeline, and the target read for it.

    A phenomenon that takes its clip length from the target has its pipeline built again
    for that length, unless a duration is given (or the model file has one)."""
    model, model_file = request.model.with_model_file()
    pipeline = model.pipeline(registry)
    scene = scene_of(pipeline.phenomenon)
    if model_file is not None:
        check_model_scene(model_file, model.model_file, pipeline.phenomenon, scene)
    fixed_values = fixed_by_user(pipeline, model.fixed)
    search = request.search
    # Checked before the target is read; the budget itself waits for the posterior.
    search.validate()
    target = request.target.load(registry, pipeline, model)
    if model.duration_s is None and (duration_s := target_duration(pipeline, target)) is not None:
        model = replace(model, duration_s=duration_s)
        pipeline = model.pipeline(registry)
    return _SetUp(model, model_file, pipeline, scene, fixed_values, target)


def _amortized_posterior(
    registry: Registry, setup: _SetUp, search: SearchSpec, render_set: Mapping[str, Any] | None
) -> tuple[Any, str | None]:
    """The target's amortized posterior and why there is none (:func:`posterior_for_refinement`);
    the camera the user told (``--render-set``) goes to an estimator told the camera."""
    if not search.use_posterior:
        return None, None
    # Imported here: torch and sbi take seconds, and a run without an estimator needs neither.
    from physinfer.posterior.workflow import posterior_for_refinement

    return posterior_for_refinement(
        registry, plugin=setup.model.plugin, parameter_space=setup.pipeline.simulator.parameter_space,
        clip=setup.target.clip, posterior=search.posterior, device=setup.model.device, seed=search.seed,
        scene=setup.scene, render={name: setup.target.render_params[name] for name in render_set or {}} or None,
    )  # fmt: skip


def _check_resumed_target(run_dir: RunDirectory, request: RefineRequest) -> None:
    """Refuse to resume a run of a user's video without ``--target``."""
    stored = run_dir.load_run_info()
    if stored.get("target") not in (None, "default") and request.target.target_path is None:
        raise UserInputError(
            f"{request.execution.out} was run against --target {stored['target']}; pass the same --target"
        )


@dataclass(frozen=True)
class _Start:
    """Where the search starts.

    Attributes:
        factory: Builds the optimizer (warm-started where a start is known).
        identity: The start's ``run.json`` entries (part of the run's identity: every
            trial's coordinates depend on the start and the search box).
        video_estimate: What the video told directly (``result.json`` ``video_estimate``).
        posterior_start: The start from the posterior estimator's median, if it was one.
    """

    factory: Callable[..., Optimizer]
    identity: dict[str, Any]
    video_estimate: dict[str, Any] | None = None
    posterior_start: Any = None


def _search_start(registry: Registry, setup: _SetUp, optimizer: str, amortized: Any) -> _Start:
    """The search's start: the model file's values, else what the video tells directly, else
    the posterior estimator's median (with its box), else the centre."""
    factory = registry.get("optimizers", optimizer).load()
    space = setup.pipeline.simulator.parameter_space
    if setup.model_file is not None:
        start = setup.model_file.start_for(full_parameter_space(setup.pipeline, setup.model.fixed))
        start_x = space.to_unit({name: start[name] for name in space.names})  # fixed parameters dropped
        return _Start(warm_start_factory(factory, start_x), {"start_x": _floats(start_x)})
    video_start = start_from_video(setup.pipeline, setup.target)
    if video_start is not None:
        # What the whole video tells directly (a pendulum's period over 25 s) is sharper than
        # an estimator that reads its first seconds; the estimator's intervals are still reported.
        start_x, box, record = video_start
        identity = {"start": record, **start_identity(video_start)}
        return _Start(warm_start_factory(factory, start_x, box), identity, video_estimate=record)
    if amortized is not None:  # spend the budget where the video points
        post_start = posterior_start(amortized, space)
        identity = {
            "start": {"posterior_median": str(amortized.estimator), "search_box": post_start.box_physical},
            "start_x": _floats(post_start.start_x),
            "search_box": [_floats(ends) for ends in post_start.box],
        }
        return _Start(warm_start_factory(factory, post_start.start_x, post_start.box), identity, None, post_start)
    return _Start(factory, {"start_x": None})


def _floats(values: Any) -> list[float]:
    return [float(v) for v in values]


def _identity(request: RefineRequest, setup: _SetUp, budget: int, start: _Start) -> dict[str, Any]:
    """What ``run.json`` records: the run's identity (checked on ``--resume``) and what it was
    run with."""
    model, search, target_path = setup.model, request.search, request.target.target_path
    run_info = {
        "plugin": model.plugin,
        "optimizer": search.optimizer,
        "seed": search.seed,
        "steps": budget,
        "effects": list(model.effects),
        "embedder": model.embedder or setup.pipeline.phenomenon.default_embedder,
        "parameters": setup.pipeline.simulator.parameter_space.to_dict(),
        "target": str(target_path) if target_path else "default",
        "render_params": dict(setup.target.render_params),
        "truth": setup.target.truth,
        "overwrite": request.execution.overwrite,
        "seeds_per_trial": search.seeds_per_trial,
        "batch_size": search.batch_size,  # informative: a resumed run may use another q
    }
    run_info.update(optional_settings(setup.fixed_values, model.duration_s, model.embedder_frames))
    if setup.scene is not None:  # recorded only when given: runs from before scenes stay resumable
        run_info["scene"] = setup.scene
    run_info.update(resume_identity(setup.target, model.weights))
    run_info.update(start.identity)
    return run_info


def resume_identity(target: Target, weights: Path | None) -> dict[str, Any]:
    """The ``run.json`` entries that tie a run to its target video and embedder weights.

    With :data:`~physinfer.rundir.IDENTITY`'s other entries they make the run's identity: a
    ``--resume`` with another video, or other ``--weights``, is refused.
    """
    return {
        "target_sha256": array_sha256(target.clip.frames, float(target.clip.fps)),
        "weights_sha256": path_sha256(weights) if weights is not None and Path(weights).exists() else None,
    }


def _report_beside(
    result: RefineResult,
    setup: _SetUp,
    start: _Start,
    posterior: tuple[Any, str | None],
    executor: dict[str, Any] | None,
    run_dir: RunDirectory,
    seed: int,
) -> None:
    """Add to ``result`` what the refine command reports beside the best fit: its adequacy,
    the held values, the scene, the target's conditioning, the video's estimate, the executor,
    and the posterior (or why there is none)."""
    target = setup.target
    if np.isfinite(result.best_distance):  # the refine command's verdict (diagnose has its own tests)
        floor = result.noise.floor if result.noise is not None else None
        result.adequacy = assess_fit(setup.pipeline, result.best_params, result.best_distance, target, floor, seed)
    result.fixed = setup.fixed_values
    result.target = TargetReport(setup.scene, target.conditions, start.video_estimate)
    result.executor = executor
    amortized, note = posterior
    if amortized is not None:
        space = setup.pipeline.simulator.parameter_space
        report_posterior(result, amortized, space, start.posterior_start, run_dir.path, seed=seed)
    elif note:
        result.target_posterior = TargetPosterior(note=note)


def write_outputs(result: RefineResult, pipeline: Pipeline, target: Target, run_dir: RunDirectory, seed: int) -> None:
    """Write ``result.json``, the refinement plot, the best trajectory and the side-by-side video,
    then ask the report for ``report.html``: the refine command's files (the loop writes only
    its run directory's trial log)."""
    best_traj = pipeline.simulator.simulate(result.best_params, seed=seed)
    best_traj.save(run_dir.path / "best_trajectory.npz")
    best_clip = pipeline.renderer.render(best_traj, target.render_params)
    write_video(run_dir.path / "side_by_side.mp4", side_by_side([target.clip, best_clip]))
    plot_refinement(result.trials, result.ground_truth, run_dir.path / "refinement.png", bands=result.posterior or None)
    result.outputs = {
        name: str(run_dir.path / name)
        for name in ("result.json", "trials.jsonl", "refinement.png", "side_by_side.mp4", "best_trajectory.npz")
    }
    atomic_write_json(run_dir.path / "result.json", result.summary())
    write_report_quietly(run_dir.path)  # report.html; a failure only warns


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
