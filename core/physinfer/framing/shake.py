"""Camera shake: each frame's global shift against a reference frame by phase correlation on
the static background, refined to 1/20 px by a local upsampled DFT (Guizar-Sicairos et al.
2008), and the frames steadied by undoing it."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from physinfer.errors import UserInputError
from physinfer.framing.region import find_moving_box, motion_energy
from physinfer.framing.settings import Box

MIN_SHAKE_RMS_PX = 0.25
"""Shifts whose rms is below this many pixels are not compensated (only blur would result)."""


def rms_about_mean(shifts: np.ndarray) -> float:
    """RMS length of ``(T, 2)`` shifts about their mean."""
    centred = shifts - shifts.mean(axis=0)
    return float(np.sqrt((centred**2).sum(axis=1).mean()))


def measure_shake(
    gray: np.ndarray, reference: int, roi: Box | None, min_rms: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """Camera shifts of every frame, and the steadied frames when compensating them helps.

    Pass 1 registers whole frames (or all but ``roi``) to whole pixels to find the moving
    region roughly; pass 2 registers the background with that region masked out, to 1/20
    pixel. The shifts are compensated when their rms reaches ``min_rms`` (analysis pixels)
    and the compensated background changes less than the raw one (a featureless sky can
    give spurious peaks).

    Returns:
        ``(T, 2)`` shifts in analysis pixels, and the steadied frames or ``None`` (not
        worth compensating).
    """
    first = estimate_shifts(gray, reference, background_weight(gray.shape[1:], roi), subpixel=False)
    box = roi
    if box is None:
        steady, valid = shift_frames(gray, first)
        try:
            box = find_moving_box(motion_energy(steady), valid)[0]
        except UserInputError:
            box = None  # said later, on the steadied frames
    weight = background_weight(gray.shape[1:], box)
    shifts = estimate_shifts(gray, reference, weight)
    if rms_about_mean(shifts) < min_rms:
        return shifts, None
    steady = shift_frames(gray, shifts)[0]
    helps = background_change(steady, reference, weight) < 0.8 * background_change(
        gray, reference, weight
    )
    return shifts, steady if helps else None


def background_weight(shape: tuple[int, int], box: Sequence[float] | None) -> np.ndarray:
    """Weights ``(h, w)`` for registration: a Tukey window, the moving box (grown) faded out.

    Soft edges keep the mask's own outline from pulling the correlation towards zero shift.
    """
    from scipy.ndimage import gaussian_filter

    h, w = shape
    weight = np.outer(_tukey(h), _tukey(w)).astype(np.float32)
    if box is not None:
        x, y, bw, bh = box
        grow = 0.15 * max(bw, bh) + 2
        mask = np.ones((h, w), np.float32)
        mask[
            max(0, int(y - grow)) : min(h, int(math.ceil(y + bh + grow))),
            max(0, int(x - grow)) : min(w, int(math.ceil(x + bw + grow))),
        ] = 0.0
        weight *= gaussian_filter(mask, sigma=max(2.0, 0.01 * max(h, w)))
    return weight


def _tukey(n: int, alpha: float = 0.2) -> np.ndarray:
    """Tukey window of length ``n``: flat, with cosine tapers over ``alpha / 2`` of each end."""
    x = np.linspace(0.0, 1.0, n)
    taper = alpha / 2
    out = np.ones(n)
    low, high = x < taper, x > 1 - taper
    out[low] = 0.5 * (1 - np.cos(np.pi * x[low] / taper))
    out[high] = 0.5 * (1 - np.cos(np.pi * (1 - x[high]) / taper))
    return out


def estimate_shifts(
    gray: np.ndarray, reference: int, weight: np.ndarray, *, subpixel: bool = True
) -> np.ndarray:
    """Global shift ``(dx, dy)`` of each frame against frame ``reference`` by phase correlation.

    Frame ``t`` shows the reference's content at ``p + shift[t]``.

    Args:
        gray: ``(T, h, w)`` float32 frames.
        reference: Index of the reference frame.
        weight: ``(h, w)`` weights (0 where the moving subject is).
        subpixel: Refine the integer peak to 1/20 pixel (:func:`_refine_peak`).

    Returns:
        ``(T, 2)`` float64 shifts in analysis pixels.
    """
    ref_spectrum = np.conj(np.fft.rfft2(_weighted(gray[reference], weight)))
    shifts = np.zeros((len(gray), 2))
    h, w = gray.shape[1:]
    for t, frame in enumerate(gray):
        if t == reference:
            continue
        cross = np.fft.rfft2(_weighted(frame, weight)) * ref_spectrum
        cross /= np.maximum(np.abs(cross), 1e-12)
        surface = np.fft.irfft2(cross, s=(h, w))
        peak_y, peak_x = np.unravel_index(int(np.argmax(surface)), surface.shape)
        dy = float(peak_y - h if peak_y > h // 2 else peak_y)
        dx = float(peak_x - w if peak_x > w // 2 else peak_x)
        if subpixel:
            for radius, step in ((1.0, 0.25), (0.25, 0.05)):  # coarse, then fine
                dy, dx = _refine_peak(cross, w, dy, dx, radius, step)
        shifts[t] = (dx, dy)
    return shifts


def _weighted(frame: np.ndarray, weight: np.ndarray) -> np.ndarray:
    mean = float((frame * weight).sum() / max(weight.sum(), 1e-9))
    return (frame - mean) * weight


def _refine_peak(
    half: np.ndarray, width: int, y: float, x: float, radius: float, step: float
) -> tuple[float, float]:
    """The maximum of the inverse DFT of a real image's spectrum on a grid around ``(y, x)``.

    The inverse DFT is evaluated only at the grid's points, ``±radius`` in steps of
    ``step`` pixels, by small matrix products (an upsampled DFT, Guizar-Sicairos et al.
    2008) rather than by zero-padding the whole FFT. ``half`` is the ``rfft2`` half
    ``(h, width // 2 + 1)``; the other half, by Hermitian symmetry, doubles the real part
    of every column but the first (and the Nyquist column of an even width).
    """
    h, n_cols = half.shape
    offsets = np.arange(-radius, radius + 1e-9, step)
    double = np.full(n_cols, 2.0)
    double[0] = 1.0
    if width % 2 == 0:
        double[-1] = 1.0
    row_phase = 2 * np.pi * np.outer(y + offsets, np.fft.fftfreq(h) * h) / h
    col_phase = 2 * np.pi * np.outer(np.arange(n_cols), x + offsets) / width
    # Complex products as real ones: OpenBLAS's complex GEMM was 50-100x slower here.
    rows_re, rows_im = np.cos(row_phase).astype(np.float32), np.sin(row_phase).astype(np.float32)
    spec = half * double
    spec_re, spec_im = spec.real.astype(np.float32), spec.imag.astype(np.float32)
    mid_re = rows_re @ spec_re - rows_im @ spec_im
    mid_im = rows_re @ spec_im + rows_im @ spec_re
    local = mid_re @ np.cos(col_phase).astype(np.float32) - mid_im @ np.sin(col_phase).astype(
        np.float32
    )
    iy, ix = np.unravel_index(int(np.argmax(local)), local.shape)
    return float(y + offsets[iy]), float(x + offsets[ix])


def background_change(gray: np.ndarray, reference: int, weight: np.ndarray) -> float:
    """Weighted mean absolute difference of every frame from the reference (the background's unrest)."""
    total = sum(float((np.abs(frame - gray[reference]) * weight).sum()) for frame in gray)
    return total / max(float(weight.sum()) * len(gray), 1e-9)


def shift_frames(gray: np.ndarray, shifts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undo the shifts (bilinear) and the mask of pixels that stayed inside every frame.

    Returns:
        Steadied ``(T, h, w)`` frames and a ``(h, w)`` bool mask of valid pixels.
    """
    from scipy.ndimage import shift as nd_shift

    h, w = gray.shape[1:]
    if not np.any(shifts):
        return gray, valid_mask((h, w), shifts)
    steady = np.empty_like(gray)
    whole = bool(np.all(shifts == np.round(shifts)))
    for t, (dx, dy) in enumerate(shifts):
        if dx == dy == 0:
            steady[t] = gray[t]
        elif whole:  # wrapped pixels fall in the invalid border
            steady[t] = np.roll(gray[t], (-int(dy), -int(dx)), axis=(0, 1))
        else:
            steady[t] = nd_shift(gray[t], (-dy, -dx), order=1, mode="nearest")
    return steady, valid_mask((h, w), shifts)


def valid_mask(shape: tuple[int, int], shifts: np.ndarray) -> np.ndarray:
    """``(h, w)`` bool: the pixels that stay inside every frame under ``shifts`` ``(T, 2)``."""
    h, w = shape
    valid = np.ones((h, w), bool)
    if not np.any(shifts):
        return valid
    mx, my = np.ceil(np.abs(shifts).max(axis=0)).astype(int) + 1
    valid[:my] = valid[h - my :] = False
    valid[:, :mx] = valid[:, w - mx :] = False
    return valid
