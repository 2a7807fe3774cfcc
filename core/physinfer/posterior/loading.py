"""What the posterior workflows load and check: an estimator (given or the phenomenon's shipped
one), the embedder it was trained with, a target's embedding, a dataset against the plugin;
and the ``progress`` callback type they share."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.evaluation import build_pipeline
from physinfer.posterior.estimator import EstimatorConfig, PosteriorEstimator, resolve_device
from physinfer.registry import Registry
from physinfer.scene import default_scene, scene_text

#: ``progress(stage, done, total)``.
ProgressFn = Callable[[str, int, int], None]


def no_progress(stage: str, done: int, total: int) -> None:
    """The default ``progress``: report nothing."""


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
    return build_pipeline(
        registry,
        plugin,
        embedder=embedder,
        weights=weights,
        device=device,
        embedder_frames=embedder_frames,
    )


def check_dataset(dataset: Any, plugin: str) -> None:
    """Refuse a dataset generated for another phenomenon, or one that stores no θ."""
    made_for = dataset.info.get("config", {}).get("phenomenon")
    if made_for not in (None, plugin):
        raise UserInputError(
            f"{dataset.root} was generated for --plugin {made_for}, not {plugin}; pass --plugin {made_for}"
        )
    if not dataset.param_names:
        raise UserInputError(f"{dataset.root} stores no parameters θ: a posterior needs them")


def load_estimator(
    registry: Registry,
    plugin: str,
    path: Path | None,
    device: str | None = None,
    *,
    scene: Mapping[str, Any] | None = None,
    render: Mapping[str, Any] | None = None,
    seconds: float | None = None,
) -> tuple[PosteriorEstimator, Path]:
    """The estimator at ``path`` or the phenomenon's shipped one, checked against ``plugin``.

    Without ``path``: the shipped default estimator, or, for a ``scene`` it was not trained
    on, the first of the phenomenon's ``scene_posteriors`` that covers the scene (the
    default's refusal is raised when none does). A shipped estimator that takes render
    settings (:attr:`~physinfer.posterior.estimator.EstimatorConfig.render_inputs`) is
    chosen first when ``render`` (the user's ``--render-set``) gives every one of them
    within its training ranges and it covers the scene; otherwise such estimators are
    passed over. ``seconds``: the target's length; of the shipped estimators that answer,
    the one trained on the longest clips the target covers is chosen (it reads more of the
    video), else the first. A given ``path`` is not checked against
    ``scene`` here: callers call :meth:`PosteriorEstimator.check_scene`.

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
        device = resolve_device(device)
        if seconds is not None and len(_shipped_lengths(phenomenon, Path(shipped))) < 2:
            seconds = None  # one clip length shipped: the first that answers, none loaded past it
        told = _shipped_told(phenomenon, scene, render, device, seconds) if render else None
        estimator, path = told or _shipped_for_scene(phenomenon, Path(shipped), scene, device, seconds)
    else:
        estimator = PosteriorEstimator.load(path, device=resolve_device(device))
    estimator.check_for(plugin, phenomenon.parameter_space, path)
    return estimator, Path(path)


def _shipped_told(
    phenomenon: Any,
    scene: Mapping[str, Any] | None,
    render: Mapping[str, Any],
    device: str,
    seconds: float | None = None,
) -> tuple[PosteriorEstimator, Path] | None:
    """Of the ``scene_posteriors`` that take render settings, all of which ``render`` gives
    within their training ranges, and that cover ``scene``: the one for ``seconds``
    (:func:`_for_length`); ``None`` when none answers (or none for so short a target)."""
    answering = []
    for path in _shipped_others(phenomenon):
        estimator = PosteriorEstimator.load(path, device=device)
        if estimator.config.render_inputs and _told_misfit(estimator, phenomenon, scene, render) is None:
            answering.append((estimator, path))
    return _for_length(answering, seconds)


def _for_length(
    answering: list[tuple[PosteriorEstimator, Path]], seconds: float | None
) -> tuple[PosteriorEstimator, Path] | None:
    """Of estimators that all answer, the one trained on the longest clips a target of
    ``seconds`` covers (the first of equals); the first when ``seconds`` is ``None``;
    ``None`` when there are none or the target is shorter than every one's clips."""
    if seconds is None:
        return answering[0] if answering else None
    covered = [pair for pair in answering if pair[0].config.clip_seconds <= seconds + 1e-6]
    return max(covered, key=lambda pair: pair[0].config.clip_seconds) if covered else None


def _told_misfit(
    estimator: PosteriorEstimator, phenomenon: Any, scene: Mapping[str, Any] | None, render: Mapping[str, Any]
) -> str | None:
    """Why a shipped estimator told the camera does not answer for ``scene`` and ``render``
    (settings not given, outside its ranges, another scene), or ``None`` when it does."""
    missing = sorted(name for name in estimator.config.render_inputs or {} if name not in render)
    if missing:
        return f"it needs --render-set for {', '.join(missing)} too"
    outside = estimator.render_outside(render)
    if outside:
        return f"outside its training cameras: {'; '.join(outside)}"
    try:
        estimator.check_scene(phenomenon, scene)
    except UserInputError as exc:
        return exc.reason
    return None


def told_passed_over(
    registry: Registry, plugin: str, scene: Mapping[str, Any] | None, render: Mapping[str, Any]
) -> list[str]:
    """Why each of the phenomenon's shipped estimators told the camera was not chosen for
    ``render`` (the user's ``--render-set``): ``["posterior_camera.safetensors: it needs
    --render-set for fov_deg too"]``; for ``infer`` to say when the camera told went unused."""
    phenomenon = registry.phenomenon(plugin)
    reasons = []
    for path in _shipped_others(phenomenon):
        estimator = PosteriorEstimator.load(path)
        why = _told_misfit(estimator, phenomenon, scene, render) if estimator.config.render_inputs else None
        if why is not None:
            reasons.append(f"{path.name}: {why}")
    return reasons


def shipped_for_longer(phenomenon: Any, than: float, seconds: float) -> bool:
    """Whether the phenomenon ships an estimator of clips longer than ``than`` seconds that a
    target of ``seconds`` covers (read from the files' metadata: cheap enough for every
    ``infer``)."""
    for path in _shipped_others(phenomenon):
        config = stored_config(path)
        if config is not None and than + 1e-6 < config.clip_seconds <= seconds + 1e-6:
            return True
    return False


def stored_config(path: str | Path) -> EstimatorConfig | None:
    """The configuration an estimator file stores, read from its metadata alone (no network
    built, no digest checked: for choosing among shipped files before loading one, which
    :meth:`PosteriorEstimator.load` checks); ``None`` when it cannot be read."""
    from safetensors import safe_open

    try:
        with safe_open(str(path), framework="pt", device="cpu") as f:
            return EstimatorConfig.from_dict(json.loads((f.metadata() or {})["physinfer"]))
    except Exception:  # noqa: BLE001 - any unreadable file is "no configuration"
        return None


def _shipped_lengths(phenomenon: Any, default: Path) -> set[float]:
    """The clip lengths of the shipped estimators, read from their metadata."""
    configs = [stored_config(path) for path in [default, *_shipped_others(phenomenon)]]
    return {config.clip_seconds for config in configs if config is not None}


def _shipped_others(phenomenon: Any) -> list[Path]:
    """The phenomenon's ``scene_posteriors`` that exist."""
    return [Path(p) for p in getattr(phenomenon, "scene_posteriors", ()) or () if Path(p).is_file()]


def _shipped_for_scene(
    phenomenon: Any, default: Path, scene: Mapping[str, Any] | None, device: str, seconds: float | None = None
) -> tuple[PosteriorEstimator, Path]:
    """The first shipped estimator (the default, then ``scene_posteriors``) that covers
    ``scene`` and takes no render settings, or with ``seconds`` the one of those for the
    target's length (:func:`_for_length`); the default when none is shipped for other
    scenes (its refusal is then the caller's to raise).

    Raises:
        UserInputError: scene estimators are shipped but none covers ``scene``: the
            default's refusal, with what the others cover.
    """
    first = PosteriorEstimator.load(default, device=device)
    refusals: list[str] = []
    answering: list[tuple[PosteriorEstimator, Path]] = []
    found_others = False
    for path in [default, *_shipped_others(phenomenon)]:
        estimator = first if path == default else PosteriorEstimator.load(path, device=device)
        if path != default and estimator.config.render_inputs:
            continue  # told the camera: chosen only when the user tells it (_shipped_told)
        found_others = found_others or path != default
        try:
            estimator.check_scene(phenomenon, scene, path)
        except UserInputError as exc:
            refusals.append(str(exc) if path == default else _coverage(estimator, path, phenomenon))
            continue
        answering.append((estimator, path))
        if seconds is None:
            break  # the first that answers: no need to load the rest
    if answering:  # a target shorter than all their clips: the first, whose embedding refuses it
        return _for_length(answering, seconds) or answering[0]
    if not found_others:
        return first, default
    raise UserInputError(f"{refusals[0]} (the plugin's other shipped estimators: {'; '.join(refusals[1:])})")


def _coverage(estimator: PosteriorEstimator, path: Path, phenomenon: Any) -> str:
    """``posterior_sizes.safetensors covers flag_height 0.6..2, flag_length 0.9..3 (pinning=hoist, ...)``."""
    ranges = estimator.config.scene_ranges or {}
    spans = ", ".join(f"{name} {low:g}..{high:g}" for name, (low, high) in sorted(ranges.items()))
    fixed = {k: v for k, v in {**default_scene(phenomenon), **(estimator.config.scene or {})}.items() if k not in ranges}
    return f"{path.name} covers {spans or 'its own scene only'}" + (f" ({scene_text(fixed)})" if fixed else "")


def estimator_embedder(
    registry: Registry, estimator: PosteriorEstimator, device: str | None
) -> Any:
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
            "video (or a wider --start/--end), an estimator trained on shorter clips, or measure it with "
            f"`physinfer refine --plugin {c.plugin}`, which searches without an estimator"
        )
    x = np.asarray(embedder.embed(clip), dtype=np.float32)
    if not np.isfinite(x).all():
        raise UserInputError(
            "the target's embedding is not finite (NaN or inf): the video may be blank or damaged"
        )
    return x
