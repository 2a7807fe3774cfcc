"""Prepare real footage for refinement: find the moving subject, steady the camera, frame it.

A phone video of a flag is not what a renderer makes: the flag sits somewhere in a wide
frame, the camera shakes, the frame rate is 30 or 60 fps. :func:`prepare_clip` turns it
into a clip framed as the phenomenon's renderer frames its subject, so that a refinement
compares like with like:

1. **Camera shake**: each frame's global shift against the middle frame, by phase
   correlation on the static background (the moving region masked out), refined to
   1/20 px by a local upsampled DFT (Guizar-Sicairos et al. 2008). A shake under
   :data:`MIN_SHAKE_RMS_PX` is left alone (resampling would only blur).
2. **The moving region**: the mean absolute difference of consecutive steadied frames
   (motion energy), smoothed, thresholded relative to its own distribution (median and
   MAD of the map; seeds at a fraction of the peak, grown down to a lower level, as
   hysteresis thresholding does), the strongest connected component's bounding box.
3. **Framing**: the phenomenon's rule maps that box to the square its renderer frames
   (:attr:`physinfer.roles.Phenomenon.framing`; :func:`default_framing` otherwise).
4. **Crop, scale, trim, resample**: every frame is cut at the square moved by its shift
   (sub-pixel, Pillow's bilinear resize with a box), scaled to ``size`` × ``size``, the
   kept span trimmed, the static background frozen (noise and compression flicker
   removed where nothing moves, :mod:`physinfer.static_background`), and the frames
   resampled to ``fps`` (:func:`physinfer.video.resample`).

Everything is reported in a :class:`PreparedClip` (box and square in the input's pixels,
per-frame shifts, shake and residual shake in pixels, frames kept, warnings), and
:func:`save_overlay` draws the box and the square on a frame for the user to check.
Refuses, with one line each: a static video, a video in which nothing stands out as
moving (with the ``--roi`` way out), a subject that leaves the frame for most of the
clip, a region of interest outside the frame. numpy, scipy and Pillow only.

For the refinement workflows (``refine``/``diagnose``/``infer``): call
``prepare_clip(read_video(path, fps), framing=phenomenon.framing or default_framing,
settings=PrepareSettings(size=embedder.size, fps=embedder.fps))`` and refine against
``result.clip``; record ``result.to_dict()`` in the run.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.types import Clip

Box = tuple[float, float, float, float]
"""``(x, y, w, h)`` in pixels: left, top, width, height."""

FramingRule = Callable[[Box], Box]
"""Maps the moving region's box to the square ``(x, y, side, side)`` a renderer frames."""

DEFAULT_MARGIN = 0.15
"""Margin of :func:`default_framing` on each side, in units of the box's longer side."""

MIN_SHAKE_RMS_PX = 0.25
"""Shifts whose rms is below this many pixels are not compensated (only blur would result)."""

ANALYSIS_SIDE = 640
"""Longer side in pixels of the grayscale copy the analysis runs on (a 1920×1080 video is
analysed at 640×360; shifts are measured to 1/20 of its pixel)."""


def default_framing(box: Box) -> Box:
    """The generic framing: a square centred on the box, its longer side plus a margin.

    Args:
        box: ``(x, y, w, h)`` of the moving region.

    Returns:
        ``(x, y, side, side)`` with ``side = max(w, h) · (1 + 2 · DEFAULT_MARGIN)``.
    """
    x, y, w, h = box
    side = max(w, h) * (1.0 + 2.0 * DEFAULT_MARGIN)
    return (x + w / 2 - side / 2, y + h / 2 - side / 2, side, side)


@dataclass(frozen=True)
class PrepareSettings:
    """Settings of :func:`prepare_clip`.

    Attributes:
        size: Side in pixels of the square output frames (the embedder's input size).
        fps: Frame rate of the output (the embedder's); ``None`` keeps the input's.
        roi: ``(x, y, w, h)`` in input pixels: the region the subject moves in, used
            instead of the one found (framed by the same rule).
        start_s: Seconds trimmed from the start.
        duration_s: Seconds kept from ``start_s`` (``None``: to the end).
        stabilise: Measure and remove global camera shake.
        edge_error_fraction: Refuse the clip when the moving region reaches the edge of
            the frame in more than this share of its frames (the subject leaves the
            frame); a smaller share is a warning.
        freeze_background: Replace the pixels that never change by more than noise and
            compression flicker with their temporal median, as a renderer draws a static
            background (:func:`physinfer.static_background.freeze_static`).
    """

    size: int = 224
    fps: float | None = None
    roi: Box | None = None
    start_s: float = 0.0
    duration_s: float | None = None
    stabilise: bool = True
    edge_error_fraction: float = 0.5
    freeze_background: bool = True

    def validate(self) -> None:
        """Raise :class:`UserInputError` naming the first bad value."""
        if not 8 <= self.size <= 4096:
            raise UserInputError(f"--size {self.size}: give a side of 8 to 4096 pixels")
        if self.fps is not None and not (math.isfinite(self.fps) and self.fps > 0):
            raise UserInputError(
                f"output frame rate {self.fps}: give a positive number of frames per second"
            )
        if not (math.isfinite(self.start_s) and self.start_s >= 0):
            raise UserInputError(f"--start {self.start_s}: give a time in seconds >= 0")
        if self.duration_s is not None and not (
            math.isfinite(self.duration_s) and self.duration_s > 0
        ):
            raise UserInputError(f"--duration {self.duration_s}: give a positive number of seconds")
        if not 0 < self.edge_error_fraction <= 1:
            raise UserInputError(
                f"edge_error_fraction={self.edge_error_fraction}: give a share in (0, 1]"
            )


@dataclass(frozen=True)
class PreparedClip:
    """What :func:`prepare_clip` made and found.

    Attributes:
        clip: The prepared clip, ``(T', size, size, 3)`` uint8 at ``fps_out``.
        box: ``(x, y, w, h)`` of the moving region (or the given roi) in input pixels,
            in the coordinates of the reference (middle kept) frame.
        square: ``(x, y, side, side)`` cropped, in input pixels; it may reach beyond the
            frame (see ``padded``).
        roi_source: ``"found"`` or ``"given"``.
        shifts: ``(T, 2)`` camera shift ``(dx, dy)`` in input pixels of each kept input
            frame against the reference frame, as measured (compensated when
            ``stabilised``).
        shake_rms_px: RMS of the measured shifts about their mean, in input pixels.
        residual_rms_px: RMS shift left after compensation, re-measured on the steadied
            frames, in input pixels.
        stabilised: Whether the shifts were compensated.
        fps_in: Frame rate of the input.
        fps_out: Frame rate of the output.
        frames_kept: ``(first, stop)`` input frame indices kept by the trim.
        input_size: ``(H, W)`` of the input frames.
        padded: The square reached beyond the frame; the outside was filled with the
            nearest edge pixels.
        edge_fraction: Share of frames in which the moving region reached the frame's edge.
        contrast: Peak motion energy over the background's median (how clearly the
            subject stands out; 1 = not at all).
        static: What freezing the static background did (``noise_sigma``, ``level``,
            ``static_fraction``; empty when it was off).
        warnings: Sentences for the user.
        seconds: Wall time of the whole preparation.
        preview: ``(H, W, 3)`` uint8 reference frame, for :func:`save_overlay`.
        energy: ``(h, w)`` float32 motion-energy map at analysis resolution.
    """

    clip: Clip
    box: Box
    square: Box
    roi_source: str
    shifts: np.ndarray
    shake_rms_px: float
    residual_rms_px: float
    stabilised: bool
    fps_in: float
    fps_out: float
    frames_kept: tuple[int, int]
    input_size: tuple[int, int]
    padded: bool
    edge_fraction: float
    contrast: float
    static: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    seconds: float = 0.0
    preview: np.ndarray = field(default_factory=lambda: np.zeros((1, 1, 3), np.uint8), repr=False)
    energy: np.ndarray = field(default_factory=lambda: np.zeros((1, 1), np.float32), repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly summary (no frames)."""
        return {
            "box": [round(v, 2) for v in self.box],
            "square": [round(v, 2) for v in self.square],
            "roi_source": self.roi_source,
            "input_size": list(self.input_size),
            "fps_in": self.fps_in,
            "fps_out": self.fps_out,
            "frames_kept": list(self.frames_kept),
            "n_frames_out": self.clip.n_frames,
            "size": self.clip.size[0],
            "shake": {
                "rms_px": round(self.shake_rms_px, 3),
                "residual_rms_px": round(self.residual_rms_px, 3),
                "stabilised": self.stabilised,
                "shifts_px": (np.round(self.shifts, 3) + 0.0).tolist(),
            },
            "padded": self.padded,
            "edge_fraction": round(self.edge_fraction, 3),
            "contrast": round(self.contrast, 2),
            "static_background": self.static or None,
            "warnings": list(self.warnings),
            "seconds": round(self.seconds, 3),
        }


def prepare_clip(
    clip: Clip, *, framing: FramingRule | None = None, settings: PrepareSettings | None = None
) -> PreparedClip:
    """Find the moving subject, steady the camera, crop to the framing, scale and resample.

    Args:
        clip: The input video ``(T, H, W, 3)`` uint8 at its fps.
        framing: The phenomenon's framing rule (:func:`default_framing` when ``None``).
        settings: See :class:`PrepareSettings`.

    Returns:
        The prepared clip and what was found (:class:`PreparedClip`).

    Raises:
        UserInputError: bad settings, a roi outside the frame, a trim that keeps fewer
            than two frames, a static video, no moving region, a subject that leaves the
            frame in more than ``edge_error_fraction`` of the frames.
    """
    from threadpoolctl import threadpool_limits

    # The analysis is many small matrix products; on a loaded 2-core machine OpenBLAS's
    # second thread made them 15x slower (13 ms instead of 0.8 ms each).
    with threadpool_limits(1):
        return _prepare(clip, framing or default_framing, settings or PrepareSettings())


def _prepare(clip: Clip, framing: FramingRule, settings: PrepareSettings) -> PreparedClip:
    import time

    t0 = time.perf_counter()
    settings.validate()
    height, width = clip.size
    if settings.roi is not None:
        check_roi(settings.roi, (height, width))
    first, stop = trim_range(clip, settings.start_s, settings.duration_s)
    frames = clip.frames[first:stop]
    gray, scale = analysis_frames(frames)
    check_not_static(gray)
    reference = len(gray) // 2

    roi_a = None if settings.roi is None else tuple(v * scale for v in settings.roi)
    measured, steadied = np.zeros((len(gray), 2)), None
    if settings.stabilise:
        measured, steadied = measure_shake(gray, reference, roi_a, MIN_SHAKE_RMS_PX * scale)
    shake_rms = rms_about_mean(measured) / scale
    stabilised = steadied is not None
    applied = measured if stabilised else np.zeros_like(measured)
    steady = steadied if steadied is not None else gray
    valid = valid_mask(gray.shape[1:], applied)
    if valid.mean() < 0.25:  # a pan, not a shake: too little of the frame stays in view
        raise UserInputError(
            f"the camera moves by up to {np.abs(applied).max() / scale:.0f} px: too much to steady (a pan?); "
            "use footage from a camera held still, or --no-stabilise"
        )
    energy = motion_energy(steady)
    if roi_a is None:
        box_a, stats = find_moving_box(energy, valid)
    else:
        box_a, stats = roi_a, energy_stats(energy, valid)
    residual = shake_rms
    if stabilised:
        weight = background_weight(gray.shape[1:], box_a)
        residual = rms_about_mean(estimate_shifts(steady, reference, weight)) / scale
    edge = edge_fraction(steady, valid, box_a, stats["low"]) if roi_a is None else 0.0
    warnings = []
    if edge > settings.edge_error_fraction:
        raise UserInputError(
            f"the moving region reaches the edge of the frame in {edge:.0%} of the frames: the subject "
            "leaves the frame, so how the renderer would frame it cannot be found; use footage that shows "
            "it whole, or give --roi x,y,w,h (input pixels) to frame it yourself"
        )
    if edge > 0:
        warnings.append(f"the moving region reaches the frame's edge in {edge:.0%} of the frames")

    box = settings.roi if settings.roi is not None else tuple(v / scale for v in box_a)
    square = framing(box)
    check_square(square)
    cropped, padded = crop_square(frames, square, applied / scale, settings.size)
    if padded:
        warnings.append(
            "the framing reaches beyond the frame; the outside was filled with edge pixels"
        )
    static: dict[str, float] = {}
    if settings.freeze_background:
        from physinfer.static_background import freeze_static

        cropped, static = freeze_static(cropped)
    out = Clip(cropped, clip.fps)
    if settings.fps is not None:
        from physinfer.video import resample

        out = resample(out, settings.fps)
    return PreparedClip(
        clip=out,
        box=tuple(float(v) for v in box),  # type: ignore[arg-type]
        square=tuple(float(v) for v in square),  # type: ignore[arg-type]
        roi_source="given" if settings.roi is not None else "found",
        shifts=measured / scale,
        shake_rms_px=float(shake_rms),
        residual_rms_px=float(residual),
        stabilised=bool(stabilised),
        fps_in=float(clip.fps),
        fps_out=float(out.fps),
        frames_kept=(first, stop),
        input_size=(height, width),
        padded=padded,
        edge_fraction=float(edge),
        contrast=float(stats["contrast"]),
        static=static,
        warnings=tuple(warnings),
        seconds=time.perf_counter() - t0,
        preview=frames[reference],
        energy=energy,
    )


# ------------------------------------------------------------------------ checks


def check_roi(roi: Sequence[float], size: tuple[int, int]) -> None:
    """Refuse a region of interest that is not inside the frame ``size = (H, W)``."""
    height, width = size
    if len(roi) != 4 or not all(math.isfinite(v) for v in roi):
        raise UserInputError(f"--roi {roi}: give x,y,w,h (four numbers, input pixels)")
    x, y, w, h = roi
    if w < 4 or h < 4 or x < 0 or y < 0 or x + w > width or y + h > height:
        raise UserInputError(
            f"--roi {','.join(f'{v:g}' for v in roi)} is not inside the {width}×{height} frame: "
            f"give x,y >= 0, w,h >= 4 and x+w <= {width}, y+h <= {height}"
        )


def check_square(square: Box) -> None:
    """Refuse a framing rule's square that is not a finite, positive square."""
    x, y, w, h = square
    if not all(math.isfinite(v) for v in square) or w <= 1 or abs(w - h) > 1e-6 * max(w, 1.0):
        raise ValueError(f"a framing rule must return a square (x, y, side, side), got {square}")


def trim_range(clip: Clip, start_s: float, duration_s: float | None) -> tuple[int, int]:
    """Input frame indices ``[first, stop)`` kept by the trim; at least two frames."""
    first = int(round(start_s * clip.fps))
    stop = (
        clip.n_frames
        if duration_s is None
        else min(clip.n_frames, first + int(round(duration_s * clip.fps)))
    )
    if stop - first < 2:
        raise UserInputError(
            f"the trim keeps {max(0, stop - first)} frame(s) of {clip.n_frames} "
            f"({clip.duration:.2f} s at {clip.fps:g} fps); keep at least two (check --start/--duration)"
        )
    return first, stop


def check_not_static(gray: np.ndarray) -> None:
    """Refuse a video whose frames do not change (a still image, or a paused recording)."""
    changes = np.abs(np.diff(gray, axis=0)).mean(axis=(1, 2)) * 255.0
    if changes.max() < 0.05:
        raise UserInputError(
            f"the video is static: no frame differs from the one before by more than {changes.max():.3f} "
            "gray levels on average; prepare needs footage in which the subject moves"
        )


# ------------------------------------------------------------------- analysis frames


def analysis_frames(frames: np.ndarray, side: int = ANALYSIS_SIDE) -> tuple[np.ndarray, float]:
    """Grayscale float32 frames shrunk so the longer side is at most ``side`` pixels.

    Returns:
        ``(T, h, w)`` luma in [0, 1] and the scale factor (analysis px per input px).
    """
    from PIL import Image

    from physinfer.video import to_gray

    height, width = frames.shape[1:3]
    scale = min(1.0, side / max(height, width))
    h, w = max(8, int(round(height * scale))), max(8, int(round(width * scale)))
    out = np.empty((len(frames), h, w), dtype=np.float32)
    for index, frame in enumerate(frames):
        small = (
            frame
            if (h, w) == (height, width)
            else np.asarray(
                Image.fromarray(frame).resize((w, h), Image.Resampling.BILINEAR, reducing_gap=2.0)
            )
        )
        out[index] = to_gray(small[None])[0]
    return out, w / width


def rms_about_mean(shifts: np.ndarray) -> float:
    """RMS length of ``(T, 2)`` shifts about their mean."""
    centred = shifts - shifts.mean(axis=0)
    return float(np.sqrt((centred**2).sum(axis=1).mean()))


# ---------------------------------------------------------------------- camera shake


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


# --------------------------------------------------------------------- moving region


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


# ------------------------------------------------------------------------- cropping


def crop_square(
    frames: np.ndarray, square: Box, shifts: np.ndarray, size: int
) -> tuple[np.ndarray, bool]:
    """Cut each frame at the square moved by its shift and scale it to ``size`` × ``size``.

    Args:
        frames: ``(T, H, W, 3)`` uint8.
        square: ``(x, y, side, side)`` in the reference frame's pixels.
        shifts: ``(T, 2)`` ``(dx, dy)`` of each frame in input pixels.
        size: Output side in pixels.

    Returns:
        ``(T, size, size, 3)`` uint8 and whether any square reached beyond the frame
        (filled with the nearest edge pixels).
    """
    from PIL import Image

    height, width = frames.shape[1:3]
    x, y, side, _ = square
    left = x + shifts[:, 0]
    top = y + shifts[:, 1]
    pad = int(
        math.ceil(
            max(
                0.0,
                -left.min(),
                -top.min(),
                (left + side).max() - width,
                (top + side).max() - height,
            )
        )
    )
    out = np.empty((len(frames), size, size, 3), np.uint8)
    for t, frame in enumerate(frames):
        if pad:
            frame = np.pad(frame, ((pad, pad), (pad, pad), (0, 0)), mode="edge")
        box = (left[t] + pad, top[t] + pad, left[t] + pad + side, top[t] + pad + side)
        out[t] = np.asarray(
            Image.fromarray(frame).resize(
                (size, size), Image.Resampling.BILINEAR, box=box, reducing_gap=2.0
            )
        )
    return out, pad > 0


# -------------------------------------------------------------------------- overlay


def save_overlay(result: PreparedClip, path: str | Path) -> Path:
    """A PNG of the reference frame with the moving box (or roi) and the cropped square drawn.

    Written atomically; matplotlib with the Agg backend.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from physinfer.io import atomic_path

    height, width = result.input_size
    fig = plt.figure(figsize=(8, 8 * height / width), dpi=max(100, width / 8))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(result.preview)
    x, y, w, h = result.box
    label = "moving region" if result.roi_source == "found" else "--roi"
    ax.add_patch(Rectangle((x, y), w, h, fill=False, edgecolor="yellow", linewidth=2, label=label))
    sx, sy, side, _ = result.square
    ax.add_patch(
        Rectangle(
            (sx, sy),
            side,
            side,
            fill=False,
            edgecolor="red",
            linewidth=2,
            linestyle="--",
            label="framing (cropped)",
        )
    )
    ax.set_xlim(min(0, sx) - 1, max(width, sx + side) + 1)
    ax.set_ylim(max(height, sy + side) + 1, min(0, sy) - 1)
    ax.legend(loc="lower right", fontsize=9, framealpha=0.8)
    ax.text(
        0.01,
        0.99,
        f"box {', '.join(f'{v:.0f}' for v in result.box)}  shake {result.shake_rms_px:.2f} px rms",
        transform=ax.transAxes,
        va="top",
        color="white",
        fontsize=9,
        bbox={"facecolor": "black", "alpha": 0.6, "pad": 2},
    )
    ax.axis("off")
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return path
