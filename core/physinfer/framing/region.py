"""The moving region: motion energy of the steadied frames, its background statistics, the
strongest connected region (hysteresis thresholding), and whether it leaves the frame."""

from __future__ import annotations

import math

import numpy as np

from physinfer.errors import UserInputError
from physinfer.framing.settings import Box


def motion_energy(steady: np.ndarray) -> np.ndarray:
    """Mean absolute difference of consecutive frames, smoothed: ``(h, w)`` float32."""
    from scipy.ndimage import gaussian_filter

    energy = np.zeros(steady.shape[1:], np.float64)
    for t in range(1, len(steady)):
        energy += np.abs(steady[t] - steady[t - 1])
    energy /= max(1, len(steady) - 1)
    return gaussian_filter(energy, sigma=_smoothing(steady.shape[1:])).astype(np.float32)


def _smoothing(shape: tuple[int, ...]) -> float:
    return max(1.0, 0.006 * max(shape))


def energy_stats(energy: np.ndarray, valid: np.ndarray) -> dict[str, float]:
    """Background level, spread and peak of a motion-energy map, and the hysteresis levels.

    The background is the median of the valid pixels, its spread 1.4826 × their MAD; the
    seed level lies at 30 % of the way from the background to the peak, the grow level at
    8 % (and at least six spreads above the background).
    """
    values = energy[valid]
    background = float(np.median(values))
    spread = max(1.4826 * float(np.median(np.abs(values - background))), 1e-6)
    peak = float(values.max())
    return {
        "background": background,
        "spread": spread,
        "peak": peak,
        "contrast": peak / max(background, 1e-6),
        "high": background + 0.3 * (peak - background),
        "low": background + max(0.08 * (peak - background), 6.0 * spread),
        "significance": (peak - background) / spread,
    }


#: A region stands out when its peak exceeds the background by this many spreads...
MIN_SIGNIFICANCE = 12.0
#: ...and this many times the background level.
MIN_CONTRAST = 3.0


def find_moving_box(energy: np.ndarray, valid: np.ndarray) -> tuple[Box, dict[str, float]]:
    """The bounding box of the strongest connected region of motion energy.

    Pixels above the seed level start regions, which grow through pixels above the grow
    level (8-connected); the region holding the most energy above the background wins.

    Returns:
        ``(x, y, w, h)`` in analysis pixels (edges, so ``w`` counts pixels) and the
        statistics of :func:`energy_stats`.

    Raises:
        UserInputError: when no region stands out from the background.
    """
    from scipy import ndimage

    stats = energy_stats(energy, valid)
    if stats["significance"] < MIN_SIGNIFICANCE or stats["contrast"] < MIN_CONTRAST:
        raise UserInputError(
            "no moving region found: looked for a region whose frame-to-frame change stands out from "
            f"the rest of the frame, but the strongest is {stats['contrast']:.1f}x the background's level "
            f"and {stats['significance']:.0f} spreads above it (needs {MIN_CONTRAST:g}x and "
            f"{MIN_SIGNIFICANCE:g}); give the subject's region with --roi x,y,w,h (input pixels)"
        )
    grown = (energy > stats["low"]) & valid
    labels, count = ndimage.label(grown, structure=np.ones((3, 3)))
    seeded = np.unique(labels[(energy > stats["high"]) & grown])
    seeded = seeded[seeded > 0]
    weights = ndimage.sum_labels(energy - stats["background"], labels, index=seeded)
    best = int(seeded[int(np.argmax(weights))])
    rows, cols = np.nonzero(labels == best)
    box = (
        float(cols.min()),
        float(rows.min()),
        float(cols.max() + 1 - cols.min()),
        float(rows.max() + 1 - rows.min()),
    )
    return box, stats


def edge_fraction(steady: np.ndarray, valid: np.ndarray, box: Box, level: float) -> float:
    """Share of frames whose motion reaches the frame's edge where the box touches it.

    Only edges the box touches (within 1.5 % of the frame's longer side) count; a frame
    counts when a pixel of the border strip along the box changes by more than ``level``.
    """
    from scipy.ndimage import gaussian_filter

    h, w = valid.shape
    rows, cols = np.nonzero(valid)
    top, bottom, left, right = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    tol = max(2, int(round(0.015 * max(h, w))))
    x, y, bw, bh = box
    strip = np.zeros((h, w), bool)
    y0, y1, x0, x1 = int(y), int(math.ceil(y + bh)), int(x), int(math.ceil(x + bw))
    if x - left <= tol:
        strip[y0:y1, left : left + tol] = True
    if right - (x + bw) <= tol:
        strip[y0:y1, right - tol : right] = True
    if y - top <= tol:
        strip[top : top + tol, x0:x1] = True
    if bottom - (y + bh) <= tol:
        strip[bottom - tol : bottom, x0:x1] = True
    if not strip.any():
        return 0.0
    sigma = _smoothing((h, w))
    hits = [
        bool((gaussian_filter(np.abs(steady[t] - steady[t - 1]), sigma)[strip] > level).any())
        for t in range(1, len(steady))
    ]
    return float(np.mean(hits))
