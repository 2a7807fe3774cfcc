"""The dataset interface the SDN's training and evaluation read.

A dataset is a set of clips, each with the id of the simulation it was rendered from,
optionally the id of its θ group (simulations that share θ and differ only in seed), and
its parameter vector θ. Inputs come either as prepared grayscale clips
``(N, T, size, size)`` uint8, or as cached front-end features ``(N, 4k, size/2, size/2)``
float32. :class:`ArrayDataset` holds arrays (numpy memmaps work, so a dataset on disk
need not fit in memory); anything with the same attributes and ``get_batch`` satisfies
:class:`SDNDataset`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from physinfer.errors import UserInputError
from physinfer.types import Clip
from physinfer_flag.sdn.frontend import (
    FrontEndConfig,
    check_video_shape,
    frontend_features,
    prepare_video,
    video_to_uint8,
)
from physinfer_flag.sdn.progress import progress_bar

InputKind = Literal["clips", "features"]


@runtime_checkable
class SDNDataset(Protocol):
    """What training and evaluation need from a dataset.

    Attributes:
        kind: ``"clips"`` (prepared grayscale videos) or ``"features"`` (front-end output).
        sim_ids: ``(N,)`` int simulation id of each clip.
        group_ids: ``(N,)`` int θ-group id of each clip, or ``None``.
        theta: ``(N, D_p)`` float parameters of each clip's simulation.
        theta_names: ``D_p`` parameter names.
        fps: Frame rate of the clips (for ``"clips"``).
        frontend_config: The settings that produced the features (for ``"features"``).
    """

    kind: InputKind
    sim_ids: np.ndarray
    group_ids: np.ndarray | None
    theta: np.ndarray
    theta_names: tuple[str, ...]
    fps: float
    frontend_config: FrontEndConfig | None

    def __len__(self) -> int:
        """Number of clips ``N``."""
        ...

    def get_batch(self, indices: np.ndarray) -> np.ndarray:
        """Inputs of the clips ``indices``: ``(B, T, H, W)`` uint8 or ``(B, C, h, w)`` float32."""
        ...


@dataclass(frozen=True)
class ArrayDataset:
    """An :class:`SDNDataset` over arrays.

    Attributes:
        inputs: ``(N, T, size, size)`` uint8 clips or ``(N, 4k, size/2, size/2)`` float features.
        sim_ids: ``(N,)`` simulation ids.
        theta: ``(N, D_p)`` parameters.
        theta_names: Names of the ``D_p`` parameters.
        group_ids: ``(N,)`` θ-group ids, or ``None``.
        kind: ``"clips"`` or ``"features"``.
        fps: Frame rate of the clips.
        frontend_config: Settings that produced ``inputs`` when ``kind == "features"``.
    """

    inputs: np.ndarray
    sim_ids: np.ndarray
    theta: np.ndarray
    theta_names: tuple[str, ...] = ()
    group_ids: np.ndarray | None = None
    kind: InputKind = "clips"
    fps: float = 25.0
    frontend_config: FrontEndConfig | None = field(default=None)

    def __post_init__(self) -> None:
        n = len(self.inputs)
        if self.kind not in ("clips", "features"):
            raise UserInputError(f"dataset kind must be 'clips' or 'features', got {self.kind!r}")
        if self.inputs.ndim != 4:
            raise UserInputError(
                f"dataset inputs must be 4-D (N, T, H, W) or (N, C, h, w), got {self.inputs.shape}"
            )
        if self.kind == "clips" and self.inputs.dtype != np.uint8:
            raise UserInputError(
                f"clip datasets hold uint8 grayscale videos, got {self.inputs.dtype}"
            )
        if self.kind == "features" and self.frontend_config is None:
            raise UserInputError(
                "a feature dataset must say which front-end settings produced it (frontend_config)"
            )
        theta = np.asarray(self.theta)
        if theta.ndim != 2 or len(theta) != n or np.shape(self.sim_ids) != (n,):
            raise UserInputError(
                f"need theta (N, D_p) and sim_ids (N,) for N={n} clips, got {theta.shape} and {np.shape(self.sim_ids)}"
            )
        if self.group_ids is not None and np.shape(self.group_ids) != (n,):
            raise UserInputError(f"group_ids must be (N,) = ({n},), got {np.shape(self.group_ids)}")
        if self.theta_names and len(self.theta_names) != theta.shape[1]:
            raise UserInputError(
                f"{len(self.theta_names)} theta_names for {theta.shape[1]} parameters"
            )

    def __len__(self) -> int:
        """Number of clips."""
        return len(self.inputs)

    def get_batch(self, indices: np.ndarray) -> np.ndarray:
        """Inputs of ``indices`` (sorted reads are cheaper on memmaps, order is kept)."""
        indices = np.asarray(indices, dtype=np.int64)
        order = np.argsort(indices, kind="stable")
        batch = np.asarray(self.inputs[indices[order]])
        out = np.empty_like(batch)
        out[order] = batch
        return out


def subset(dataset: SDNDataset, indices: Sequence[int] | np.ndarray) -> ArrayDataset:
    """An in-memory :class:`ArrayDataset` of some clips of ``dataset``."""
    idx = np.asarray(indices, dtype=np.int64)
    return ArrayDataset(
        inputs=dataset.get_batch(idx),
        sim_ids=np.asarray(dataset.sim_ids)[idx],
        theta=np.asarray(dataset.theta)[idx],
        theta_names=tuple(dataset.theta_names),
        group_ids=None if dataset.group_ids is None else np.asarray(dataset.group_ids)[idx],
        kind=dataset.kind,
        fps=dataset.fps,
        frontend_config=dataset.frontend_config,
    )


def check_frame_rate(dataset: SDNDataset, config: FrontEndConfig) -> None:
    """Raise :class:`UserInputError` when clips are not at the front end's frame rate."""
    if dataset.kind == "clips" and abs(dataset.fps - config.fps) > 1e-6:
        raise UserInputError(
            f"the clips are at {dataset.fps:g} fps but the network expects {config.fps:g} fps; "
            "resample them (physinfer.video.resample) when preparing the dataset"
        )


def as_features(
    dataset: SDNDataset,
    config: FrontEndConfig,
    *,
    device: str | None = None,
    batch_size: int = 8,
    progress: bool = False,
) -> SDNDataset:
    """The dataset with inputs replaced by front-end features (computed once, in memory).

    A feature dataset is returned as is after checking its settings match ``config``.

    Args:
        dataset: Clips or features.
        config: Front-end settings of the network that will read the features.
        device: Torch device for the front end.
        batch_size: Clips per front-end pass.
        progress: Show a progress bar on stderr.

    Returns:
        A ``"features"`` dataset, ``(N, 4k, size/2, size/2)`` float32 inputs.
    """
    if dataset.kind == "features":
        if dataset.frontend_config != config:
            raise UserInputError(
                f"the cached features were computed with front-end settings {dataset.frontend_config}, "
                f"but the network uses {config}; recompute the cache"
            )
        return dataset
    check_frame_rate(dataset, config)
    n = len(dataset)
    out = np.empty((n, config.out_channels, config.out_size, config.out_size), dtype=np.float32)
    with progress_bar(progress) as bar:
        task = bar.add_task("front end", total=n, info="")
        for start in range(0, n, batch_size):
            idx = np.arange(start, min(n, start + batch_size))
            videos = dataset.get_batch(idx)
            check_video_shape(videos, config)
            out[idx] = frontend_features(
                videos, config=config, device=device, batch_size=batch_size
            )
            bar.advance(task, len(idx))
    return ArrayDataset(
        inputs=out,
        sim_ids=np.asarray(dataset.sim_ids),
        theta=np.asarray(dataset.theta),
        theta_names=tuple(dataset.theta_names),
        group_ids=None if dataset.group_ids is None else np.asarray(dataset.group_ids),
        kind="features",
        fps=config.fps,
        frontend_config=config,
    )


def group_ids_from_theta(theta: np.ndarray) -> np.ndarray:
    """θ-group ids: clips whose θ rows are identical share a group.

    Args:
        theta: ``(N, D_p)`` parameters.

    Returns:
        ``(N,)`` int64 ids, numbered in order of the sorted distinct rows.
    """
    _, inverse = np.unique(np.asarray(theta), axis=0, return_inverse=True)
    return inverse.reshape(-1).astype(np.int64)


class PreparedClips:
    """An :class:`SDNDataset` view of a generated clip dataset, prepared for the SDN.

    Wraps any object shaped like :class:`physinfer.datasets.ClipDataset` (attributes
    ``sim_ids``, ``params``, ``param_names``, ``fps``; method ``clips(indices)`` giving
    ``(B, T, H, W)`` or ``(B, T, H, W, 3)`` uint8). Clips are resampled, cut to
    ``n_frames``, turned to grayscale and centre-cropped/resized when read; stored clips
    already in the network's format are only cut. θ groups are clips with identical θ.

    Args:
        clips: The clip dataset (one split).
        config: Front-end settings of the network that will read it.
    """

    kind: InputKind = "clips"
    frontend_config: FrontEndConfig | None = None

    def __init__(self, clips: object, *, config: FrontEndConfig) -> None:
        self.source = clips
        self.config = config
        self.sim_ids = np.asarray(clips.sim_ids, dtype=np.int64)  # type: ignore[attr-defined]
        self.theta = np.asarray(clips.params, dtype=np.float64)  # type: ignore[attr-defined]
        self.theta_names = tuple(clips.param_names)  # type: ignore[attr-defined]
        self.group_ids: np.ndarray | None = group_ids_from_theta(self.theta)
        self.fps = config.fps
        self._source_fps = float(clips.fps)  # type: ignore[attr-defined]

    def __len__(self) -> int:
        """Number of clips."""
        return len(self.sim_ids)

    def get_batch(self, indices: np.ndarray) -> np.ndarray:
        """Prepared clips ``(B, n_frames, size, size)`` uint8."""
        c = self.config
        raw = self.source.clips(np.asarray(indices, dtype=np.int64))  # type: ignore[attr-defined]
        if (
            raw.ndim == 4
            and raw.shape[2:] == (c.size, c.size)
            and abs(self._source_fps - c.fps) < 1e-6
        ):
            if raw.shape[1] < c.n_frames:
                raise UserInputError(
                    f"the dataset's clips have {raw.shape[1]} frames; the network needs {c.n_frames}"
                )
            return np.ascontiguousarray(raw[:, : c.n_frames])
        out = np.empty((len(raw), c.n_frames, c.size, c.size), dtype=np.uint8)
        for i, frames in enumerate(raw):
            rgb = frames[..., None] if frames.ndim == 3 else frames
            out[i] = video_to_uint8(
                prepare_video(Clip(np.ascontiguousarray(rgb), self._source_fps), c)
            )
        return out
