"""Posterior workflows over the roles: train an estimator on a dataset, infer the
posterior of one video, and check calibration on held-out simulations.

Each returns a result object with the numbers, the files it wrote and ``to_dict()`` (the
JSON the CLI prints). Progress goes to an injected ``progress(stage, done, total)``
callback; nothing here prints.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.conditioning import Conditioning
from physinfer.errors import UserInputError
from physinfer.io import atomic_save_npz, atomic_write_json, check_output_dir
from physinfer.parameters import ParameterSpace
from physinfer.posterior.estimator import (
    NetworkConfig,
    PosteriorEstimator,
    embedder_probe,
    resolve_device,
)
from physinfer.posterior.summary import correlations, marginals
from physinfer.registry import Registry

#: ``progress(stage, done, total)``.
ProgressFn = Callable[[str, int, int], None]


def _no_progress(stage: str, done: int, total: int) -> None:
    pass


# ------------------------------------------------------------------------------ train


@dataclass
class TrainResult:
    """A trained estimator and where it was written."""

    estimator: PosteriorEstimator
    path: Path
    cache: Path
    seconds: dict[str, float]

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer posterior train --json`` prints."""
        c = self.estimator.config
        return {
            "estimator": str(self.path),
            "plugin": c.plugin,
            "embedder": c.embedder,
            "embedder_frames": c.embedder_frames,
            "clip_seconds": c.clip_seconds,
            "parameters": [p["name"] for p in c.parameters],
            "training": c.training,
            "scene": c.scene,
            "embeddings_cache": str(self.cache),
            "seconds": self.seconds,
        }


def build_embedder(
    registry: Registry,
    plugin: str,
    *,
    embedder: str | None,
    embedder_frames: int | None,
    weights: Path | None,
    device: str | None,
) -> Any:
    """The pipeline (simulator, renderer, embedder) of ``plugin`` with the chosen embedder."""
    from physinfer.pipeline import build_pipeline

    return build_pipeline(
        registry, plugin, embedder=embedder, weights=weights, device=device, embedder_frames=embedder_frames
    )


def train_posterior(
    registry: Registry,
    *,
    plugin: str,
    data: Path,
    out: Path,
    embedder: str | None = None,
    embedder_frames: int | None = None,
    weights: Path | None = None,
    device: str | None = None,
    split: str = "train",
    network: NetworkConfig | None = None,
    seed: int = 0,
    progress: ProgressFn = _no_progress,
) -> TrainResult:
    """Embed a dataset's clips (cached beside it) and train q(θ | s(x)) with sbi's NPE.

    Raises:
        UserInputError: a dataset of another phenomenon or without θ, clips shorter than
            the embedder reads, or too few clips.
    """
    from physinfer.datasets.loader import ClipDataset
    from physinfer.posterior.features import embed_dataset
    from physinfer.posterior.training import train_estimator
    network = network or NetworkConfig()
    network.validate()  # before the slow embedding
    out = _estimator_path(out)
    dataset = ClipDataset(data, split)
    _check_dataset(dataset, plugin)
    pipeline = build_embedder(
        registry, plugin, embedder=embedder, embedder_frames=embedder_frames, weights=weights, device=device
    )
    emb = pipeline.embedder
    name = embedder or pipeline.phenomenon.default_embedder
    clip_seconds = dataset.clip_format.n_frames / dataset.clip_format.fps
    if clip_seconds + 1e-9 < emb.n_frames / emb.fps:
        raise UserInputError(
            f"the clips of {data} last {clip_seconds:.2f} s but the embedder {name!r} reads "
            f"{emb.n_frames} frames at {emb.fps:g} fps ({emb.n_frames / emb.fps:.2f} s); generate longer "
            "clips (dataset generate --frames N) or lower --embedder-frames"
        )
    probe = embedder_probe(emb)
    identity = {
        "plugin": plugin,
        "embedder": name,
        "embedder_frames": int(emb.n_frames),
        "embedder_fps": float(emb.fps),
        "frames_option": embedder_frames,
        "weights": str(weights) if weights else None,
        "probe": [float(v) for v in probe],
        "clip_seconds": float(clip_seconds),
    }
    t0 = time.perf_counter()
    pairs = embed_dataset(
        data,
        split,
        emb,
        {k: identity[k] for k in ("embedder", "embedder_frames", "embedder_fps", "probe")},
        on_progress=lambda done, total: progress("embedding", done, total),
    )
    t1 = time.perf_counter()
    estimator = train_estimator(
        pairs,
        identity,
        network=network,
        seed=seed,
        device=resolve_device(device),
        on_epoch=lambda done, total, best: progress("training", done, total),
    )
    estimator.config.training.update(dataset=str(Path(data).resolve().name), split=split)
    scene = dataset.info.get("config", {}).get("scene")
    if scene is not None:  # the clips' scene: targets of another one get no intervals from it
        estimator.config = replace(estimator.config, scene=dict(scene))
    t2 = time.perf_counter()
    estimator.save(out)
    pipeline.renderer.close()
    return TrainResult(estimator, out, pairs.cache, {"embed": t1 - t0, "train": t2 - t1})


def _estimator_path(out: Path) -> Path:
    out = Path(out)
    if out.suffix != ".safetensors":
        raise UserInputError(f"--out {out}: name the estimator file *.safetensors")
    if out.is_dir():
        raise UserInputError(f"--out {out} is a directory; give a file name ending in .safetensors")
    check_output_dir(out.parent)  # before the slow embedding
    return out


def _check_dataset(dataset: Any, plugin: str) -> None:
    made_for = dataset.info.get("config", {}).get("phenomenon")
    if made_for not in (None, plugin):
        raise UserInputError(
            f"{dataset.root} was generated for --plugin {made_for}, not {plugin}; pass --plugin {made_for}"
        )
    if not dataset.param_names:
        raise UserInputError(f"{dataset.root} stores no parameters θ: a posterior needs them")


# ------------------------------------------------------------------------------ infer


def load_estimator(
    registry: Registry, plugin: str, path: Path | None, device: str | None = None
) -> tuple[PosteriorEstimator, Path]:
    """The estimator at ``path`` or the phenomenon's shipped one, checked against ``plugin``.

    Raises:
        UserInputError: no estimator given and none shipped, or one made for another
            phenomenon or parameter space.
    """
    phenomenon = registry.phenomenon(plugin)
    if path is None:
        shipped = getattr(phenomenon, "default_posterior", None)
        if shipped is None or not Path(shipped).is_file():
            raise UserInputError(
                f"the plugin {plugin!r} ships no posterior estimator; train one with `physinfer posterior "
                f"train --plugin {plugin} --data DATASET --out FILE.safetensors` and pass --posterior FILE"
            )
        path = Path(shipped)
    estimator = PosteriorEstimator.load(path, device=resolve_device(device))
    estimator.check_for(plugin, phenomenon.parameter_space, path)
    return estimator, Path(path)


def estimator_embedder(registry: Registry, estimator: PosteriorEstimator, device: str | None) -> Any:
    """The embedder ``estimator`` was trained with, rebuilt and fingerprint-checked."""
    c = estimator.config
    pipeline = build_embedder(
        registry,
        c.plugin,
        embedder=c.embedder,
        embedder_frames=c.frames_option,
        weights=Path(c.weights) if c.weights else None,
        device=device,
    )
    estimator.check_embedder(pipeline.embedder)
    return pipeline


def embed_target(estimator: PosteriorEstimator, embedder: Any, clip: Any) -> np.ndarray:
    """``(E,)`` the target's embedding by the estimator's embedder, with a clear error when
    the target is shorter than the clips the estimator was trained on."""
    c = estimator.config
    if clip.duration + 1e-6 < c.embedder_frames / c.embedder_fps:
        raise UserInputError(
            f"the target lasts {clip.duration:.2f} s but the posterior estimator reads {c.embedder_frames} "
            f"frames at {c.embedder_fps:g} fps ({c.embedder_frames / c.embedder_fps:.2f} s); use a longer "
            "video, or an estimator trained on shorter clips"
        )
    x = np.asarray(embedder.embed(clip), dtype=np.float32)
    if not np.isfinite(x).all():
        raise UserInputError(
            "the target's embedding is not finite (NaN or inf): the video may be blank or damaged"
        )
    return x


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

    def plot(self, title: str = "") -> Any:
        """The corner plot of the identified parameters and the strongest correlated pair, in
        physical units with the truth marked where known (a matplotlib figure; ``corner.png``)."""
        from physinfer.posterior.figures import corner_figure

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
        if self.target_conditions:
            d["target_conditions"] = self.target_conditions
        if self.truth:
            d["truth"] = self.truth
            d["truth_in_ci90"] = {
                name: bool(m["ci90"][0] <= self.truth[name] <= m["ci90"][1])
                for name, m in self.marginals.items()
                if name in self.truth
            }
        return d


def posterior_of_clip(
    estimator: PosteriorEstimator, embedder: Any, clip: Any, *, n_samples: int = 5000, seed: int = 0
) -> PosteriorReport:
    """Sample the posterior of one clip and summarise it."""
    t0 = time.perf_counter()
    x = embed_target(estimator, embedder, clip)
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
    )
    return report


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
) -> PosteriorReport:
    """The posterior of one video (default: the plugin's embedded target), written to ``out``:
    ``posterior.json``, ``samples.npz`` and ``corner.png``.

    ``scene_set``: the target's known scene settings (``--scene-set``); an estimator
    trained on clips of another scene is refused. ``conditioning``: how a ``target_path``
    video is framed (:mod:`physinfer.conditioning`; ζ is not estimated: the amortized
    posterior was trained across ζ); ``None``: used as it is.

    Raises:
        UserInputError: a mismatched or damaged estimator (another scene included), a
            target too short for it, an unreadable video.
    """
    from physinfer.pipeline import load_target

    if n_samples < 100:
        raise UserInputError(f"--samples {n_samples}: at least 100 samples are needed for intervals")
    out = Path(out)
    check_output_dir(out)
    t_start = time.perf_counter()
    from physinfer.scene import resolve_scene

    phenomenon = registry.phenomenon(plugin)
    scene = resolve_scene(phenomenon, scene_set)  # a typo is refused before the estimator loads
    estimator, path = load_estimator(registry, plugin, posterior, device)
    estimator.check_scene(phenomenon, scene, path)
    pipeline = estimator_embedder(registry, estimator, device)
    if conditioning is not None:
        conditioning = replace(conditioning, estimate_render=False)
    target = load_target(pipeline, target_path, fps=fps, truth=truth, render_set={}, conditioning=conditioning)
    t_ready = time.perf_counter()
    report = posterior_of_clip(estimator, pipeline.embedder, target.clip, n_samples=n_samples, seed=seed)
    report.estimator = path
    report.truth = dict(target.truth) if target.truth else None
    report.scene = scene
    report.target_conditions = target.conditions
    report.seconds["start_up"] = t_ready - t_start
    write_report(report, estimator, out, title=target.description)
    pipeline.renderer.close()
    return report


def write_report(report: PosteriorReport, estimator: PosteriorEstimator, out: Path, *, title: str = "") -> None:
    """``posterior.json``, ``samples.npz`` (physical and normalised) and ``corner.png`` in ``out``."""
    from physinfer.posterior.figures import corner_plot

    out.mkdir(parents=True, exist_ok=True)
    space = estimator.parameter_space
    physical = np.stack([spec.from_unit(report.samples_unit[:, i]) for i, spec in enumerate(space)], axis=1)
    atomic_save_npz(
        out / "samples.npz", names=np.array(report.names), samples=physical, samples_unit=report.samples_unit
    )
    report.paths["samples"] = str(out / "samples.npz")
    report.paths["corner"] = str(corner_plot(report, space, out / "corner.png", title=title))
    report.paths["posterior"] = str(out / "posterior.json")
    atomic_write_json(out / "posterior.json", report.to_dict())
    from physinfer.report import write_report_quietly  # report.html; a failure only warns

    write_report_quietly(out)


# ------------------------------------------------------------------------- calibrate


@dataclass
class CalibrationReport:
    """Simulation-based calibration of an estimator on a dataset split."""

    calibration: Any
    estimator: Path
    data: Path
    split: str
    median_abs_error: dict[str, float]
    contraction: dict[str, float]
    paths: dict[str, str] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer evaluate calibration --json`` prints."""
        d = self.calibration.to_dict()
        for name, row in d["parameters"].items():
            row["median_abs_error"] = self.median_abs_error[name]
            row["mean_contraction"] = self.contraction[name]
        d.update(estimator=str(self.estimator), data=str(self.data), split=self.split)
        d.update(files=self.paths, seconds=self.seconds)
        return d


def evaluate_calibration(
    registry: Registry,
    *,
    plugin: str,
    data: Path,
    out: Path,
    posterior: Path | None = None,
    split: str = "test",
    n_samples: int = 1000,
    seed: int = 0,
    device: str | None = None,
    progress: ProgressFn = _no_progress,
) -> CalibrationReport:
    """Ranks, expected coverage, posterior-median errors and contraction on held-out clips.

    The held-out clips are embedded with the estimator's own embedder (cached beside the
    dataset like the training clips).
    """
    from physinfer.datasets.loader import ClipDataset
    from physinfer.posterior.calibration import calibrate, plot_calibration
    from physinfer.posterior.features import embed_dataset
    from physinfer.posterior.summary import PRIOR_VARIANCE

    if n_samples < 50:
        raise UserInputError(f"--samples {n_samples}: at least 50 posterior samples per simulation are needed")
    out = Path(out)
    check_output_dir(out)
    t0 = time.perf_counter()
    estimator, path = load_estimator(registry, plugin, posterior, device)
    dataset = ClipDataset(data, split)
    _check_dataset(dataset, plugin)
    if dataset.parameter_space.to_dict() != estimator.parameter_space.to_dict():
        raise UserInputError(
            f"{data} was drawn from another parameter space than the estimator's; calibrate on a dataset "
            "of the same model"
        )
    pipeline = estimator_embedder(registry, estimator, device)
    c = estimator.config
    pairs = embed_dataset(
        data,
        split,
        pipeline.embedder,
        {"embedder": c.embedder, "embedder_frames": c.embedder_frames, "embedder_fps": c.embedder_fps, "probe": c.probe},
        on_progress=lambda done, total: progress("embedding", done, total),
    )
    t1 = time.perf_counter()
    names = estimator.parameter_space.names
    medians = np.empty_like(pairs.theta_unit, dtype=np.float64)
    variances = np.empty_like(medians)

    def sampler(xs: np.ndarray, n: int, batch_seed: int) -> np.ndarray:
        samples = estimator.sample_unit_batched(xs, n, seed=batch_seed)
        return samples

    cal = calibrate(
        pairs.theta_unit.astype(np.float64),
        pairs.x,
        _recording(sampler, medians, variances),
        names,
        n_samples=n_samples,
        seed=seed,
        on_progress=lambda done, total: progress("sampling", done, total),
    )
    t2 = time.perf_counter()
    space = estimator.parameter_space
    truth = pairs.theta
    med_phys = np.stack([spec.from_unit(medians[:, i]) for i, spec in enumerate(space)], axis=1)
    report = CalibrationReport(
        calibration=cal,
        estimator=path,
        data=Path(data),
        split=split,
        median_abs_error={n: float(np.median(np.abs(med_phys[:, i] - truth[:, i]))) for i, n in enumerate(names)},
        contraction={n: float(np.mean(1 - variances[:, i] / PRIOR_VARIANCE)) for i, n in enumerate(names)},
        seconds={"embed": t1 - t0, "calibrate": t2 - t1},
    )
    out.mkdir(parents=True, exist_ok=True)
    report.paths["plot"] = str(plot_calibration(cal, out / "calibration.png", title=f"{plugin}: {Path(data).name} ({split})"))
    report.paths["report"] = str(out / "calibration.json")
    atomic_write_json(out / "calibration.json", report.to_dict())
    pipeline.renderer.close()
    return report


def _recording(
    sampler: Callable[[np.ndarray, int, int], np.ndarray], medians: np.ndarray, variances: np.ndarray
) -> Callable[[np.ndarray, int, int], np.ndarray]:
    """Wrap ``sampler`` to keep each pair's posterior median and variance as batches pass."""
    state = {"start": 0}

    def wrapped(xs: np.ndarray, n: int, seed: int) -> np.ndarray:
        samples = sampler(xs, n, seed)
        start, stop = state["start"], state["start"] + len(xs)
        medians[start:stop] = np.median(samples, axis=0)
        variances[start:stop] = samples.var(axis=0)
        state["start"] = stop
        return samples

    return wrapped


def summary_lines(marginals_: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Printed lines: one per identified or weakly identified parameter, then one line
    naming every parameter the video does not determine (their numbers are in the JSON)."""
    from physinfer.posterior.summary import format_marginal

    shown = [format_marginal(name, m) for name, m in marginals_.items() if m["label"] == "identified"]
    shown += [format_marginal(name, m) for name, m in marginals_.items() if m["label"] == "weakly identified"]
    rest = [name for name, m in marginals_.items() if m["label"] == "not identified"]
    if rest:
        shown.append(f"  not identified (the video barely narrows their ranges): {', '.join(rest)}")
    return shown


# ------------------------------------------------------------------- for a refinement


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
) -> tuple[PosteriorReport | None, str | None]:
    """The amortized posterior of a refinement's target, or why there is none.

    With ``posterior`` given, any mismatch (another plugin, parameter space, embedder, a
    target shorter than its clips) is the user's error. Without it, the phenomenon's shipped
    estimator is used when it applies; when it does not (effects switched in, parameters
    held by ``--fix``, a short target, another ``scene`` than its training clips') the
    refinement goes on without it and the reason is returned instead.

    Returns:
        ``(report, None)``, or ``(None, reason)`` (``reason`` is ``None`` when the
        phenomenon ships no estimator).
    """
    phenomenon = registry.phenomenon(plugin)
    if posterior is None and getattr(phenomenon, "default_posterior", None) is None:
        return None, None
    try:
        estimator, path = load_estimator(registry, plugin, posterior, device)
        estimator.check_for(plugin, parameter_space, path)
        estimator.check_scene(phenomenon, scene, path)
        pipeline = estimator_embedder(registry, estimator, device)
        report = posterior_of_clip(estimator, pipeline.embedder, clip, n_samples=n_samples, seed=seed)
        pipeline.renderer.close()
    except UserInputError as exc:
        if posterior is not None:
            raise
        return None, f"the plugin's posterior estimator does not apply to this refinement: {exc}"
    report.estimator = path
    return report, None
