"""The training workflow (``physinfer posterior train``): embed a dataset's clips (cached beside
it) and train q(θ | s(x)) on the (θ, embedding) pairs; the result and where it was written."""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.as_given import CameraModel
from physinfer.datasets.loader import ClipDataset
from physinfer.errors import UserInputError
from physinfer.io import check_output_dir
from physinfer.posterior.estimator import NetworkConfig, PosteriorEstimator, resolve_device
from physinfer.posterior.features import EmbeddedSet, TargetPath, embed_dataset, join_sets
from physinfer.posterior.fingerprint import embedder_probe, probe_clip
from physinfer.posterior.held_out import MAX_CLIPS, SAMPLES, held_out_check
from physinfer.posterior.inputs import checked_rows, render_ranges, varied_render_settings
from physinfer.posterior.loading import ProgressFn, build_embedder, check_dataset, no_progress
from physinfer.posterior.training import train_estimator
from physinfer.registry import Registry
from physinfer.types import Clip
from physinfer.video import to_gray


@dataclass
class TrainResult:
    """A trained estimator and where it was written."""

    estimator: PosteriorEstimator
    path: Path
    cache: Path
    seconds: dict[str, float]
    #: The cache of each dataset trained on (``cache`` is the first's).
    caches: tuple[Path, ...] = ()

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
            "scene_ranges": c.scene_ranges,
            "render_inputs": c.render_inputs,
            # one dataset: its cache; several: a list, one per dataset
            "embeddings_cache": [str(c) for c in self.caches] if len(self.caches) > 1 else str(self.cache),
            "targets": c.targets,
            "constant_inputs": len((c.inputs or {}).get("constant", [])),
            "held_out": c.held_out,
            "seconds": self.seconds,
        }

    def plot(self) -> Any:
        """The validation loss per epoch of each flow trained (a matplotlib figure)."""
        from matplotlib.figure import Figure

        fig = Figure(figsize=(5, 3.2), layout="constrained")
        ax = fig.subplots()
        curves = self.estimator.validation_curves
        for k, curve in enumerate(curves):
            ax.plot(range(1, len(curve) + 1), curve, lw=1, label=f"flow {k}" if len(curves) > 1 else None)
        ax.set_xlabel("epoch")
        ax.set_ylabel("validation loss (−log q)")
        ax.set_title(f"{self.estimator.config.plugin}: {self.path.name}", fontsize=9)
        if len(curves) > 1:
            ax.legend(fontsize=7)
        return fig


def train_posterior(
    registry: Registry,
    *,
    plugin: str,
    data: Path | Sequence[Path],
    out: Path,
    embedder: str | None = None,
    embedder_frames: int | None = None,
    weights: Path | None = None,
    device: str | None = None,
    split: str = "train",
    network: NetworkConfig | None = None,
    seed: int = 0,
    as_given: bool = True,
    accept_miscalibrated: bool = False,
    render_inputs: Sequence[str] = (),
    told_camera: bool = False,
    progress: ProgressFn = no_progress,
) -> TrainResult:
    """Embed a dataset's clips (cached beside it) and train q(θ | s(x)) with sbi's NPE.

    ``data``: one dataset directory, or several trained on together (more clips than one
    dataset holds, each dataset with its own cache): they must be of one phenomenon, clip
    format, parameter space and scene.

    ``as_given``: embed the clips as users give videos (:mod:`physinfer.as_given`: camera
    effects, H.264, ``infer``'s conditioning), so that the estimator is trained on what it
    will be asked about; ``False``: the stored renders as they are.

    Before writing, the estimator is checked on the dataset's held-out clips (the ``test``
    split, else ``val``), sent down the same path (:mod:`physinfer.posterior.held_out`): one
    whose 90 % intervals miss the truth too often or collapse to points is refused, with
    what to change, unless ``accept_miscalibrated`` (then written, with the check recorded).

    ``render_inputs``: render settings ζ the estimator is told (each clip's, from the
    dataset; ``infer`` then needs them with ``--render-set``); ``told_camera``: every numeric
    setting the training clips vary (the camera and the light), with ``render_inputs``.
    Neither: the estimator averages over the clips' ζ, as before.

    Raises:
        UserInputError: a dataset of another phenomenon or without θ, datasets that differ in
            clip format, parameters or scene, clips shorter than the embedder reads, grayscale
            clips for an embedder that reads colour, too few clips, a render input the clips do
            not vary, or an estimator that fails the held-out check.
    """
    network = network or NetworkConfig()
    network.validate()  # before the slow embedding
    out = _estimator_path(out)
    datasets = _checked_datasets(data, split, plugin)
    dataset = datasets[0]
    told = _told_ranges(datasets, render_inputs, told_camera)  # before the slow embedding
    pipeline = build_embedder(
        registry, plugin, embedder=embedder, embedder_frames=embedder_frames, weights=weights, device=device
    )
    emb = pipeline.embedder
    name = embedder or pipeline.phenomenon.default_embedder
    clip_seconds = _checked_clip_seconds(dataset, dataset.root, emb, name)  # alike in all
    identity = _identity(plugin, name, emb, embedder_frames, weights, clip_seconds)
    t0 = time.perf_counter()
    path = TargetPath(pipeline.phenomenon, CameraModel(), seed) if as_given else None
    embedder_info = {k: identity[k] for k in ("embedder", "embedder_frames", "embedder_fps", "probe")}
    pairs, caches = _embedded(datasets, split, emb, embedder_info, path, progress)
    pairs = pairs.with_render_inputs(told)
    t1 = time.perf_counter()
    estimator = train_estimator(
        pairs, identity, network=network, seed=seed, device=resolve_device(device),
        on_epoch=lambda done, total, best: progress("training", done, total),
    )  # fmt: skip
    _record_dataset(estimator, datasets, split)
    t2 = time.perf_counter()
    roots = [d.root for d in datasets]
    held_out = _check_held_out(estimator, roots, split, emb, embedder_info, path, pipeline.phenomenon, progress)
    estimator.config = replace(estimator.config, held_out=held_out)
    if held_out and held_out["problems"] and not accept_miscalibrated:
        raise UserInputError(_refusal(held_out, ", ".join(map(str, roots)), as_given))
    t3 = time.perf_counter()
    estimator.save(out)
    pipeline.renderer.close()
    seconds = {"embed": t1 - t0, "train": t2 - t1, "held_out_check": t3 - t2}
    return TrainResult(estimator, out, caches[0], seconds, caches)


def _told_ranges(datasets: Sequence[Any], render_inputs: Sequence[str], told_camera: bool) -> dict[str, list[float]]:
    """``{name: [low, high]}`` of the render settings the estimator is told (``--render-input``,
    and with ``--told-camera`` every numeric one the training clips vary), over the training
    clips' ζ of every dataset; empty when none is told."""
    dataset = datasets[0]
    zetas = [zeta for d in datasets for zeta in d.render_params]
    names = [*render_inputs, *(varied_render_settings(zetas) if told_camera else ())]
    if told_camera and not names:
        raise UserInputError(
            f"--told-camera: the clips of {dataset.root} were all rendered with one camera and light",
            remedy="drop --told-camera, or generate a dataset whose renders vary (dataset generate without "
            "a fixed --render-set)",
        )
    return render_ranges(names, zetas) if names else {}


def _checked_datasets(data: Path | Sequence[Path], split: str, plugin: str) -> list[ClipDataset]:
    """The ``split`` of each dataset ``data``, checked for ``plugin`` and against the first: one
    estimator learns from clips of one format, parameter space and scene.

    Raises:
        UserInputError: no dataset, one of another phenomenon or without θ, or datasets that
            differ (what differs is named).
    """
    given = list(data) if isinstance(data, tuple | list) else [data]
    if not given:
        raise UserInputError("data: give the dataset directory (physinfer dataset generate)")
    for item in given:
        if not isinstance(item, str | os.PathLike):
            raise UserInputError(f"--data {item!r}: give a path")
    roots = [Path(item) for item in given]
    datasets = [ClipDataset(root, split) for root in roots]
    for dataset in datasets:
        check_dataset(dataset, plugin)
    first = datasets[0]
    for other in datasets[1:]:
        differs = [what for what, key in _DATASET_TERMS.items() if key(other) != key(first)]
        if differs:
            raise UserInputError(
                f"{other.root} differs from {first.root} in its {' and '.join(differs)}; "
                "train on datasets generated alike (dataset generate with the same options but --seed)"
            )
    return datasets


#: What datasets trained on together must share, and how each is read.
_DATASET_TERMS: dict[str, Any] = {
    "clip format": lambda d: d.clip_format,
    "parameters": lambda d: d.parameter_space.to_dict(),
    "scene": lambda d: d.info.get("config", {}).get("scene"),
    "scene ranges": lambda d: d.scene_ranges,
}


def _embedded(
    datasets: Sequence[ClipDataset],
    split: str,
    embedder: Any,
    embedder_info: dict[str, Any],
    path: TargetPath | None,
    progress: ProgressFn,
) -> tuple[EmbeddedSet, tuple[Path, ...]]:
    """The embedded training clips of every dataset as one set (each cached beside its
    dataset), and the cache files; one progress bar over all of them."""
    total, before, sets = sum(len(d) for d in datasets), 0, []
    for dataset in datasets:
        sets.append(
            embed_dataset(
                dataset.root, split, embedder, embedder_info, as_given=path,
                on_progress=lambda done, _, before=before: progress("embedding", before + done, total),
            )
        )  # fmt: skip
        before += len(dataset)
    return join_sets(sets), tuple(s.cache for s in sets)


def _checked_clip_seconds(dataset: Any, data: Path, embedder: Any, name: str) -> float:
    """The dataset's clip length in seconds, refused when shorter than ``embedder`` reads or
    grayscale for an embedder that reads colour."""
    clip_seconds = dataset.clip_format.n_frames / dataset.clip_format.fps
    reads = embedder.n_frames / embedder.fps
    if clip_seconds + 1e-9 < reads:
        raise UserInputError(
            f"the clips of {data} last {clip_seconds:.2f} s but the embedder {name!r} reads "
            f"{embedder.n_frames} frames at {embedder.fps:g} fps ({reads:.2f} s); generate longer "
            "clips (dataset generate --frames N) or lower --embedder-frames"
        )
    check_clip_colour(dataset, embedder, name)
    return clip_seconds


def _identity(
    plugin: str,
    name: str,
    embedder: Any,
    frames_option: int | None,
    weights: Path | None,
    clip_seconds: float,
) -> dict[str, Any]:
    """What the estimator was trained on, stored in it: the embedder (its name, frames, rate
    and its answer to a probe clip, so another embedder is told apart) and the clip length."""
    probe = embedder_probe(embedder)
    return {
        "plugin": plugin,
        "embedder": name,
        "embedder_frames": int(embedder.n_frames),
        "embedder_fps": float(embedder.fps),
        "frames_option": frames_option,
        "weights": str(weights) if weights else None,
        "probe": [float(v) for v in probe],
        "clip_seconds": float(clip_seconds),
    }


def _record_dataset(estimator: PosteriorEstimator, datasets: Sequence[Any], split: str) -> None:
    """Note the dataset (a list of names for several) and split in the estimator's training
    record, and the clips' scene in its config: targets of another scene get no intervals from it."""
    names = [d.root.resolve().name for d in datasets]
    estimator.config.training.update(dataset=names[0] if len(names) == 1 else names, split=split)
    scene = datasets[0].info.get("config", {}).get("scene")
    if scene is not None:
        estimator.config = replace(estimator.config, scene=dict(scene))


def check_clip_colour(dataset: Any, embedder: Any, name: str) -> None:
    """Refuse grayscale clips for an embedder that reads colour: targets arrive in colour,
    and an estimator trained without it meets inputs it never saw."""
    if dataset.clip_format.channels != 1 or not reads_colour(embedder):
        return
    raise UserInputError(
        f"{dataset.root} stores grayscale clips, but the embedder {name!r} reads colour and videos arrive "
        "in colour; generate the dataset in colour (`physinfer dataset generate` without --gray)"
    )


def reads_colour(embedder: Any) -> bool:
    """Whether ``embedder`` tells a colour clip from its grayscale (BT.601 luma) version."""
    probe = probe_clip(int(embedder.n_frames), float(embedder.fps))
    frames = probe.frames.astype(np.float32)
    tint = np.array([1.3, 0.8, 0.6], dtype=np.float32)  # a colour clip with the probe's motion
    coloured = np.clip(frames * tint, 0, 255).astype(np.uint8)
    luma = np.rint(to_gray(coloured) * 255.0).astype(np.uint8)
    gray = np.repeat(luma[..., None], 3, axis=-1)
    a = np.asarray(embedder.embed(Clip(coloured, probe.fps)), dtype=np.float64)
    b = np.asarray(embedder.embed(Clip(gray, probe.fps)), dtype=np.float64)
    return bool(np.linalg.norm(a - b) > 1e-3 * max(np.linalg.norm(a), 1e-12))


def _check_held_out(
    estimator: PosteriorEstimator,
    roots: Sequence[Path],
    split: str,
    embedder: Any,
    embedder_info: dict[str, Any],
    path: TargetPath | None,
    phenomenon: Any,
    progress: ProgressFn,
) -> dict[str, Any] | None:
    """The held-out check on the datasets' ``test`` (else ``val``) splits, or ``None`` when
    none has held-out clips."""
    held = {root: _held_out_split(root, split) for root in roots}
    sets = [
        embed_dataset(
            root, s, embedder, embedder_info, as_given=path,
            on_progress=lambda done, total: progress("held-out clips", done, total),
        )
        for root, s in held.items()
        if s is not None
    ]  # fmt: skip
    if not sets:
        return None
    pairs = join_sets(sets).with_render_inputs(estimator.config.render_inputs)
    rows = slice(0, min(len(pairs), MAX_CLIPS))
    x = checked_rows(estimator.config.inputs, pairs.conditions[rows])
    samples = estimator.sample_unit_batched(x, SAMPLES, seed=0)
    names = estimator.parameter_space.names
    nuisance = getattr(phenomenon, "nuisance", ()) or ()
    check = held_out_check(pairs.theta_unit[rows].astype(np.float64), samples, names, nuisance)
    splits = sorted({s for s in held.values() if s is not None})
    return {"split": splits[0] if len(splits) == 1 else splits, "as_given": path is not None, **check}


def _held_out_split(root: Path, split: str) -> str | None:
    """The split of ``root`` a training on ``split`` is checked on: ``test``, else ``val``
    (``None`` without held-out clips)."""
    return next((s for s in ("test", "val") if s != split and len(ClipDataset(root, s)) > 0), None)


def _refusal(held_out: dict[str, Any], data: str, as_given: bool) -> str:
    """The refusal of an estimator that failed the held-out check, with what to change."""
    fixes = [
        "an ensemble of flows (--ensemble 5: their mixture is wider where they disagree)",
        "more training clips (dataset generate --sims N)",
        "a longer clip or another embedder (--embedder, --embedder-frames)",
    ]
    if not as_given:
        fixes.insert(0, "train on clips as users give them (drop --stored)")
    return (
        f"the estimator failed its check on {held_out['clips']} held-out clips of {data} "
        f"({held_out['split']} split): {'; '.join(held_out['problems'])}. Its intervals would be wrong on "
        f"videos; try {', or '.join(fixes)}. Nothing was written (--accept-miscalibrated writes it anyway)"
    )


def _estimator_path(out: Path) -> Path:
    out = Path(out)
    if out.suffix != ".safetensors":
        raise UserInputError(f"--out {out}: name the estimator file *.safetensors")
    if out.is_dir():
        raise UserInputError(f"--out {out} is a directory; give a file name ending in .safetensors")
    check_output_dir(out.parent)  # before the slow embedding
    return out
