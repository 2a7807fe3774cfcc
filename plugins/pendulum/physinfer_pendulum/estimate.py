"""What a pendulum video tells before any simulation: its period, hence its length.

The tracked path's dominant frequency ``f`` (zero-padded spectrum, parabolic peak) gives the
small-angle length ``L₀ = g / (2π f)²``. A larger swing has a longer period, so the true
length lies between ``L₀`` over the period factor of the largest amplitude in θ's range and
a little above ``L₀``: :func:`video_estimate` returns that interval as the search box.
"""

from __future__ import annotations

import numpy as np

from physinfer.types import Clip

G = 9.81
#: Relative slack on both ends of the length box (the frequency read from a few swings).
SLACK = 0.06


def period_factor(amplitude_deg: float) -> float:
    """``T(amplitude) / T₀`` of an undamped pendulum (the series to θ⁴)."""
    theta = np.radians(amplitude_deg)
    return float(1 + theta**2 / 16 + 11 * theta**4 / 3072)


def dominant_frequency(u: np.ndarray, fps: float) -> float:
    """The strongest frequency of ``u`` in Hz (zero-padded, parabolic peak interpolation)."""
    n = len(u)
    n_fft = max(1 << 15, 1 << int(np.ceil(np.log2(16 * n))))
    power = np.abs(np.fft.rfft((u - u.mean()) * np.hanning(n), n_fft)) ** 2
    k = int(np.argmax(power[1:])) + 1
    if 1 <= k < len(power) - 1:
        a, b, c = np.log(power[k - 1 : k + 2] + 1e-300)
        k = k + 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) < 0 else k
    return float(k * fps / n_fft)


def video_estimate(clip: Clip, max_amplitude_deg: float = 60.0) -> dict[str, tuple[float, float, float]]:
    """``{"length": (L₀, low, high)}`` from the clip's tracked period (the motion embedder's track)."""
    from physinfer.embedders import MotionSpectrumEmbedder
    from physinfer.errors import UserInputError
    from physinfer.tracking import half_swings

    embedder = MotionSpectrumEmbedder()
    u, _, _ = embedder.track(clip).axes()
    crossings, _ = half_swings(u, embedder.fps)
    if crossings < 2:
        raise UserInputError(
            f"the clip ({clip.n_frames / clip.fps:.2f} s) is too short to see a full swing: the bob crosses "
            f"the middle of its path {crossings} time(s); give a clip of at least two swings"
        )
    frequency = dominant_frequency(u, embedder.fps)
    small_angle = G / (2 * np.pi * frequency) ** 2
    low = small_angle / period_factor(max_amplitude_deg) ** 2 * (1 - SLACK)
    return {"length": (small_angle, low, small_angle * (1 + SLACK))}
