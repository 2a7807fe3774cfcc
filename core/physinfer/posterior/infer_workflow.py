"""The posterior of one video (``physinfer infer``, and the start of a refinement): embed it,
sample the estimator, summarise per parameter, and write ``posterior.json``, ``samples.npz``
and ``corner.png``; the lines printed for it."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.adequacy import predictive_check
from physinfer.conditioning import Conditioning
from physinfer.errors import UserInputError
from physinfer.evaluation import build_pipeline
from physinfer.io import atomic_save_npz, atomic_write_json, check_output_dir
from physinfer.parameters import ParameterSpace
from physinfer.posterior.estimator import PosteriorEstimator
from physinfer.posterior.figures import corner_figure, corner_plot
from physinfer.posterior.inputs import MAX_OUTSIDE_SHARE
from physinfer.posterior.loading import (
    embed_target,
    estimator_embedder,
    load_estimator,
    shipped_for_longer,
    told_passed_over,
)
from physinfer.posterior.summary import correlations, format_marginal, marginals
from physinfer.registry import Registry
from physinfer.report import write_report_quietly
from physinfer.roles import Target
from physinfer.scene import default_scene, resolve_scene
from physinfer.target import load_target
from physinfer.threads import with_refinement_threads


@dataclass
class PosteriorReport:
    """The posterior of one target: marginals, correlations and the samples.

    Attributes:
        marginals: ``{name: {median, ci50, ci90, contraction, label, unit}}``.
        correlations: Strongest pairs ``[{a, b, r}]``.
        samples_unit: ``(S, D)`` samples in normalised coordinates.
        names: ``(D,)`` parameter names.
        estimator: Path of the estimator used.
        truth: Known true values, if any.
        paths: Files written.
        seconds: Time per stage.
        scene: The target's scene settings, when given.
        space: The estimator's parameter space (for :meth:`plot`).
        target_conditions: How a user's video was framed (:mod:`physinfer.conditioning`).
        adequacy: Whether the posterior's median reproduces the video
            (:func:`physinfer.adequacy.predictive_check`), or ``None`` when not checked.
        inputs: How the video's embedding compares with the estimator's training inputs
            (:meth:`PosteriorEstimator.input_check`), or ``None`` (an older estimator).
        degenerate: Why the posterior is degenerate (every sample of a parameter at one
            value), or ``None``.
        notes: What was left out of the results and why (a corner plot not drawn).
        render_set: The render settings the user told (``--render-set``), when given.
    """

    marginals: dict[str, dict[str, Any]]
    correlations: list[dict[str, Any]]
    samples_unit: np.ndarray
    names: list[str]
    estimator: Path
    truth: dict[str, float] | None = None
    paths: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    scene: dict[str, Any] | None = None
    space: ParameterSpace | None = field(default=None, repr=False)
    target_conditions: dict[str, Any] | None = None
    adequacy: dict[str, Any] | None = None
    inputs: dict[str, Any] | None = None
    degenerate: str | None = None
    notes: list[str] = field(default_factory=list)
    render_set: dict[str, Any] | None = None
    nuisance: tuple[str, ...] = ()

    def plot(self, title: str = "") -> Any:
        """The corner plot of the identified parameters and the strongest correlated pair, in
        physical units with the truth marked where known (a matplotlib figure; ``corner.png``)."""
        if self.space is None:
            raise ValueError("this report carries no parameter space to draw in")
        return corner_figure(self, self.space, title=title)

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer infer --json`` prints (and ``posterior.json``)."""
        d: dict[str, Any] = {
            "posterior": self.marginals,
            "correlations": self.correlations,
            "estimator": str(self.estimator),
            "n_samples": int(len(self.samples_unit)),
            "files": self.paths,
            "seconds": self.seconds,
        }
        if self.scene is not None:
            d["scene"] = self.scene
        if self.render_set:
            d["render_set"] = self.render_set
        if self.target_conditions:
            d["target_conditions"] = self.target_conditions
        if self.adequacy is not None:
            d["adequacy"] = self.adequacy
        if self.inputs is not None:
            d["inputs"] = self.inputs
        if self.degenerate is not None:
            d["degenerate"] = self.degenerate
        if self.notes:
            d["notes"] = list(self.notes)
        if self.nuisance:
            d["nuisance"] = list(self.nuisance)
        if self.truth:
            d["truth"] = self.truth
            d["truth_in_ci90"] = {
                name: bool(m["ci90"][0] <= self.truth[name] <= m["ci90"][1])
                for name, m in self.marginals.items()
                if name in self.truth
            }
        return d


def posterior_of_clip(
    estimator: PosteriorEstimator,
    embedder: Any,
    clip: Any,
    *,
    n_samples: int = 5000,
    seed: int = 0,
    scene: Mapping[str, Any] | None = None,
    render: Mapping[str, Any] | None = None,
) -> PosteriorReport:
    """Sample the posterior of one clip and summarise it; ``scene``: the target's complete
    scene, which an estimator trained across scene ranges takes as input; ``render``: the
    render settings the user told, which an estimator told the camera takes (one outside
    its training ranges is reported in ``inputs`` as ``render_outside``, extrapolating)."""
    t0 = time.perf_counter()
    x, inputs = estimator.input_check(estimator.condition(embed_target(estimator, embedder, clip), scene, render))
    if estimator.config.render_inputs and inputs is not None:
        inputs["render_outside"] = estimator.render_outside(render)
        inputs["extrapolating"] = inputs["extrapolating"] or bool(inputs["render_outside"])
    t1 = time.perf_counter()
    samples = estimator.sample_unit(x, n_samples, seed=seed)
    t2 = time.perf_counter()
    space = estimator.parameter_space
    report = PosteriorReport(
        marginals=marginals(samples, space),
        correlations=correlations(samples, space.names),
        samples_unit=samples,
        names=space.names,
        estimator=Path("."),
        seconds={"embed": t1 - t0, "sample": t2 - t1},
        space=space,
        inputs=inputs,
        degenerate=degenerate_reason(samples, space.names),
    )
    return report


def degenerate_reason(samples_unit: np.ndarray, names: Sequence[str]) -> str | None:
    """Why a posterior is degenerate — a parameter whose samples all sit at one value — or
    ``None``. Such a posterior is no measurement: an estimator pushed outside what it was
    trained on can put all its mass in one place (a spring's damping at "0.2987–0.2987")."""
    spread = np.quantile(samples_unit, 0.95, axis=0) - np.quantile(samples_unit, 0.05, axis=0)
    for i, name in enumerate(names):
        if spread[i] < 1e-3:
            return f"every sample of {name} lies at one value (90 % of them within 0.05 % of its range)"
    return None


@with_refinement_threads
def infer(
    registry: Registry,
    *,
    plugin: str,
    out: Path,
    target_path: Path | None = None,
    posterior: Path | None = None,
    fps: float | None = None,
    truth: Sequence[str] = (),
    n_samples: int = 5000,
    seed: int = 0,
    device: str | None = None,
    scene_set: Mapping[str, Any] | None = None,
    conditioning: Conditioning | None = None,
    check: bool = True,
    render_set: Mapping[str, Any] | None = None,
) -> PosteriorReport:
    """The posterior of one video (default: the plugin's embedded target), written to ``out``:
    ``posterior.json``, ``samples.npz`` and ``corner.png``.

    ``check``: simulate the posterior's median and say whether the model reproduces the
    video (``adequacy``, :func:`physinfer.adequacy.predictive_check`; a few simulations).

    ``scene_set``: the target's known scene settings (``--scene-set``); an estimator
    trained on clips of another scene is refused. ``conditioning``: how a ``target_path``
    video is framed (:mod:`physinfer.conditioning`; ζ is not estimated: the amortized
    posterior was trained across ζ); ``None``: used as it is. ``render_set``: the camera and
    light the video was taken with (``--render-set``): an estimator told the camera needs
    them (and the shipped one is chosen when they are given), the predictive check renders
    with them.

    Raises:
        UserInputError: a mismatched or damaged estimator (another scene included), a
            target too short for it, an unreadable video.
    """
    if n_samples < 100:
        raise UserInputError(
            f"--samples {n_samples}: at least 100 samples are needed for intervals"
        )
    out = Path(out)
    check_output_dir(out)
    t_start = time.perf_counter()
    loaded = _load_estimator(registry, plugin, posterior, device, scene_set, render_set)
    if conditioning is not None:
        conditioning = replace(conditioning, estimate_render=False)
    target = load_target(  # checks the render settings' names and values against the renderer
        loaded.pipeline, target_path, fps=fps, truth=truth, render_set=render_set or {}, conditioning=conditioning
    )  # fmt: skip
    told = {name: target.render_params[name] for name in render_set or {}}  # as the renderer types them
    if posterior is None:  # a longer video may have a shipped estimator of longer clips
        loaded = _for_target_length(registry, plugin, loaded, device, scene_set, render_set, target.clip.duration)
    t_ready = time.perf_counter()
    report = posterior_of_clip(
        loaded.estimator, loaded.pipeline.embedder, target.clip, n_samples=n_samples, seed=seed,
        scene=loaded.scene or default_scene(loaded.phenomenon), render=told,
    )  # fmt: skip
    if check:
        _check_adequacy(report, registry, plugin, loaded, target, device, seed)
    report.estimator = loaded.path
    report.truth = dict(target.truth) if target.truth else None
    report.scene = loaded.scene
    report.render_set = told or None
    report.nuisance = tuple(getattr(loaded.phenomenon, "nuisance", ()) or ())
    if told and posterior is None and not loaded.estimator.config.render_inputs:
        report.notes += [
            f"the camera told was not used by {why}" for why in told_passed_over(registry, plugin, loaded.scene, told)
        ]
    report.target_conditions = target.conditions
    report.seconds["start_up"] = t_ready - t_start
    write_report(report, loaded.estimator, out, title=target.description)
    loaded.pipeline.renderer.close()
    return report


@dataclass(frozen=True)
class _LoadedEstimator:
    """The estimator ``infer`` samples, with what was resolved on the way to it.

    Attributes:
        phenomenon: The plugin's phenomenon.
        scene: The target's complete scene (``None``: the phenomenon has no scene settings).
        estimator: The estimator, checked against that scene.
        path: Where it was loaded from.
        pipeline: The pipeline of the embedder it was trained with.
    """

    phenomenon: Any
    scene: dict[str, Any] | None
    estimator: PosteriorEstimator
    path: Path
    pipeline: Any


def _load_estimator(
    registry: Registry,
    plugin: str,
    posterior: Path | None,
    device: str | None,
    scene_set: Mapping[str, Any] | None,
    render_set: Mapping[str, Any] | None = None,
) -> _LoadedEstimator:
    """Resolve the scene, load the estimator (the shipped one told the camera when
    ``render_set`` tells it), check its scene and rebuild its embedder."""
    phenomenon = registry.phenomenon(plugin)
    scene = resolve_scene(phenomenon, scene_set)  # a typo is refused before the estimator loads
    estimator, path = load_estimator(registry, plugin, posterior, device, scene=scene, render=render_set)
    estimator.check_scene(phenomenon, scene, path)
    pipeline = estimator_embedder(registry, estimator, device)
    return _LoadedEstimator(phenomenon, scene, estimator, path, pipeline)


def _for_target_length(
    registry: Registry,
    plugin: str,
    loaded: _LoadedEstimator,
    device: str | None,
    scene_set: Mapping[str, Any] | None,
    render_set: Mapping[str, Any] | None,
    seconds: float,
) -> _LoadedEstimator:
    """The shipped estimator for a target of ``seconds`` (the longest clips it covers), or
    ``loaded``. The target was framed for ``loaded``'s embedder: only one of the same
    embedder and rate (reading more frames) is taken."""
    if not shipped_for_longer(loaded.phenomenon, loaded.estimator.config.clip_seconds, seconds):
        return loaded  # the usual case: nothing to reload
    estimator, path = load_estimator(registry, plugin, None, device, scene=loaded.scene, render=render_set, seconds=seconds)
    now, longer = loaded.estimator.config, estimator.config
    if path == loaded.path or (longer.embedder, longer.embedder_fps) != (now.embedder, now.embedder_fps):
        return loaded
    loaded.pipeline.renderer.close()
    return _load_estimator(registry, plugin, path, device, scene_set, render_set)


def _check_adequacy(
    report: PosteriorReport,
    registry: Registry,
    plugin: str,
    loaded: _LoadedEstimator,
    target: Target,
    device: str | None,
    seed: int,
) -> None:
    """Simulate the posterior's median and set ``report.adequacy`` (and its time in ``seconds``)."""
    median = report.space.from_unit(np.median(report.samples_unit, axis=0))
    config = loaded.estimator.config
    checked = loaded.pipeline if not loaded.scene else build_pipeline(
        registry, plugin, embedder=config.embedder, embedder_frames=config.frames_option,
        weights=Path(config.weights) if config.weights else None, device=device, scene_set=loaded.scene,
    )  # fmt: skip
    t_check = time.perf_counter()
    report.adequacy = predictive_check(checked, median, target, seed)
    report.seconds["check"] = time.perf_counter() - t_check


def write_report(
    report: PosteriorReport, estimator: PosteriorEstimator, out: Path, *, title: str = ""
) -> None:
    """``posterior.json``, ``samples.npz`` (physical and normalised) and ``corner.png`` in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    space = estimator.parameter_space
    physical = np.stack(
        [spec.from_unit(report.samples_unit[:, i]) for i, spec in enumerate(space)], axis=1
    )
    atomic_save_npz(
        out / "samples.npz",
        names=np.array(report.names),
        samples=physical,
        samples_unit=report.samples_unit,
    )
    report.paths["samples"] = str(out / "samples.npz")
    if report.degenerate is None:
        try:
            report.paths["corner"] = str(corner_plot(report, space, out / "corner.png", title=title))
        except (ValueError, MemoryError) as exc:  # a plot never costs the answer
            report.notes.append(f"corner plot skipped: it could not be drawn ({exc})")
    else:
        report.notes.append(f"corner plot skipped: the posterior is degenerate ({report.degenerate})")
    report.paths["posterior"] = str(out / "posterior.json")
    atomic_write_json(out / "posterior.json", report.to_dict())
    write_report_quietly(out)  # report.html; a failure only warns


def _first_clause(exc: Exception) -> str:
    """The reason of a refusal, without its remedy: a :class:`UserInputError`'s ``reason``
    where it keeps the remedy apart, else the message up to its first semicolon."""
    remedy = getattr(exc, "remedy", None)
    return str(getattr(exc, "reason", "")) if remedy else str(exc).split("; ")[0]


def trust_lines(report: PosteriorReport) -> list[str]:
    """Printed before the intervals when they should not be trusted: a degenerate
    posterior, a video whose embedding lies outside the estimator's training inputs."""
    lines = []
    if report.degenerate:
        lines.append(
            f"degenerate posterior: {report.degenerate}; the estimator was not trained on videos like this "
            "one: measure it with `physinfer refine --no-posterior`, or train on clips like it"
        )
    inputs = report.inputs or {}
    render_outside = inputs.get("render_outside") or []
    if render_outside:
        lines.append(
            f"warning: the camera told with --render-set lies outside the estimator's training clips "
            f"({'; '.join(render_outside)}): the intervals are extrapolated, not calibrated for it"
        )
    if inputs.get("extrapolating") and (not render_outside or inputs["outside"] > MAX_OUTSIDE_SHARE * inputs["dimensions"]):
        lines.append(
            f"warning: the video's embedding lies outside the estimator's training clips in {inputs['outside']} "
            f"of {inputs['dimensions']} inputs (up to {inputs['worst_sd']:g} training SDs): the intervals are "
            "extrapolated, not calibrated for it"
        )
    if inputs.get("held"):
        lines.append(
            f"note: {inputs['held']} inputs the training clips never varied were held at their training value"
        )
    return lines + [f"note: {n}" for n in report.notes]


def summary_lines(marginals_: Mapping[str, Mapping[str, Any]], nuisance: Sequence[str] = ()) -> list[str]:
    """Printed lines: one per identified or weakly identified parameter, then one line
    naming every parameter the video does not determine (their numbers are in the JSON), then
    the ``nuisance`` parameters on a line of their own: what the video leaves open and the
    physics does not care about (a pendulum's phase) is no measurement, identified or not."""
    measured = {name: m for name, m in marginals_.items() if name not in nuisance}
    return _measured_lines(measured) + [
        f"  nuisance (what the video leaves open, not a measurement): {_nuisance_text(name, marginals_[name])}"
        for name in nuisance
        if name in marginals_
    ]


def _nuisance_text(name: str, m: Mapping[str, Any]) -> str:
    unit = f" {m['unit']}" if m.get("unit") else ""
    lo, hi = m["ci90"]
    return f"{name} = {m['median']:.3g}{unit} [90 %: {lo:.3g} – {hi:.3g}]"


def _measured_lines(marginals_: Mapping[str, Mapping[str, Any]]) -> list[str]:
    shown = [
        format_marginal(name, m) for name, m in marginals_.items() if m["label"] == "identified"
    ]
    shown += [
        format_marginal(name, m)
        for name, m in marginals_.items()
        if m["label"] == "weakly identified"
    ]
    rest = [name for name, m in marginals_.items() if m["label"] == "not identified"]
    if rest:
        shown.append(f"  not identified (the video barely narrows their ranges): {', '.join(rest)}")
    return shown


def posterior_for_refinement(
    registry: Registry,
    *,
    plugin: str,
    parameter_space: Any,
    clip: Any,
    posterior: Path | None,
    device: str | None = None,
    seed: int = 0,
    n_samples: int = 5000,
    scene: Mapping[str, Any] | None = None,
    render: Mapping[str, Any] | None = None,
) -> tuple[PosteriorReport | None, str | None]:
    """The amortized posterior of a refinement's target, or why there is none.

    With ``posterior`` given, any mismatch (another plugin, parameter space, embedder, a
    target shorter than its clips) is the user's error. Without it, the phenomenon's shipped
    estimator is used when it applies; when it does not (effects switched in, parameters
    held by ``--fix``, a short target, another ``scene`` than its training clips') the
    refinement goes on without it and the reason is returned instead; so it does, given or
    shipped, when the posterior of this clip is degenerate or extrapolated (a search started
    there starts in the wrong place). ``scene``: the
    complete scene (:func:`physinfer.scene.resolve_scene`), ``None`` for the default.
    ``render``: the render settings the user told (``--render-set``, typed), which choose and
    condition an estimator told the camera, as ``infer``'s do.

    Returns:
        ``(report, None)``, or ``(None, reason)`` (``reason`` is ``None`` when the
        phenomenon ships no estimator).
    """
    phenomenon = registry.phenomenon(plugin)
    if posterior is None and getattr(phenomenon, "default_posterior", None) is None:
        return None, None
    try:
        estimator, path = load_estimator(
            registry, plugin, posterior, device, scene=scene, render=render, seconds=clip.duration
        )  # fmt: skip
        estimator.check_for(plugin, parameter_space, path)
        estimator.check_scene(phenomenon, scene, path)
        pipeline = estimator_embedder(registry, estimator, device)
        report = posterior_of_clip(
            estimator,
            pipeline.embedder,
            clip,
            n_samples=n_samples,
            seed=seed,
            scene=scene or default_scene(phenomenon),
            render=render,
        )
        pipeline.renderer.close()
    except UserInputError as exc:
        if posterior is not None:
            raise
        return None, f"searching without a posterior: the plugin's estimator does not apply ({_first_clause(exc)})"
    report.estimator = path
    distrust = _distrust(report)
    if distrust is not None:  # a search started from it would start in the wrong place
        return None, f"searching without a posterior: {distrust}"
    return report, None


def _distrust(report: PosteriorReport) -> str | None:
    """Why a refinement should not start from ``report`` (degenerate, or the video outside
    what the estimator was trained on), or ``None``."""
    if report.degenerate:
        return f"the estimator's posterior of this video is degenerate ({report.degenerate})"
    inputs = report.inputs or {}
    if inputs.get("extrapolating"):
        return (
            f"the video's embedding lies outside the estimator's training clips in {inputs['outside']} of "
            f"{inputs['dimensions']} inputs"
        )
    return None
