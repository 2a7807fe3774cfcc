"""Where, when and at which frequencies a best-fit simulation disagrees with the target.

Both clips are reduced the same way (grayscale, common frame rate and length, centre crop
to a small square), and every pixel's intensity over time is treated as a signal. Per
pixel we take the Hann-windowed periodogram; per region of a ``grid × grid`` partition
of the image we then pool:

- the **motion power** (mean periodogram power above ``f_min``): how much moves there;
- the **dominant frequency** (the frequency of the pooled spectrum's peak): how fast;
- **band powers** in log-spaced bands: which part of the spectrum differs;
- the **non-stationarity** of the motion amplitude: the coefficient of variation of the
  RMS frame-to-frame change over ``n_segments`` consecutive segments (gusts make the
  amplitude come and go; a steady wind does not).

A region's discrepancy score adds the absolute log power ratio, the relative frequency
difference and the non-stationarity difference (the last two only where something moves:
at least a tenth of the busiest region's power), so the regions that disagree most come
first. Everything is numpy; nothing depends on the embedder, so the localisation reads
the same whatever embedding the refinement used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physinfer.types import Clip
from physinfer.video import center_crop_resize, resample, to_gray


@dataclass(frozen=True)
class LocaliseConfig:
    """Settings of :func:`spectral_maps` and :func:`localise`.

    Attributes:
        size: Side of the square grayscale image the clips are reduced to.
        grid: Regions per side.
        f_min: Lowest frequency counted as motion, Hz (below it: drift and lighting).
        n_bands: Log-spaced frequency bands between ``f_min`` and the Nyquist frequency.
        n_segments: Consecutive segments for the amplitude non-stationarity.
    """

    size: int = 64
    grid: int = 4
    f_min: float = 0.2
    n_bands: int = 4
    n_segments: int = 4

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if self.size < 8 or self.grid < 1 or self.size % self.grid:
            raise ValueError("size must be at least 8 and a multiple of grid")
        if self.f_min <= 0 or self.n_bands < 1 or self.n_segments < 2:
            raise ValueError("need f_min > 0, n_bands >= 1 and n_segments >= 2")


@dataclass(frozen=True)
class SpectralMaps:
    """Per-pixel and per-region spectral statistics of one clip.

    Attributes:
        fps: Frame rate of the analysed signal, Hz.
        freqs: ``(F,)`` frequencies of the periodogram, Hz.
        power: ``(S, S)`` per-pixel motion power (mean periodogram power above ``f_min``).
        dominant: ``(S, S)`` per-pixel frequency of the largest periodogram value above ``f_min``, Hz.
        region_spectrum: ``(G, G, F)`` mean periodogram per region.
        region_bands: ``(G, G, B)`` mean power per region and band.
        band_edges: ``(B + 1,)`` band edges, Hz.
        envelope: ``(G, G, n_segments)`` RMS frame-to-frame change per region and segment.
    """

    fps: float
    freqs: np.ndarray
    power: np.ndarray
    dominant: np.ndarray
    region_spectrum: np.ndarray
    region_bands: np.ndarray
    band_edges: np.ndarray
    envelope: np.ndarray

    def region_power(self) -> np.ndarray:
        """``(G, G)`` motion power per region."""
        return self.region_bands.mean(axis=-1)

    def region_dominant(self) -> np.ndarray:
        """``(G, G)`` frequency of each region's spectral peak (above ``f_min``), Hz."""
        return self.freqs[np.argmax(self.region_spectrum, axis=-1)]

    def nonstationarity(self) -> np.ndarray:
        """``(G, G)`` coefficient of variation of the motion amplitude over segments."""
        mean = self.envelope.mean(axis=-1)
        return self.envelope.std(axis=-1) / np.maximum(mean, 1e-12)


def prepare(clip: Clip, *, fps: float, n_frames: int, size: int) -> np.ndarray:
    """``(T, H, W, C)`` clip → ``(n_frames, size, size)`` float32 gray in ``[0, 1]``."""
    clip = resample(clip, fps)
    return center_crop_resize(to_gray(clip.frames[:n_frames]), size)


def common_format(clips: list[Clip]) -> tuple[float, int]:
    """The frame rate (lowest) and length (shortest, in frames at that rate) all clips share."""
    fps = min(c.fps for c in clips)
    n = min(int(round(c.n_frames * fps / c.fps)) for c in clips)
    return fps, n


def spectral_maps(clip: Clip, *, fps: float, n_frames: int, config: LocaliseConfig) -> SpectralMaps:
    """Compute the spectral maps of ``clip`` at ``fps`` over its first ``n_frames`` frames.

    Raises:
        ValueError: for fewer than 8 frames (no spectrum worth the name).
    """
    config.validate()
    if n_frames < 8:
        raise ValueError(f"need at least 8 frames to localise, got {n_frames}")
    video = prepare(clip, fps=fps, n_frames=n_frames, size=config.size).astype(np.float64)
    signals = video.transpose(1, 2, 0)  # (S, S, T)
    t = signals.shape[-1]
    x = (signals - signals.mean(axis=-1, keepdims=True)) * np.hanning(t)
    periodogram = np.abs(np.fft.rfft(x, axis=-1)) ** 2 / t
    freqs = np.fft.rfftfreq(t, d=1.0 / fps)
    motion = freqs >= config.f_min
    spectrum = np.where(motion, periodogram, 0.0)
    g, cell = config.grid, config.size // config.grid
    region_spectrum = spectrum.reshape(g, cell, g, cell, -1).mean(axis=(1, 3))
    edges = np.geomspace(config.f_min, fps / 2.0, config.n_bands + 1)
    band = np.digitize(freqs, edges) - 1
    bands = np.zeros((g, g, config.n_bands))
    for b in range(config.n_bands):
        sel = (band == b) | ((b == config.n_bands - 1) & (freqs == edges[-1]))
        if sel.any():
            bands[..., b] = region_spectrum[..., sel].mean(axis=-1)
    diffs = np.diff(signals, axis=-1) ** 2  # (S, S, T-1)
    segments = np.array_split(diffs, config.n_segments, axis=-1)
    envelope = np.stack(
        [np.sqrt(s.reshape(g, cell, g, cell, -1).mean(axis=(1, 3, 4))) for s in segments], axis=-1
    )
    return SpectralMaps(
        fps=float(fps),
        freqs=freqs,
        power=spectrum[..., motion].mean(axis=-1) if motion.any() else np.zeros(signals.shape[:2]),
        dominant=freqs[np.argmax(spectrum, axis=-1)],
        region_spectrum=region_spectrum,
        region_bands=bands,
        band_edges=edges,
        envelope=envelope,
    )


def _log_ratio(a: np.ndarray, b: np.ndarray, floor: float) -> np.ndarray:
    return np.log10((a + floor) / (b + floor))


def compare_regions(target: SpectralMaps, fit: SpectralMaps) -> list[dict]:
    """Per-region numbers of target vs fit, most discrepant first.

    Args:
        target: Maps of the target clip.
        fit: Maps of the best-fit simulation, on the same frame rate, length and grid.

    Returns:
        One dict per region: ``row``, ``col`` (0 = top/left), ``box`` (``[x0, y0, x1, y1]``
        as fractions of the analysed square), ``power_target``, ``power_fit``,
        ``log10_power_ratio`` (target over fit), ``freq_target_hz``, ``freq_fit_hz``,
        ``nonstationarity_target``, ``nonstationarity_fit``, ``band`` (``[lo, hi]`` Hz of
        the band whose power differs most), ``band_log10_ratio`` and ``score``.
    """
    g = target.region_bands.shape[0]
    floor = 1e-3 * max(float(target.region_power().max()), float(fit.region_power().max()), 1e-12)
    ratio = _log_ratio(target.region_power(), fit.region_power(), floor)
    band_ratio = _log_ratio(target.region_bands, fit.region_bands, floor)
    worst_band = np.argmax(np.abs(band_ratio), axis=-1)
    f_t, f_f = target.region_dominant(), fit.region_dominant()
    ns_t, ns_f = target.nonstationarity(), fit.nonstationarity()
    rel_freq = np.abs(f_t - f_f) / np.maximum(np.maximum(f_t, f_f), 1e-6)
    # Frequency and non-stationarity of a region where (almost) nothing moves are those of
    # pixel noise: only the power term speaks for such regions.
    moving = np.maximum(target.region_power(), fit.region_power()) >= 100.0 * floor
    score = np.abs(ratio) + np.where(moving, rel_freq + np.abs(ns_t - ns_f), 0.0)
    regions = []
    for r in range(g):
        for c in range(g):
            b = int(worst_band[r, c])
            regions.append(
                {
                    "row": r,
                    "col": c,
                    "box": [c / g, r / g, (c + 1) / g, (r + 1) / g],
                    "power_target": float(target.region_power()[r, c]),
                    "power_fit": float(fit.region_power()[r, c]),
                    "log10_power_ratio": float(ratio[r, c]),
                    "freq_target_hz": float(f_t[r, c]),
                    "freq_fit_hz": float(f_f[r, c]),
                    "nonstationarity_target": float(ns_t[r, c]),
                    "nonstationarity_fit": float(ns_f[r, c]),
                    "band": [float(target.band_edges[b]), float(target.band_edges[b + 1])],
                    "band_log10_ratio": float(band_ratio[r, c, b]),
                    "score": float(score[r, c]),
                }
            )
    return sorted(regions, key=lambda d: -d["score"])


def global_summary(target: SpectralMaps, fit: SpectralMaps) -> dict:
    """Whole-image numbers: band powers, amplitude over time, dominant frequency.

    Returns:
        ``bands`` (per band: edges, target and fit power, log10 ratio), ``envelope_target``
        and ``envelope_fit`` (per segment, whole image), ``nonstationarity_target`` /
        ``_fit``, ``freq_target_hz`` / ``_fit_hz`` (peak of the whole-image spectrum) and
        ``worst_band`` (the band whose power differs most).
    """
    t_bands, f_bands = target.region_bands.mean(axis=(0, 1)), fit.region_bands.mean(axis=(0, 1))
    floor = 1e-3 * max(float(t_bands.max()), float(f_bands.max()), 1e-12)
    ratios = _log_ratio(t_bands, f_bands, floor)
    bands = [
        {
            "band": [float(target.band_edges[b]), float(target.band_edges[b + 1])],
            "power_target": float(t_bands[b]),
            "power_fit": float(f_bands[b]),
            "log10_ratio": float(ratios[b]),
        }
        for b in range(len(t_bands))
    ]
    env_t, env_f = target.envelope.mean(axis=(0, 1)), fit.envelope.mean(axis=(0, 1))

    def cv(e: np.ndarray) -> float:
        return float(e.std() / max(e.mean(), 1e-12))

    spec_t, spec_f = target.region_spectrum.mean(axis=(0, 1)), fit.region_spectrum.mean(axis=(0, 1))
    return {
        "bands": bands,
        "worst_band": bands[int(np.argmax(np.abs(ratios)))]["band"],
        "envelope_target": [float(v) for v in env_t],
        "envelope_fit": [float(v) for v in env_f],
        "nonstationarity_target": cv(env_t),
        "nonstationarity_fit": cv(env_f),
        "freq_target_hz": float(target.freqs[int(np.argmax(spec_t))]),
        "freq_fit_hz": float(fit.freqs[int(np.argmax(spec_f))]),
    }


def localise(target: Clip, fit: Clip, config: LocaliseConfig | None = None) -> tuple[dict, SpectralMaps, SpectralMaps]:
    """Compare a target clip with a best-fit clip.

    Args:
        target: The measured clip ``(T, H, W, 3)``.
        fit: The simulation at the best-fit θ, rendered with the target's ζ.
        config: Settings (defaults suit clips of 2–4 s).

    Returns:
        ``(numbers, target_maps, fit_maps)``; ``numbers`` holds ``regions`` (most
        discrepant first, see :func:`compare_regions`) and ``global`` (see
        :func:`global_summary`).
    """
    config = config or LocaliseConfig()
    fps, n = common_format([target, fit])
    t_maps = spectral_maps(target, fps=fps, n_frames=n, config=config)
    f_maps = spectral_maps(fit, fps=fps, n_frames=n, config=config)
    numbers = {"regions": compare_regions(t_maps, f_maps), "global": global_summary(t_maps, f_maps)}
    return numbers, t_maps, f_maps
