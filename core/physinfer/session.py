"""Glue between the registry and the loop: build a phenomenon's pipeline, load a
target, run a refinement with a progress bar and write its outputs.

The CLI calls these functions; notebooks and benchmarks can call them too.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from physinfer.errors import PhysinferError, UserInputError
from physinfer.locking import exclusive_directory
from physinfer.parameters import (
    ParameterSpace,
    UnknownParameterError,
    parse_float_assignments,
    refuse_repeats,
)
from physinfer.refine import Pipeline, RefineConfig, RefineResult, run_refinement, write_outputs
from physinfer.registry import Registry, accepts_keyword
from physinfer.roles import Target
from physinfer.rundir import TARGET_FILE, RunDirectory, TrialRecord
from physinfer.scene import bind_scene, resolve_scene, scene_of


def build_pipeline(
    registry: Registry,
    plugin: str,
    *,
    effects: Sequence[str] = (),
    embedder: str | None = None,
    weights: Path | None = None,
    device: str | None = None,
    fixed: Sequence[str] = (),
    duration_s: float | None = None,
    embedder_frames: int | None = None,
    scene_set: Mapping[str, Any] | None = None,
) -> Pipeline:
    """Build simulator (with effects), renderer and embedder of a phenomenon.

    Args:
        registry: Loaded plugin registry.
        plugin: Phenomenon name.
        effects: Effect names to switch in.
        embedder: Embedder name, ``None`` for the phenomenon's default; ``""`` for none.
        weights: Embedder weights file (``None``: the shipped default).
        device: torch device for the embedder.
        fixed: ``NAME=VALUE`` items (patterns allowed) held fixed and left out of θ (see
            :mod:`physinfer.fixed`).
        duration_s: Seconds every simulation records (``None``: the phenomenon's default);
            for phenomena whose ``make_simulator`` takes ``duration_s``.
        embedder_frames: Frames the embedder reads (``None``: its default); for embedders
            whose factory takes ``n_frames`` (parameter-free ones; an SDN's are in its weights).
        scene_set: Known scene settings by name (``--scene-set``, strings or values; see
            :mod:`physinfer.scene`); ``None``: the phenomenon's default scene. The pipeline's
            ``phenomenon`` is bound to the validated scene (:func:`physinfer.scene.scene_of`).

    Raises:
        UserInputError: a duration the phenomenon cannot record, frames the embedder
            cannot be told, a device this machine lacks, an effect given twice, or a
            scene setting that is unknown or out of range.
    """
    from physinfer.devices import check_device
    from physinfer.fixed import FixedParameters, resolve_fixed

    device = check_device(device)  # refused here, not ignored by an embedder that needs none
    refuse_repeats(effects, "--effect")
    phenomenon = registry.phenomenon(plugin)
    if scene_set:
        phenomenon = bind_scene(phenomenon, resolve_scene(phenomenon, scene_set))
    effect_objs = [registry.effect(name, phenomenon=phenomenon.name) for name in effects]
    simulator = make_simulator(phenomenon, effect_objs, duration_s)
    if fixed:
        with naming_effects(registry, phenomenon.name, effects, "--fix"):
            simulator = FixedParameters(simulator, resolve_fixed(simulator.parameter_space, fixed))
    renderer = phenomenon.make_renderer()
    embedder_obj: Any = None
    if embedder != "":
        name = embedder or phenomenon.default_embedder
        options: dict[str, Any] = {"model": str(weights) if weights else None, "device": device}
        if embedder_frames is not None:
            if not accepts_keyword(registry.get("embedders", name).load(), "n_frames"):
                raise UserInputError(
                    f"--embedder-frames: the embedder {name!r} reads a fixed number of frames (an SDN's "
                    "are set by its weights); use it with a parameter-free embedder such as 'spectral'"
                )
            options["n_frames"] = embedder_frames
        embedder_obj = registry.embedder(name, **options)
    return Pipeline(phenomenon, simulator, renderer, embedder_obj, effect_objs)


class EffectParameterError(UserInputError):
    """A parameter of one of the phenomenon's effects, given while that effect is not switched in.

    Attributes:
        name: The parameter (or pattern) as given.
        option: The option it was given to (``--set``, ``--fix``, ``--truth``).
        effect: The effect it belongs to.
    """

    def __init__(self, name: str, option: str, effect: str) -> None:
        super().__init__(f"{name} (in {option}) belongs to the effect {effect}: add --effect {effect}")
        self.name, self.option, self.effect = name, option, effect

    def __reduce__(self) -> tuple:  # pickled across worker processes
        return (type(self), (self.name, self.option, self.effect))


@contextmanager
def naming_effects(registry: Registry, phenomenon: str, effects: Sequence[str], option: str) -> Iterator[None]:
    """Turn "unknown parameter" into the effect to switch in, when the name is an effect's.

    The effects' parameter spaces are built only when a name is unknown, so a correct
    command pays nothing for the hint.

    Raises:
        EffectParameterError: a parameter of an effect of ``phenomenon`` not in ``effects``.
    """
    try:
        yield
    except UnknownParameterError as exc:
        owners = effect_parameters(registry, phenomenon, effects)
        matches = fnmatch.filter(owners, exc.name)
        if not matches:
            raise
        raise EffectParameterError(exc.name, option, owners[matches[0]]) from None


def effect_parameters(registry: Registry, phenomenon: str, effects: Sequence[str] = ()) -> dict[str, str]:
    """Parameter name → effect, for the effects of ``phenomenon`` that are not in ``effects``."""
    owners: dict[str, str] = {}
    for name in registry.effects_of(phenomenon):
        if name in effects:
            continue
        try:
            space = registry.effect(name, phenomenon=phenomenon).parameter_space
        except PhysinferError:  # a broken plugin gives no hint; its own error shows elsewhere
            continue
        for spec in space:
            owners.setdefault(spec.name, name)
    return owners


def make_simulator(phenomenon: Any, effects: Sequence[Any], duration_s: float | None = None) -> Any:
    """The phenomenon's simulator with ``effects``, recording ``duration_s`` seconds when given.

    Raises:
        UserInputError: a duration that is not positive, or one the phenomenon cannot record.
    """
    if duration_s is None:
        return phenomenon.make_simulator(effects)
    if not duration_s > 0:
        raise UserInputError(f"--duration must be positive seconds, got {duration_s:g}")
    if not accepts_keyword(phenomenon.make_simulator, "duration_s"):
        raise UserInputError(
            f"--duration: the phenomenon {phenomenon.name!r} records a fixed length (its make_simulator "
            "takes no duration_s); drop --duration"
        )
    return phenomenon.make_simulator(effects, duration_s=duration_s)


def optional_settings(
    fixed: Mapping[str, float], duration_s: float | None, embedder_frames: int | None
) -> dict[str, Any]:
    """The ``run.json`` (and ``model.json``) entries of ``--fix``, ``--duration`` and
    ``--embedder-frames``: only those set.

    All are resume keys; leaving an unset one out keeps runs made before the option existed
    resumable.
    """
    settings: dict[str, Any] = {}
    if fixed:
        settings["fixed"] = dict(fixed)
    if duration_s is not None:
        settings["duration_s"] = duration_s
    if embedder_frames is not None:
        settings["embedder_frames"] = embedder_frames
    return settings


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


def fixed_by_user(pipeline: Pipeline, fixed: Sequence[str]) -> dict[str, float]:
    """The values ``--fix`` (``fixed``, its items) holds in ``pipeline``; ``{}`` without it.

    Only the wrapper ``--fix`` adds counts: a phenomenon whose own simulator holds some
    parameters fixed (the diagnose benchmark's ``flag_lite``) has not had them fixed by the user.
    """
    from physinfer.fixed import split_fixed

    return split_fixed(pipeline.simulator)[1] if fixed else {}


def full_parameter_space(pipeline: Pipeline, fixed: Sequence[str]) -> ParameterSpace:
    """Every parameter of the pipeline's model, those ``--fix`` (``fixed``, its items) holds included.

    Only ``--fix``'s wrapper is looked through: parameters a phenomenon's own simulator
    holds fixed (the diagnose benchmark's ``flag_lite``) are not part of its model, so
    they are neither in a model file nor accepted by ``--truth``.
    """
    from physinfer.fixed import split_fixed

    return (split_fixed(pipeline.simulator)[0] if fixed else pipeline.simulator).parameter_space


def load_target(
    pipeline: Pipeline,
    target_path: Path | None,
    *,
    fps: float | None,
    truth: Sequence[str],
    render_set: Mapping[str, Any],
    fixed: Sequence[str] = (),
) -> Target:
    """The user's video (with ``--truth`` and ζ) or the phenomenon's embedded target.

    ``fixed``: ``--fix``'s items (their parameters may have a ``--truth`` too).
    """
    truth_values = parse_float_assignments(truth, "--truth")
    space = full_parameter_space(pipeline, fixed)
    for name in truth_values:
        space[name]  # unknown names fail with the list of known ones
    if target_path is None:
        target = pipeline.phenomenon.default_target()
        zeta = pipeline.renderer.check_render_params({**target.render_params, **render_set})
        merged_truth = {**(target.truth or {}), **truth_values}
        return Target(target.clip, merged_truth or None, zeta, target.description)
    from physinfer.video import read_target_video

    zeta = pipeline.renderer.check_render_params({**pipeline.renderer.default_render_params, **render_set})
    clip = read_target_video(target_path, fps=fps)
    return Target(clip, truth_values or None, zeta, str(target_path))


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
        from physinfer.diagnose.model import model_for_refine

        model_file = model_for_refine(model, plugin, effects)
        effects = model_file.effects
        if duration_s is None:  # the clip length the model was fitted on (diagnose --duration)
            duration_s = model_file.extra.get("duration_s")
        if not fixed:  # the values the diagnosis held fixed (diagnose --fix)
            fixed = [f"{name}={value!r}" for name, value in model_file.extra.get("fixed", {}).items()]
    pipeline = build_pipeline(
        registry, plugin, effects=effects, embedder=embedder, weights=weights, device=device, fixed=fixed,
        duration_s=duration_s, embedder_frames=embedder_frames, scene_set=scene_set,
    )  # fmt: skip
    scene = scene_of(pipeline.phenomenon)
    fixed_values = fixed_by_user(pipeline, fixed)
    budget = steps if steps is not None else pipeline.phenomenon.default_steps
    config = RefineConfig(
        steps=budget,
        optimizer=optimizer,
        seed=seed,
        noise_samples=noise_samples,
        seeds_per_trial=seeds_per_trial,
        floor_samples=floor_samples,
        select_top=select_top,
        select_seeds=select_seeds,
        batch_size=batch_size,
    )
    config.validate()
    with naming_effects(registry, plugin, effects, "--truth"):
        target = load_target(pipeline, target_path, fps=fps, truth=truth, render_set=render_set or {}, fixed=fixed)
    amortized, amortized_note = None, None
    if use_posterior:
        from physinfer.posterior.workflow import posterior_for_refinement

        amortized, amortized_note = posterior_for_refinement(
            registry, plugin=plugin, parameter_space=pipeline.simulator.parameter_space, clip=target.clip,
            posterior=posterior, device=device, seed=seed, scene=scene,
        )  # fmt: skip
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
    start_x, post_start = None, None
    if model_file is not None:
        from physinfer.diagnose.warmstart import warm_start_factory

        space = pipeline.simulator.parameter_space
        start = model_file.start_for(full_parameter_space(pipeline, fixed))  # fixed parameters dropped below
        start_x = space.to_unit({name: start[name] for name in space.names})
        factory = warm_start_factory(factory, start_x)
    elif amortized is not None:  # spend the budget where the video points
        from physinfer.diagnose.warmstart import warm_start_factory
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

        if fixed_values:
            result.extra["fixed"] = fixed_values
        if scene is not None:
            result.extra["scene"] = scene
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
