"""Freeze the static background of a prepared clip, as the renderer draws it: without noise.

A rendered clip's background does not change from frame to frame; a camera's does, by
sensor noise and compression flicker. An embedder that reads per-pixel temporal spectra
(the flag's SDN keeps each pixel's peak power *and* its peak frequency) sees that flicker
as signal: in a static pixel of a render the peak frequency is a constant, in a noisy one
it is random. :func:`freeze_static` replaces every pixel whose value never leaves its
temporal median by more than the noise would explain with that median, and leaves the
pixels the subject moves through alone. numpy only.
"""

from __future__ import annotations

from typing import Any

import numpy as np

NOISE_SIGMAS = 4.5
"""A pixel is static when its largest deviation from its temporal median, over frames and
channels, stays within this many noise standard deviations (180 Gaussian samples exceed
4.5 σ with probability ~0.1 %)."""

MIN_LEVEL = 24.0
"""The threshold is at least this many gray levels. Compression flicker is not Gaussian
(most pixels repeat exactly, a few jump at key frames, so σ reads 0): 24 levels froze the
background of H.264 CRF 35 clips and of noisy ones (σ ≈ 6) alike and kept the embedding of
clean renders where it was (8 and 16 left noise in, 40 began to freeze the flag; measured
on three held-out flags, docs/real-videos.md)."""

MAX_LEVEL = 64.0
"""The threshold never exceeds this many gray levels: a subject moving with less contrast
than that against itself would be frozen."""


def freeze_static(frames: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """Replace the static pixels of ``frames`` by their temporal median.

    Args:
        frames: ``(T, H, W, C)`` uint8.

    Returns:
        The frames with static pixels frozen, and ``{"noise_sigma": σ in gray levels (robust,
        from the median absolute deviation from the temporal median), "level": the largest
        deviation (gray levels) still counted as static, "static_fraction": share of pixels
        frozen}``.
    """
    if frames.shape[0] < 3:
        return frames, {"noise_sigma": 0.0, "level": 0.0, "static_fraction": 0.0}
    median = np.median(frames, axis=0).astype(np.uint8)
    deviation = np.abs(frames.astype(np.int16) - median.astype(np.int16))
    sigma = 1.4826 * float(np.median(deviation))
    largest = deviation.max(axis=(0, 3))
    level = min(MAX_LEVEL, max(MIN_LEVEL, NOISE_SIGMAS * sigma))
    static = largest <= level
    out = frames.copy()
    out[:, static] = median[static]
    return out, {
        "noise_sigma": round(sigma, 3),
        "level": round(float(level), 2),
        "static_fraction": round(float(static.mean()), 4),
    }
