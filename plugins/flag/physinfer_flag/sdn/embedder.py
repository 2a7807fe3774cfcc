"""The flag plugin's embedders: the trained SDN and the parameter-free spectral one.

Both prepare a clip the same way (resample to ``fps``, first ``n_frames`` frames,
grayscale, centre crop, resize to ``size``; :func:`physinfer.video.prepare_for_embedding`)
and run the SDN's fixed front end. :class:`SDNEmbedder` then applies the trained head
(weights from a safetensors file, by default the one shipped with the plugin);
:class:`SpectralEmbedder` pools the spectral maps over a grid and needs no weights,
as a baseline and a fallback.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from physinfer.errors import UserInputError
from physinfer.roles import Embedder
from physinfer.types import Clip
from physinfer_flag.sdn.baselines import SpectralPooling
from physinfer_flag.sdn.frontend import FrontEndConfig, SpectralFrontEnd, prepare_video
from physinfer_flag.sdn.network import SDN
from physinfer_flag.sdn.settings import resolve_device
from physinfer_flag.sdn.weights import DEFAULT_WEIGHTS, load_sdn


def _prepared_batch(
    clips: Sequence[Clip], config: FrontEndConfig, device: torch.device
) -> torch.Tensor:
    videos = np.stack([prepare_video(c, config) for c in clips])  # (B, T, size, size) float32
    return torch.from_numpy(videos).to(device)


class SDNEmbedder(Embedder):
    """Clip → SDN embedding ``(D_e,)``.

    Args:
        model: Weights file or training output directory, an :class:`SDN` in memory, or
            ``None`` for the weights shipped with the plugin
            (``physinfer_flag/data/sdn_default.safetensors``).
        device: Torch device (default: cuda if available, else cpu).
        batch_size: Clips per forward pass in :meth:`embed_many`.

    Attributes:
        fps: Frame rate clips are resampled to (from the weights' configuration).
        n_frames: Frames consumed.
        size: Side of the square grayscale input.
        dim: ``D_e``.

    Raises:
        UserInputError: when no weights are given and none are shipped, or the file is
            not SDN weights.
    """

    def __init__(
        self,
        *,
        model: str | Path | SDN | None = None,
        device: str | None = None,
        batch_size: int = 8,
    ) -> None:
        self.device = resolve_device(device)
        if isinstance(model, SDN):
            self.network = model.to(self.device).eval()
        else:
            if model is None:
                if not DEFAULT_WEIGHTS.is_file():
                    raise UserInputError(
                        f"the flag plugin's default SDN weights are missing ({DEFAULT_WEIGHTS}); "
                        "run `make pretrained` to generate and train them, pass --model PATH to "
                        "weights from `physinfer train`, or choose --embedder spectral"
                    )
                model = DEFAULT_WEIGHTS
            self.network = load_sdn(model, self.device)
        if batch_size < 1:
            raise UserInputError(f"batch_size must be positive, got {batch_size}")
        self.batch_size = batch_size
        c = self.network.config.frontend
        self.fps, self.n_frames, self.size = float(c.fps), int(c.n_frames), int(c.size)
        self.dim = int(self.network.config.embedding_dim)

    def embed(self, clip: Clip) -> np.ndarray:
        """Embed one clip; returns ``(D_e,)`` float32.

        Raises:
            UserInputError: when the clip is shorter than ``n_frames`` at ``fps``.
        """
        return self.embed_many([clip])[0]

    @torch.inference_mode()
    def embed_many(self, clips: Sequence[Clip]) -> np.ndarray:
        """Embed several clips; returns ``(N, D_e)`` float32."""
        out = np.empty((len(clips), self.dim), dtype=np.float32)
        for start in range(0, len(clips), self.batch_size):
            batch = _prepared_batch(
                clips[start : start + self.batch_size], self.network.config.frontend, self.device
            )
            out[start : start + len(batch)] = self.network(batch).float().cpu().numpy()
        return out


@dataclass(frozen=True)
class SpectralEmbedderConfig:
    """Settings of :class:`SpectralEmbedder`.

    Attributes:
        frontend: The fixed front end (the SDN's defaults).
        grid: Cells per side of the spatial pooling grid.
        power_floor: Added to mean powers before the log.
        shape_grid: Cells per side of the clip's time-averaged image appended to the
            spectral features (0: none). The spectral maps keep the motion and drop the
            mean shape; a steady change of the flag's pose (a yawed or tilted wind) shows
            mostly there.
        shape_weight: Scale of the mean image's cells (gray levels in [0, 1]) against the
            spectral features.
    """

    frontend: FrontEndConfig = field(default_factory=FrontEndConfig)
    grid: int = 7
    power_floor: float = 1e-6
    shape_grid: int = 0
    shape_weight: float = 30.0

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        self.frontend.validate()
        if self.grid < 1 or self.grid > self.frontend.out_size:
            raise ValueError(
                f"grid must be between 1 and {self.frontend.out_size}, got {self.grid}"
            )
        if self.power_floor <= 0:
            raise ValueError("power_floor must be positive")
        if not 0 <= self.shape_grid <= self.frontend.size:
            raise ValueError(f"shape_grid must be between 0 and {self.frontend.size}, got {self.shape_grid}")
        if self.shape_weight <= 0:
            raise ValueError("shape_weight must be positive")


class SpectralEmbedder(Embedder):
    """Clip → pooled spectral maps, no learned weights (baseline and fallback).

    The SDN front end (temporal Gaussian, derivative filters, max-pool, peak power and
    frequency per pixel), then per grid cell and channel the log mean peak power and the
    power-weighted mean peak frequency: ``(4k · grid²,)``, 196 values by default.

    Args:
        config: Settings.
        model: Must be ``None`` (accepted for the uniform embedder factory signature).
        device: Torch device (default: cuda if available, else cpu).
        n_frames: Frames read from each clip, replacing ``config.frontend.n_frames`` (30):
            ``refine --embedder-frames``, for clips longer than the default (``--duration``).

    Raises:
        UserInputError: when a model is given.
    """

    def __init__(
        self,
        *,
        config: SpectralEmbedderConfig | None = None,
        model: str | Path | None = None,
        device: str | None = None,
        n_frames: int | None = None,
    ) -> None:
        if model is not None:
            raise UserInputError(
                "the spectral embedder has no weights; drop --model or choose --embedder sdn"
            )
        self.config = config or SpectralEmbedderConfig()
        if n_frames is not None:
            frontend = replace(self.config.frontend, n_frames=int(n_frames))
            self.config = replace(self.config, frontend=frontend)
        try:
            self.config.validate()
        except ValueError as exc:
            raise UserInputError(f"invalid spectral embedder settings: {exc}") from None
        self.device = resolve_device(device)
        c = self.config.frontend
        self.fps, self.n_frames, self.size = float(c.fps), int(c.n_frames), int(c.size)
        self.frontend = SpectralFrontEnd(config=c).to(self.device)
        self.pooling = SpectralPooling(
            frontend=c, grid=self.config.grid, power_floor=self.config.power_floor
        )
        self.dim = self.pooling.out_dim + self.config.shape_grid**2

    def embed(self, clip: Clip) -> np.ndarray:
        """Embed one clip; returns ``(4k · grid² + shape_grid²,)`` float32.

        Raises:
            UserInputError: when the clip is shorter than ``n_frames`` at ``fps``.
        """
        return self.embed_many([clip])[0]

    @torch.inference_mode()
    def embed_many(self, clips: Sequence[Clip]) -> np.ndarray:
        """Embed several clips; returns ``(N, 4k · grid² + shape_grid²)`` float32."""
        out = np.empty((len(clips), self.dim), dtype=np.float32)
        for start in range(0, len(clips), 8):
            batch = _prepared_batch(clips[start : start + 8], self.config.frontend, self.device)
            features = self.pooling(self.frontend(batch))
            if self.config.shape_grid:
                features = torch.cat([features, self._mean_shape(batch)], dim=1)
            out[start : start + len(batch)] = features.float().cpu().numpy()
        return out

    def _mean_shape(self, videos: torch.Tensor) -> torch.Tensor:
        """``(B, T, S, S)`` gray videos → ``(B, shape_grid²)`` weighted cells of their mean image."""
        mean = videos.mean(dim=1, keepdim=True)  # (B, 1, S, S)
        cells = torch.nn.functional.adaptive_avg_pool2d(mean, self.config.shape_grid)
        return cells.flatten(1) * self.config.shape_weight


def spectral_shape_embedder(
    *, model: str | Path | None = None, device: str | None = None, n_frames: int | None = None
) -> SpectralEmbedder:
    """:class:`SpectralEmbedder` plus the mean image on a 16 × 16 grid: motion and mean shape.

    Experimental: a wind that turns or tilts the flag moves its mean pose far more than its
    flapping spectrum. The weight (30 per unit gray level) makes the two blocks' seed-to-seed
    spreads of the same order on the flag at 6 m/s (Euclidean 5–16 for the mean image, 6–9
    for the spectral features; docs/benchmarks.md, effect visibility), so neither drowns the
    other. It separates yaw and inclination better at the true θ, but the diagnosis fitted
    worse with it at 24 trials per stage (docs/benchmarks.md), so nothing uses it by default.

    Args:
        model: Must be ``None``.
        device: Torch device.
        n_frames: Frames read from each clip (default 30).
    """
    return SpectralEmbedder(
        config=SpectralEmbedderConfig(shape_grid=16), model=model, device=device, n_frames=n_frames
    )
