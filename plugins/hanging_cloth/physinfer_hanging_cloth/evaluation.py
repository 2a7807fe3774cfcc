"""The Bouman et al. evaluation: embeddings → PCA → linear regression, leave one fabric out.

As in the paper (following Bouman et al. 2013): every video is embedded, the embeddings
are projected to 50 dimensions by PCA and a linear regression predicts the logarithm of
the fabric's stiffness and of its area weight. Cross-validation leaves one fabric — all
its videos — out per fold; PCA and regression are fitted on the other fabrics only. The
score is Pearson's R between the held-out predictions and the ground truth, over all
videos, on log values (so any choice of units gives the same R).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physinfer.errors import UserInputError
from physinfer.roles import Embedder
from physinfer.types import Clip
from physinfer.video import read_video
from physinfer_hanging_cloth.data import QUANTITIES, BoumanDataset

#: Dimensions the paper projects the embeddings to.
PCA_DIMS = 50


@dataclass(frozen=True)
class EvaluationResult:
    """Scores and held-out predictions of one evaluation.

    Attributes:
        pearson_stiffness: Pearson R of log stiffness (predicted vs true, all videos).
        pearson_area_weight: Pearson R of log area weight.
        n_videos: Videos evaluated.
        n_fabrics: Fabrics (folds).
        pca_dims: Largest number of PCA components used in a fold.
        predictions: ``{"stiffness": (N,), "area_weight": (N,)}`` held-out predictions of
            the natural log in canonical units (lbf·in², oz/yd²).
        truths: The same for the ground truth.
    """

    pearson_stiffness: float
    pearson_area_weight: float
    n_videos: int
    n_fabrics: int
    pca_dims: int
    predictions: dict[str, np.ndarray]
    truths: dict[str, np.ndarray]

    def summary(self) -> dict[str, float | int]:
        """The JSON result of ``physinfer evaluate bouman``."""
        return {
            "pearson_stiffness": self.pearson_stiffness,
            "pearson_area_weight": self.pearson_area_weight,
            "n_videos": self.n_videos,
            "n_fabrics": self.n_fabrics,
            "pca_dims": self.pca_dims,
        }


def frames_needed(path: Path, embedder: Embedder) -> int | None:
    """Frames to read from ``path`` so the embedder gets ``n_frames`` after resampling.

    Reading only what is needed keeps long, large real videos from filling memory.
    ``None`` (read everything) when the container does not tell its frame rate.
    """
    if path.suffix.lower() == ".gif" or path.is_dir():
        return None
    try:
        import av

        with av.open(str(path)) as container:
            rate = container.streams.video[0].average_rate
    except Exception:  # unreadable files are reported by read_video with a clear message
        return None
    if not rate:
        return None
    return int(math.ceil(embedder.n_frames * float(rate) / embedder.fps)) + 2


def embed_videos(
    dataset: BoumanDataset, embedder: Embedder, *, on_video: Callable[[int, int], None] | None = None,
    batch: int = 8,
) -> np.ndarray:
    """Embed every video of the dataset.

    Args:
        dataset: The checked dataset.
        embedder: Any registered embedder.
        on_video: Called with ``(done, total)`` after each batch (progress).
        batch: Videos embedded per call of ``embed_many``.

    Returns:
        ``(N, D_e)`` float64 embeddings in the order of ``dataset.videos``.

    Raises:
        UserInputError: for an unreadable or too short video (naming it).
    """
    out: list[np.ndarray] = []
    videos = dataset.videos
    for start in range(0, len(videos), batch):
        clips: list[Clip] = []
        for entry in videos[start : start + batch]:
            clip = read_video(entry.path, max_frames=frames_needed(entry.path, embedder))
            if clip.duration < embedder.n_frames / embedder.fps - 1e-9:
                raise UserInputError(
                    f"video {entry.path} lasts {clip.duration:.2f} s; the embedder needs "
                    f"{embedder.n_frames / embedder.fps:.2f} s ({embedder.n_frames} frames at {embedder.fps:g} fps)"
                )
            clips.append(clip)
        out.append(np.asarray(embedder.embed_many(clips), dtype=np.float64))
        if on_video is not None:
            on_video(min(start + batch, len(videos)), len(videos))
    return np.concatenate(out)


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson correlation of two ``(N,)`` vectors; NaN when either is constant."""
    a = np.asarray(a, dtype=np.float64) - np.mean(a)
    b = np.asarray(b, dtype=np.float64) - np.mean(b)
    denom = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b / denom) if denom > 0 else float("nan")


def leave_one_group_out(
    features: np.ndarray, targets: np.ndarray, groups: np.ndarray, *, pca_dims: int = PCA_DIMS
) -> tuple[np.ndarray, int]:
    """Held-out predictions of a PCA + linear-regression model, one group per fold.

    Args:
        features: ``(N, D)`` embeddings.
        targets: ``(N, K)`` regression targets.
        groups: ``(N,)`` group label of each row; each fold holds out one group.
        pca_dims: Components kept (fewer when a fold has fewer training rows or
            features: ``min(pca_dims, n_train - 1, D)``).

    Returns:
        ``(N, K)`` predictions and the largest number of components used.
    """
    from sklearn.decomposition import PCA
    from sklearn.linear_model import LinearRegression

    predictions = np.empty_like(targets, dtype=np.float64)
    used = 0
    for group in np.unique(groups):
        test = groups == group
        train = ~test
        n_components = max(1, min(pca_dims, int(train.sum()) - 1, features.shape[1]))
        pca = PCA(n_components=n_components, svd_solver="full").fit(features[train])
        model = LinearRegression().fit(pca.transform(features[train]), targets[train])
        predictions[test] = model.predict(pca.transform(features[test]))
        used = max(used, n_components)
    return predictions, used


def evaluate_embeddings(dataset: BoumanDataset, embeddings: np.ndarray, *, pca_dims: int = PCA_DIMS) -> EvaluationResult:
    """Cross-validate embeddings of ``dataset.videos`` against its ground truth.

    Args:
        dataset: The checked dataset.
        embeddings: ``(N, D_e)`` in the order of ``dataset.videos``.
        pca_dims: PCA components (the paper: 50).

    Raises:
        UserInputError: when the embeddings do not match the videos or are not finite.
    """
    embeddings = np.asarray(embeddings, dtype=np.float64)
    if embeddings.ndim != 2 or embeddings.shape[0] != len(dataset.videos):
        raise UserInputError(f"expected ({len(dataset.videos)}, D) embeddings, got {embeddings.shape}")
    if not np.isfinite(embeddings).all():
        raise UserInputError("the embedder returned NaN or infinite values")
    truths = dataset.targets()
    target_matrix = np.stack([truths[q] for q in QUANTITIES], axis=1)
    predicted, used = leave_one_group_out(embeddings, target_matrix, dataset.groups(), pca_dims=pca_dims)
    predictions = {q: predicted[:, k] for k, q in enumerate(QUANTITIES)}
    return EvaluationResult(
        pearson_stiffness=pearson(predictions["stiffness"], truths["stiffness"]),
        pearson_area_weight=pearson(predictions["area_weight"], truths["area_weight"]),
        n_videos=len(dataset.videos),
        n_fabrics=dataset.n_fabrics,
        pca_dims=used,
        predictions=predictions,
        truths=truths,
    )


def plot_bars(result: EvaluationResult, path: str | Path, *, label: str) -> Path:
    """Bar chart of the two Pearson R, like the paper's figure, written atomically as PNG.

    Args:
        result: The evaluation.
        path: Destination ``.png``.
        label: What was evaluated (embedder name), shown in the title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from physinfer.io import atomic_path

    values = [result.pearson_stiffness, result.pearson_area_weight]
    fig, ax = plt.subplots(figsize=(4.2, 3.4), dpi=120)
    try:
        bars = ax.bar(["stiffness", "area weight"], [0.0 if math.isnan(v) else v for v in values],
                      color=["#4c72b0", "#dd8452"], width=0.6)
        for bar, value in zip(bars, values, strict=True):
            ax.annotate("n/a" if math.isnan(value) else f"{value:.2f}",
                        (bar.get_x() + bar.get_width() / 2, max(bar.get_height(), 0.0)),
                        ha="center", va="bottom", fontsize=9)
        ax.set_ylim(min(0.0, *(v for v in values if not math.isnan(v)), 0.0) - 0.05, 1.0)
        ax.axhline(0.0, color="black", linewidth=0.6)
        ax.set_ylabel("Pearson R (log values)")
        ax.set_title(f"{label}: {result.n_videos} videos, {result.n_fabrics} fabrics", fontsize=9)
        fig.tight_layout()
        path = Path(path)
        with atomic_path(path, suffix=".png") as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
    return path
