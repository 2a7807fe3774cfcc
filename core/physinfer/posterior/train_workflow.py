"""The training workflow (``physinfer posterior train``): embed a dataset's clips (cached beside
it) and train q(θ | s(x)) on the (θ, embedding) pairs; the result and where it was written."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from physinfer.errors import UserInputError
from physinfer.io import check_output_dir
from physinfer.posterior.estimator import NetworkConfig, PosteriorEstimator, resolve_device
from physinfer.posterior.fingerprint import embedder_probe
from physinfer.posterior.loading import ProgressFn, build_embedder, check_dataset, no_progress
from physinfer.registry import Registry


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
            "scene_ranges": c.scene_ranges,
            "embeddings_cache": str(self.cache),
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
    data: Path,
    out: Path,
    embedder: str | None = None,
    embedder_frames: int | None = None,
    weights: Path | None = None,
    device: str | None = None,
    split: str = "train",
    network: NetworkConfig | None = None,
    seed: int = 0,
    progress: ProgressFn = no_progress,
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
    check_dataset(dataset, plugin)
    pipeline = build_embedder(
        registry,
        plugin,
        embedder=embedder,
        embedder_frames=embedder_frames,
        weights=weights,
        device=device,
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
