"""Parameter-free embedders that work for any phenomenon.

:class:`MotionSpectrumEmbedder` (``motion``) compares how the subject moves, from its tracked
path, and leaves looks out: the one for real footage. :class:`GridSpectrumEmbedder`
(``grid_spectrum``) follows the paper's idea — the spatial distribution of temporal spectral power —
without learning: the clip is turned to grayscale, cropped and shrunk, each pixel's
signal is Hann-windowed and Fourier-transformed (zero-padded, so the spectrum varies
smoothly with the frequency of the motion), and the power is pooled over a grid of
cells and a set of frequency bands. Powers of the first and second half of the clip
are added (the motion energy of each quarter of the clip, per cell) so that decaying or
growing motion is told apart. numpy only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from physinfer.errors import NothingMoves, UserInputError
from physinfer.roles import Embedder
from physinfer.tracking import MotionTrack, track_motion
from physinfer.types import Clip
from physinfer.video import prepare_for_embedding, resample


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


@dataclass(frozen=True)
class MotionSpectrumConfig:
    """Settings of :class:`MotionSpectrumEmbedder`.

    Attributes:
        fps: Frame rate clips are resampled to.
        n_frames: Frames read from the start of a clip (``--embedder-frames``; an amortized
            estimator is trained on clips of one length); ``None``: the whole clip, up to
            ``max_seconds``.
        min_frames: Fewest frames a clip must have (one second at ``fps``).
        max_seconds: Longest stretch read from the start of a clip.
        size: Side of the square a video is framed to before tracking (``prepare``).
        f_min: Lowest frequency of the spectral grid in Hz.
        f_max: Highest frequency in Hz (below the Nyquist frequency).
        n_freqs: Points of the log-spaced frequency grid.
        widths: Smoothing widths of the spectra in natural-log frequency, narrow to broad: the
            narrow ones place a frequency precisely, the broad ones keep the distance falling
            towards it from far away (an optimizer finds the basin).
        n_segments: Consecutive segments whose swing amplitude is kept (the decay).
        n_times: Samples of the path itself (along and across the swing), kept for short
            clips: a clip of about one swing has a spectrum as wide as its frequency, but its
            path still fixes the period once the phase (a nuisance) is searched.
        short_s: Clips up to this long keep the path at full weight; the weight falls to 0 at
            1.5 times this (a longer clip's path makes the distance rugged in the period: on a
            6-s clip with it at half weight, 24 trials missed the length by 11 %).
    """

    fps: float = 20.0
    n_frames: int | None = None
    min_frames: int = 20
    max_seconds: float = 40.0
    size: int = 96
    f_min: float = 0.1
    f_max: float = 8.0
    n_freqs: int = 72
    widths: tuple[float, ...] = (0.03, 0.1, 0.3)
    n_segments: int = 4
    n_times: int = 40
    short_s: float = 4.0

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if not 0 < self.f_min < self.f_max < self.fps / 2:
            raise ValueError("need 0 < f_min < f_max < fps / 2")
        if self.min_frames < 8 or self.max_seconds * self.fps < max(self.n_frames or 0, self.min_frames):
            raise ValueError("need min_frames >= 8 and n_frames, min_frames <= max_seconds * fps")
        if self.n_frames is not None and self.n_frames < self.min_frames:
            raise ValueError(f"n_frames must be at least {self.min_frames}")
        if not self.widths or min(self.widths) <= 0:
            raise ValueError("widths must be positive")


def smoothed_spectra(signals: np.ndarray, fps: float, grid: np.ndarray, widths: Sequence[float]) -> np.ndarray:
    """Hann-windowed power spectra of ``signals`` smoothed in log frequency onto ``grid``.

    Args:
        signals: ``(K, T)`` real signals.
        fps: Sampling rate in Hz.
        grid: ``(F,)`` frequencies in Hz.
        widths: Gaussian widths in natural-log frequency.

    Returns:
        ``(len(widths), K, F)`` power, each row a weighted mean of the periodogram.
    """
    t = signals.shape[-1]
    x = (signals - signals.mean(axis=-1, keepdims=True)) * np.hanning(t)
    n_fft = max(4096, 1 << int(np.ceil(np.log2(8 * t))))
    power = np.abs(np.fft.rfft(x, n=n_fft, axis=-1)) ** 2 / t
    freqs = np.fft.rfftfreq(n_fft, d=1.0 / fps)[1:]
    log_f, log_grid = np.log(freqs), np.log(grid)
    out = []
    for width in widths:
        kernel = np.exp(-0.5 * ((log_f[None, :] - log_grid[:, None]) / width) ** 2)  # (F, n)
        kernel /= kernel.sum(axis=1, keepdims=True)
        out.append(power[:, 1:] @ kernel.T)
    return np.stack(out)


class MotionSpectrumEmbedder(Embedder):
    """Embeds how the subject moves, not how it looks: spectra of its tracked path.

    The clip is reduced to the path of what moves (:func:`physinfer.tracking.track_motion`),
    turned into its principal axes (``u`` along the swing, ``v`` across it), and described
    by (1) the power spectrum of ``u`` on a log-frequency grid, smoothed at several widths
    and normalised to unit sum, (2) the spectrum of ``v`` on the same scale (the ratio tells
    the arc's curvature), and (3) the swing's amplitude in consecutive segments relative to
    the whole (its decay). Phase, the subject's place and size in the image, the camera's
    roll and every colour and texture leave it unchanged: a real video and a render of the
    same motion embed alike.

    Clips are read whole (up to ``max_seconds``; the first ``n_frames`` when set), so a
    simulation must span as long as its target: phenomena whose simulator takes
    ``duration_s`` and that set ``duration_from_target`` get that from the host.

    Args:
        config: Settings.
        model: Ignored (the factory signature).
        device: Ignored (numpy on CPU).
        n_frames: Frames read, overriding ``config.n_frames`` (``--embedder-frames``).
    """

    def __init__(
        self,
        *,
        config: MotionSpectrumConfig | None = None,
        model: str | None = None,
        device: str | None = None,
        n_frames: int | None = None,
    ) -> None:
        self.config = config or MotionSpectrumConfig()
        if n_frames is not None:
            self.config = replace(self.config, n_frames=int(n_frames))
        self.config.validate()
        self.fps, self.size = self.config.fps, self.config.size
        self.n_frames = self.config.n_frames or self.config.min_frames  # the fewest a clip needs
        self._grid = np.geomspace(self.config.f_min, self.config.f_max, self.config.n_freqs)

    @property
    def dimension(self) -> int:
        """Length of the embedding."""
        c = self.config
        return 2 * len(c.widths) * c.n_freqs + c.n_segments + 2 * c.n_times

    def track(self, clip: Clip, *, allow_shift: bool = False) -> MotionTrack:
        """The subject's path in ``clip`` at the embedder's frame rate and length
        (``allow_shift``: see :func:`physinfer.tracking.track_motion`)."""
        c = self.config
        clip = resample(clip, c.fps)
        if clip.n_frames < self.n_frames:
            raise UserInputError(
                f"the clip is too short: {clip.n_frames / c.fps:.2f} s; the motion embedder needs at least "
                f"{self.n_frames / c.fps:.2f} s"
            )
        keep = c.n_frames or int(round(c.max_seconds * c.fps))
        return track_motion(Clip(clip.frames[:keep], c.fps), allow_shift=allow_shift)

    #: ``--roi`` means "compare only this region": conditioning freezes the pixels outside it.
    compares_roi_only = True

    def embed(self, clip: Clip) -> np.ndarray:
        """Embed a clip; returns ``(2 · len(widths) · n_freqs + n_segments + 2 · n_times,)`` float32."""
        c = self.config
        try:
            track = self.track(clip)
        except NothingMoves:
            # A simulation whose motion no camera would see (a 1° swing of a long pendulum) is
            # an observation too: the embedding of stillness. A target that does not move is
            # refused before it is embedded (framing, the phenomenon's video estimate).
            return np.zeros(self.dimension, dtype=np.float32)
        u, v, _ = track.axes()
        scale = float(np.sqrt(np.mean(u**2)))
        if scale < 1e-6:
            return np.zeros(self.dimension, dtype=np.float32)
        spectra = smoothed_spectra(np.stack([u, v]) / scale, c.fps, self._grid, c.widths)  # (W, 2, F)
        spectra /= spectra[:, :1].sum(axis=-1, keepdims=True)  # u's spectrum sums to 1 at each width
        segments = np.array_split(u, c.n_segments)
        envelope = np.array([np.sqrt(np.mean(s**2)) for s in segments]) / scale
        weight = float(np.clip(3.0 - 2.0 * track.duration_s / c.short_s, 0.0, 1.0))
        times = np.linspace(0, len(u) - 1, c.n_times)
        path = np.concatenate([np.interp(times, np.arange(len(u)), x) for x in (u, v)]) / scale
        # Amplitudes, not powers (as grid_spectrum): distances grow about linearly with differences.
        return np.concatenate([np.sqrt(spectra).ravel() * 3.0, envelope, weight * path]).astype(np.float32)
