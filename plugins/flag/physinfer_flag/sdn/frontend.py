"""The SDN's fixed front end: clip → spectral feature maps, with no trainable weights.

In the paper's order: a temporal Gaussian (σ_t = 1), first-order Gaussian derivative
filters in x and y (σ = 2), a 2× spatial max-pool of both filtered volumes, and the
spectral decomposition layer (k = 1). A ``(N, T, H, W)`` grayscale video becomes
``(N, 4k, H/2, W/2)`` maps: peak powers of the x- and y-derivative signals, then their
peak frequencies in Hz.

:class:`SpectralFrontEnd` is the fast implementation. Everything before the max-pool is
linear, so the temporal Gaussian is one ``(T, T)`` matrix product and both derivative
filters are applied with one forward 2D FFT and one batched inverse (their spectra are
outer products of 1D spectra). The max-pool is not linear, so it stays between the
filters and the DFT; after it, the Hann window, the mean removal and the DFT are again
one ``(2F, T)`` matrix product. :class:`ReferenceFrontEnd` is the plain version
(convolutions, ``max_pool2d``, ``torch.fft.rfft``) that the fast one is tested against.

Because the front end is fixed, its output can be computed once per clip and cached
(:func:`save_cached_features`), so that training touches only the 2D layers.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.fft
import torch
import torch.nn.functional as F
from torch import nn

from physinfer.errors import UserInputError
from physinfer.io import atomic_save_npz
from physinfer.types import Clip
from physinfer.video import prepare_for_embedding
from physinfer_flag.sdn.settings import resolve_device, settings_from_dict
from physinfer_flag.sdn.spectral import (
    SpectralSettings,
    dft_basis,
    power_from_coefficients,
    select_peaks,
    spectral_decomposition,
)

FEATURES_FORMAT = "physinfer-sdn-frontend/1"
# Working-set size of one block of frames in the fused spatial filtering (fits in L2/L3).
_CHUNK_BYTES = 4 * 2**20


@dataclass(frozen=True)
class FrontEndConfig:
    """Settings of the fixed front end (the paper's values by default).

    Attributes:
        fps: Frame rate clips are resampled to; frequencies are in Hz at this rate.
        n_frames: Frames consumed (the first ``n_frames`` after resampling).
        size: Side of the square grayscale input (centre crop, then resize).
        sigma_t: Standard deviation of the temporal Gaussian, in frames.
        sigma_xy: Standard deviation of the spatial derivative-of-Gaussian filters, in pixels.
        truncate: Filters are cut at ``truncate · σ`` (radius rounded up).
        k: Periodogram peaks kept per pixel signal.
        detrend: Remove each pixel signal's mean before the window (see
            :class:`~physinfer_flag.sdn.spectral.SpectralSettings`).
        exclude_dc: Never report 0 Hz as a peak.
        n_fft: DFT length; ``None`` uses ``n_frames`` (the paper's frequency resolution).
    """

    fps: float = 25.0
    n_frames: int = 30
    size: int = 224
    sigma_t: float = 1.0
    sigma_xy: float = 2.0
    truncate: float = 3.0
    k: int = 1
    detrend: bool = True
    exclude_dc: bool = True
    n_fft: int | None = None

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if self.n_frames < 4:
            raise ValueError(f"n_frames must be at least 4, got {self.n_frames}")
        if self.size < 8 or self.size % 2:
            raise ValueError(f"size must be an even number of at least 8 pixels, got {self.size}")
        if self.sigma_t <= 0 or self.sigma_xy <= 0 or self.truncate <= 0:
            raise ValueError("sigma_t, sigma_xy and truncate must be positive")
        self.spectral_settings().validate()
        if self.spectral_settings().n_candidate_bins(self.n_frames) < self.k:
            raise ValueError(
                f"k={self.k} exceeds the number of frequency bins for {self.n_frames} frames"
            )

    def spectral_settings(self, method: str = "matmul") -> SpectralSettings:
        """The settings of the spectral layer inside this front end."""
        return SpectralSettings(
            k=self.k,
            fps=self.fps,
            detrend=self.detrend,
            exclude_dc=self.exclude_dc,
            n_fft=self.n_fft,
            method=method,  # type: ignore[arg-type]
        )

    @property
    def out_channels(self) -> int:
        """``2k · 2``: power and frequency for each peak of the x and y derivatives."""
        return 4 * self.k

    @property
    def out_size(self) -> int:
        """Side of the output maps (half the input side)."""
        return self.size // 2

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> FrontEndConfig:
        """Rebuild from :meth:`to_dict` output; unknown keys are an error."""
        return settings_from_dict(cls, data)


# -- filters ---------------------------------------------------------------------------


def filter_radius(sigma: float, truncate: float) -> int:
    """Half-width of a Gaussian filter cut at ``truncate · sigma``."""
    return max(1, math.ceil(truncate * sigma))


def gaussian_kernel(sigma: float, truncate: float = 3.0) -> torch.Tensor:
    """Sampled Gaussian normalised to sum 1, ``(2R + 1,)`` float64."""
    r = filter_radius(sigma, truncate)
    i = torch.arange(-r, r + 1, dtype=torch.float64)
    g = torch.exp(-0.5 * (i / sigma) ** 2)
    return g / g.sum()


def gaussian_derivative_kernel(sigma: float, truncate: float = 3.0) -> torch.Tensor:
    """First-order Gaussian derivative, as a correlation kernel, ``(2R + 1,)`` float64.

    Scaled so that correlating it with the ramp ``f[n] = n`` gives exactly 1: the output
    is the intensity gradient per pixel of the Gaussian-smoothed image.
    """
    g = gaussian_kernel(sigma, truncate)
    r = (len(g) - 1) // 2
    i = torch.arange(-r, r + 1, dtype=torch.float64)
    d = i * g
    return d / (i * d).sum()


def temporal_smoothing_matrix(n_frames: int, sigma: float, truncate: float = 3.0) -> torch.Tensor:
    """The temporal Gaussian with replicated end frames as a ``(T, T)`` matrix (float64).

    ``smoothed = M @ video`` along the time axis.
    """
    g = gaussian_kernel(sigma, truncate)
    r = (len(g) - 1) // 2
    m = torch.zeros(n_frames, n_frames, dtype=torch.float64)
    rows = torch.arange(n_frames)
    for offset, weight in zip(range(-r, r + 1), g.tolist(), strict=True):
        cols = (rows + offset).clamp(0, n_frames - 1)
        m.index_put_(
            (rows, cols), torch.full((n_frames,), weight, dtype=torch.float64), accumulate=True
        )
    return m


def derivative_filters_2d(sigma: float, truncate: float = 3.0) -> torch.Tensor:
    """The x- and y-derivative correlation kernels, ``(2, 2R + 1, 2R + 1)`` float64.

    Channel 0 differentiates along the width (x), channel 1 along the height (y).
    """
    g = gaussian_kernel(sigma, truncate)
    d = gaussian_derivative_kernel(sigma, truncate)
    return torch.stack([torch.outer(g, d), torch.outer(d, g)])


def _circular_spectrum(kernel_1d: torch.Tensor, n: int) -> torch.Tensor:
    """rfft of a correlation kernel laid out so that circular convolution correlates."""
    r = (len(kernel_1d) - 1) // 2
    placed = torch.zeros(n, dtype=torch.float64)
    for i, value in zip(range(-r, r + 1), kernel_1d.tolist(), strict=True):
        placed[(-i) % n] = value
    return torch.fft.fft(placed)


# -- the front ends -------------------------------------------------------------------


def _to_float_video(video: torch.Tensor) -> torch.Tensor:
    if video.ndim != 4:
        raise UserInputError(
            f"the front end takes videos (N, T, H, W), got shape {tuple(video.shape)}"
        )
    if video.dtype == torch.uint8:
        return video.to(torch.float32) / 255.0
    return video.to(torch.float32) if not video.is_floating_point() else video


@dataclass(frozen=True)
class _FusedConstants:
    temporal: torch.Tensor  # (T, T) temporal Gaussian
    spectra: torch.Tensor  # (2, n_w // 2 + 1, n_h) derivative-filter spectra
    dft_t: torch.Tensor  # (2F, T) window + mean removal + DFT
    n_h: int
    n_w: int


class SpectralFrontEnd(nn.Module):
    """The fused fixed front end (no trainable weights).

    Args:
        config: Front-end settings.

    Shapes:
        input ``(N, T, H, W)`` uint8 (0–255) or float (0–1), ``H`` and ``W`` even →
        output ``(N, 4k, H/2, W/2)``: ``[P_x, P_y, Ω_x, Ω_y]`` for ``k = 1``.
    """

    def __init__(self, *, config: FrontEndConfig | None = None) -> None:
        super().__init__()
        self.config = config or FrontEndConfig()
        self.config.validate()
        self._settings = self.config.spectral_settings("matmul")
        self._radius = filter_radius(self.config.sigma_xy, self.config.truncate)
        self._cache: dict[tuple[Any, ...], Any] = {}

    def _constants(
        self, t: int, h: int, w: int, device: torch.device, dtype: torch.dtype
    ) -> _FusedConstants:
        key = (t, h, w, str(device), dtype)
        if key not in self._cache:
            c = self.config
            r = self._radius
            n_h = scipy.fft.next_fast_len(h + 2 * r, real=True)
            n_w = scipy.fft.next_fast_len(w + 2 * r, real=True)
            g, d = (
                gaussian_kernel(c.sigma_xy, c.truncate),
                gaussian_derivative_kernel(c.sigma_xy, c.truncate),
            )
            gh, dh = _circular_spectrum(g, n_h), _circular_spectrum(d, n_h)
            gw, dw = (
                _circular_spectrum(g, n_w)[: n_w // 2 + 1],
                _circular_spectrum(d, n_w)[: n_w // 2 + 1],
            )
            # Separable kernels have outer-product spectra; laid out (2, n_w // 2 + 1, n_h)
            # because the data is transposed while the height axis is transformed.
            spectra = torch.stack([torch.outer(dw, gh), torch.outer(gw, dh)])
            complex_dtype = torch.complex64 if dtype == torch.float32 else torch.complex128
            self._cache[key] = _FusedConstants(
                temporal=temporal_smoothing_matrix(t, c.sigma_t, c.truncate).to(
                    device=device, dtype=dtype
                ),
                spectra=spectra.to(device=device, dtype=complex_dtype),
                dft_t=dft_basis(self._settings, t, dtype=dtype).T.contiguous().to(device),
                n_h=n_h,
                n_w=n_w,
            )
        return self._cache[key]

    def filtered(self, video: torch.Tensor) -> torch.Tensor:
        """Temporal Gaussian, derivative filters and max-pool, before the spectral layer.

        Args:
            video: ``(N, T, H, W)`` video.

        Returns:
            ``(N, T, 2, H/2, W/2)`` pooled x- and y-derivative volumes.
        """
        if video.ndim != 4:
            raise UserInputError(
                f"the front end takes videos (N, T, H, W), got shape {tuple(video.shape)}"
            )
        n, t, h, w = video.shape
        dtype = video.dtype if video.is_floating_point() else torch.float32
        k = self._constants(t, h, w, video.device, dtype)
        if video.device.type != "cpu":
            frames = (k.temporal @ _to_float_video(video).reshape(n, t, h * w)).reshape(n * t, h, w)
            return self._filter_and_pool(frames, k).reshape(n, t, 2, h // 2, w // 2)
        # On CPU, one clip and a few frames at a time: every frame is independent once
        # the temporal Gaussian is applied, and small blocks keep the FFT buffers in
        # cache (three times faster than one pass over a whole clip on a 2-core CPU).
        step = max(1, _CHUNK_BYTES // (16 * k.n_h * k.n_w))
        pooled = torch.empty(n, t, 2, h // 2, w // 2, device=video.device, dtype=dtype)
        for i in range(n):
            clip = _to_float_video(video[i : i + 1]).reshape(t, h * w)
            frames = (k.temporal @ clip).reshape(t, h, w)
            for start in range(0, t, step):
                # Slice assignment (not out=) keeps autograd working through the front end.
                pooled[i, start : start + step] = self._filter_and_pool(
                    frames[start : start + step], k
                )
        return pooled

    def _filter_and_pool(self, frames: torch.Tensor, k: _FusedConstants) -> torch.Tensor:
        """Derivative filters and 2x max-pool: ``(B, H, W)`` frames → ``(B, 2, H/2, W/2)``."""
        r = self._radius
        h2, w2 = frames.shape[1] // 2 * 2, frames.shape[2] // 2 * 2
        x = F.pad(frames[None], (r, r, r, r), mode="replicate")[0]
        # 2D filtering by FFT. Padding to h + 2r >= the filter support keeps the circular
        # convolution from wrapping. Every transform runs along the last, contiguous axis
        # (strided FFTs are several times slower on CPU), hence the two transposes.
        spectrum = torch.fft.rfft(x, n=k.n_w, dim=-1).transpose(-1, -2).contiguous()
        spectrum = torch.fft.fft(spectrum, n=k.n_h, dim=-1)  # (B, n_w/2+1, n_h)
        rows = torch.fft.ifft(spectrum[:, None] * k.spectra, dim=-1)[..., r : r + h2]
        y = torch.fft.irfft(rows.transpose(-1, -2).contiguous(), n=k.n_w, dim=-1)[..., r : r + w2]
        return torch.maximum(
            torch.maximum(y[..., 0::2, 0::2], y[..., 0::2, 1::2]),
            torch.maximum(y[..., 1::2, 0::2], y[..., 1::2, 1::2]),
        )

    def forward(self, video: torch.Tensor) -> torch.Tensor:
        """Spectral feature maps, ``(N, 4k, H/2, W/2)``."""
        pooled = self.filtered(video)
        n, t, c, h, w = pooled.shape
        dft_t = self._constants(
            t, video.shape[2], video.shape[3], pooled.device, pooled.dtype
        ).dft_t
        coefficients = dft_t @ pooled.reshape(n, t, c * h * w)  # (N, 2F, C·h·w)
        power = power_from_coefficients(coefficients, t, dim=1)
        values, hz = select_peaks(power, self._settings, t, dim=1)  # (N, k, C·h·w)
        k = self._settings.k
        # Channel c·k + i for peak i of channel c, as spectral_decomposition lays it out.
        values = values.reshape(n, k, c, h, w).transpose(1, 2).reshape(n, c * k, h, w)
        hz = hz.reshape(n, k, c, h, w).transpose(1, 2).reshape(n, c * k, h, w)
        return torch.cat([values, hz], dim=1)


class ReferenceFrontEnd(nn.Module):
    """The plain front end: convolutions, ``max_pool2d`` and ``torch.fft.rfft``.

    Same contract and same numbers as :class:`SpectralFrontEnd` (up to float rounding);
    kept as the readable specification and the speed reference.
    """

    def __init__(self, *, config: FrontEndConfig | None = None) -> None:
        super().__init__()
        self.config = config or FrontEndConfig()
        self.config.validate()
        c = self.config
        self.register_buffer(
            "temporal",
            gaussian_kernel(c.sigma_t, c.truncate).float().reshape(1, 1, -1, 1, 1),
            persistent=False,
        )
        self.register_buffer(
            "spatial",
            derivative_filters_2d(c.sigma_xy, c.truncate).float()[:, None],
            persistent=False,
        )
        self._settings = c.spectral_settings("fft")

    def forward(self, video: torch.Tensor) -> torch.Tensor:
        """Spectral feature maps, ``(N, 4k, H/2, W/2)``."""
        x = _to_float_video(video)
        n, t, h, w = x.shape
        rt = (self.temporal.shape[2] - 1) // 2
        x = F.conv3d(F.pad(x[:, None], (0, 0, 0, 0, rt, rt), mode="replicate"), self.temporal)
        rs = (self.spatial.shape[-1] - 1) // 2
        frames = F.pad(x.reshape(n * t, 1, h, w), (rs, rs, rs, rs), mode="replicate")
        y = F.max_pool2d(F.conv2d(frames, self.spatial), 2)  # (N·T, 2, H/2, W/2)
        y = y.reshape(n, t, 2, h // 2, w // 2).transpose(1, 2)  # (N, 2, T, H/2, W/2)
        return spectral_decomposition(y, self._settings)


# -- clips, batches and the feature cache ---------------------------------------------


def prepare_video(clip: Clip, config: FrontEndConfig) -> np.ndarray:
    """Resample, cut, grayscale, crop and resize a clip for the front end.

    Returns:
        ``(n_frames, size, size)`` float32 in [0, 1].

    Raises:
        UserInputError: when the clip is shorter than ``n_frames`` at ``fps``.
    """
    return prepare_for_embedding(clip, fps=config.fps, n_frames=config.n_frames, size=config.size)


def video_to_uint8(video: np.ndarray) -> np.ndarray:
    """``(…)`` float in [0, 1] → uint8 (for compact datasets of prepared clips)."""
    return np.clip(np.rint(np.asarray(video, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)


def check_video_shape(videos: np.ndarray, config: FrontEndConfig) -> None:
    """Raise :class:`UserInputError` unless ``videos`` is ``(N, ≥n_frames, size, size)``."""
    if (
        videos.ndim != 4
        or videos.shape[1] < config.n_frames
        or videos.shape[2:] != (config.size, config.size)
    ):
        raise UserInputError(
            f"videos must be (N, T>={config.n_frames}, {config.size}, {config.size}) grayscale, "
            f"got {tuple(videos.shape)}; prepare clips with physinfer_flag.sdn.frontend.prepare_video"
        )


@torch.inference_mode()
def frontend_features(
    videos: np.ndarray,
    *,
    config: FrontEndConfig,
    device: str | None = None,
    batch_size: int = 4,
    frontend: SpectralFrontEnd | None = None,
) -> np.ndarray:
    """Front-end features of many prepared videos (the first ``n_frames`` of each).

    Args:
        videos: ``(N, T, size, size)`` uint8 or float in [0, 1], ``T ≥ n_frames``.
        config: Front-end settings.
        device: Torch device (default: cuda if available, else cpu).
        batch_size: Clips per forward pass (bounds memory).
        frontend: A ready front end to reuse (built from ``config`` when omitted).

    Returns:
        ``(N, 4k, size/2, size/2)`` float32.
    """
    check_video_shape(videos, config)
    target = resolve_device(device)
    frontend = (frontend or SpectralFrontEnd(config=config)).to(target)
    out = np.empty(
        (len(videos), config.out_channels, config.out_size, config.out_size), dtype=np.float32
    )
    for start in range(0, len(videos), batch_size):
        chunk = torch.from_numpy(
            np.ascontiguousarray(videos[start : start + batch_size, : config.n_frames])
        )
        out[start : start + len(chunk)] = frontend(chunk.to(target)).cpu().numpy()
    return out


def save_cached_features(path: str | Path, features: np.ndarray, config: FrontEndConfig) -> None:
    """Write one clip's front-end features to an NPZ (atomic, no pickles).

    Args:
        path: Destination ``.npz``.
        features: ``(4k, size/2, size/2)`` float array from :func:`frontend_features`.
        config: The settings that produced them (stored, checked on load).
    """
    expected = (config.out_channels, config.out_size, config.out_size)
    if features.shape != expected:
        raise UserInputError(
            f"features must be {expected} for this front end, got {features.shape}"
        )
    atomic_save_npz(
        path,
        features=features.astype(np.float32),
        format=np.asarray(FEATURES_FORMAT),
        frontend_config=np.asarray(json.dumps(config.to_dict(), sort_keys=True)),
    )


def cache_clip_features(
    path: str | Path, clip: Clip, *, config: FrontEndConfig, device: str | None = None
) -> np.ndarray:
    """Prepare a clip, run the front end and save the result (see :func:`save_cached_features`).

    Returns:
        The ``(4k, size/2, size/2)`` features written.
    """
    video = prepare_video(clip, config)[None]
    features = frontend_features(video, config=config, device=device)[0]
    save_cached_features(path, features, config)
    return features


def load_cached_features(
    path: str | Path, config: FrontEndConfig | None = None
) -> tuple[np.ndarray, FrontEndConfig]:
    """Read features written by :func:`save_cached_features`.

    Args:
        path: The ``.npz`` file.
        config: When given, the stored settings must equal it.

    Returns:
        ``(features (4k, size/2, size/2) float32, the stored FrontEndConfig)``.

    Raises:
        UserInputError: unreadable file, wrong format, or settings that differ from ``config``.
    """
    try:
        with np.load(path, allow_pickle=False) as data:
            fmt = str(data["format"])
            stored = FrontEndConfig.from_dict(json.loads(str(data["frontend_config"])))
            features = data["features"].astype(np.float32)
    except (OSError, KeyError, ValueError) as exc:
        raise UserInputError(f"cannot read cached front-end features {path}: {exc}") from None
    if fmt != FEATURES_FORMAT:
        raise UserInputError(f"{path}: format {fmt!r}, expected {FEATURES_FORMAT!r}")
    if config is not None and stored != config:
        raise UserInputError(
            f"{path} was computed with front-end settings {stored.to_dict()}, not {config.to_dict()}; "
            "recompute the cache"
        )
    return features, stored
