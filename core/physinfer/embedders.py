"""A parameter-free spectral embedder that works for any phenomenon.

It follows the paper's idea — the spatial distribution of temporal spectral power —
without learning: the clip is turned to grayscale, cropped and shrunk, each pixel's
signal is Hann-windowed and Fourier-transformed (zero-padded, so the spectrum varies
smoothly with the frequency of the motion), and the power is pooled over a grid of
cells and a set of frequency bands. Powers of the first and second half of the clip
are added (the motion energy of each quarter of the clip, per cell) so that decaying or
growing motion is told apart. numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from physinfer.roles import Embedder
from physinfer.types import Clip
from physinfer.video import prepare_for_embedding


@dataclass(frozen=True)
class GridSpectrumConfig:
    """Settings of :class:`GridSpectrumEmbedder`.

    Attributes:
        fps: Frame rate clips are resampled to.
        n_frames: Frames consumed (the first ``n_frames`` after resampling).
        size: Side of the square grayscale image the clip is reduced to.
        grid: Cells per side for spatial pooling.
        n_bands: Frequency bands between ``f_min`` and ``f_max`` (log-spaced).
        f_min: Lowest band edge in Hz.
        f_max: Highest band edge in Hz (at most the Nyquist frequency).
        pad: Zero-padding factor of the FFT.
        n_segments: Consecutive segments whose motion energy is kept (temporal envelope).
    """

    fps: float = 25.0
    n_frames: int = 100
    size: int = 64
    grid: int = 4
    n_bands: int = 16
    f_min: float = 0.2
    f_max: float = 5.0
    pad: int = 4
    n_segments: int = 4

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if self.n_frames < 8:
            raise ValueError("n_frames must be at least 8")
        if not 0 < self.f_min < self.f_max <= self.fps / 2:
            raise ValueError("need 0 < f_min < f_max <= fps / 2")
        if self.size % self.grid:
            raise ValueError("size must be a multiple of grid")


def band_power(signals: np.ndarray, fps: float, edges: np.ndarray, pad: int) -> np.ndarray:
    """Mean periodogram power of each band for each signal.

    Args:
        signals: ``(..., T)`` real signals.
        fps: Sampling rate in Hz.
        edges: ``(B + 1,)`` band edges in Hz.
        pad: Zero-padding factor of the FFT.

    Returns:
        ``(..., B)`` band powers.
    """
    t = signals.shape[-1]
    x = signals - signals.mean(axis=-1, keepdims=True)
    x = x * np.hanning(t)
    n_fft = pad * t
    power = np.abs(np.fft.rfft(x, n=n_fft, axis=-1)) ** 2 / t
    freqs = np.fft.rfftfreq(n_fft, d=1.0 / fps)
    band = np.digitize(freqs, edges) - 1  # -1 and B mean outside every band
    out = np.zeros(signals.shape[:-1] + (len(edges) - 1,), dtype=np.float64)
    for b in range(len(edges) - 1):
        sel = band == b
        if sel.any():
            out[..., b] = power[..., sel].mean(axis=-1)
    return out


class GridSpectrumEmbedder(Embedder):
    """Parameter-free embedding: band powers of pixel signals pooled over a spatial grid.

    Output dimension ``grid² · (n_bands + n_segments)``: band amplitudes of the whole
    clip, and the motion amplitude of each of ``n_segments`` consecutive segments.

    Args:
        config: Settings; defaults suit clips of 4 s at 25 fps.
        model: Ignored (accepted for the uniform embedder factory signature).
        device: Ignored (numpy on CPU).
        n_frames: Frames read, overriding ``config.n_frames`` (``--embedder-frames``).
    """

    def __init__(
        self,
        *,
        config: GridSpectrumConfig | None = None,
        model: str | None = None,
        device: str | None = None,
        n_frames: int | None = None,
    ) -> None:
        self.config = config or GridSpectrumConfig()
        if n_frames is not None:
            self.config = replace(self.config, n_frames=int(n_frames))
        self.config.validate()
        self.fps, self.n_frames = self.config.fps, self.config.n_frames
        self._edges = np.geomspace(self.config.f_min, self.config.f_max, self.config.n_bands + 1)

    def _cells(self, per_pixel: np.ndarray) -> np.ndarray:
        """``(S, S, K)`` → ``(grid · grid · K,)`` cell means."""
        g, cell = self.config.grid, self.config.size // self.config.grid
        return per_pixel.reshape(g, cell, g, cell, -1).mean(axis=(1, 3)).reshape(-1)

    def embed(self, clip: Clip) -> np.ndarray:
        """Embed a clip; returns ``(grid² · (n_bands + n_segments),)`` float32."""
        c = self.config
        video = prepare_for_embedding(clip, fps=c.fps, n_frames=c.n_frames, size=c.size)
        signals = video.transpose(1, 2, 0)  # (S, S, T)
        spectrum = self._cells(band_power(signals, c.fps, self._edges, c.pad))
        segments = np.array_split(signals - signals.mean(axis=-1, keepdims=True), c.n_segments, axis=-1)
        envelope = self._cells(np.stack([np.mean(s**2, axis=-1) for s in segments], axis=-1))
        # Amplitudes, not powers: distances then grow roughly linearly with motion differences.
        return (np.concatenate([np.sqrt(spectrum), 10.0 * np.sqrt(envelope)]) * 10.0).astype(np.float32)
