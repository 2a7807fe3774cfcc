"""The steps of :func:`prepare_clip` in order: trim, analyse, steady, find the moving region,
frame, crop, freeze the static background, resample."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from physinfer.errors import UserInputError
from physinfer.framing.checks import check_not_static, check_roi, check_square, trim_range
from physinfer.framing.frames import analysis_frames, crop_square
from physinfer.framing.region import edge_fraction, energy_stats, find_moving_box, motion_energy
from physinfer.framing.settings import (
    FramingRule,
    PreparedClip,
    PrepareSettings,
    default_framing,
)
from physinfer.framing.shake import (
    MIN_SHAKE_RMS_PX,
    background_weight,
    estimate_shifts,
    measure_shake,
    rms_about_mean,
    valid_mask,
)
from physinfer.static_background import freeze_static
from physinfer.types import Clip
from physinfer.video import resample


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
    fps_in = float(clip.fps)
    frames, fps_work = _working_frames(clip, first, stop, settings.fps)
    gray, scale = analysis_frames(frames)
    check_not_static(gray)
    reference = len(gray) // 2

    roi_a = None if settings.roi is None else tuple(v * scale for v in settings.roi)
    shake = _steady(gray, reference, roi_a, scale, settings.stabilise)
    energy = motion_energy(shake.steady)
    if roi_a is None:
        box_a, stats = find_moving_box(energy, shake.valid)
    else:
        box_a, stats = roi_a, energy_stats(energy, shake.valid)
    residual = shake.rms
    if shake.stabilised:
        weight = background_weight(gray.shape[1:], box_a)
        residual = rms_about_mean(estimate_shifts(shake.steady, reference, weight)) / scale
    edge = edge_fraction(shake.steady, shake.valid, box_a, stats["low"]) if roi_a is None else 0.0
    warnings = _edge_warnings(edge, settings.edge_error_fraction)

    box = settings.roi if settings.roi is not None else tuple(v / scale for v in box_a)
    square = framing(box)
    check_square(square)
    out, padded, static = _framed(frames, fps_work, square, shake.applied / scale, settings)
    if padded:
        warnings.append(
            "the framing reaches beyond the frame; the outside was filled with edge pixels"
        )
    return PreparedClip(
        clip=out,
        box=tuple(float(v) for v in box),  # type: ignore[arg-type]
        square=tuple(float(v) for v in square),  # type: ignore[arg-type]
        roi_source="given" if settings.roi is not None else "found",
        shifts=shake.measured / scale,
        shake_rms_px=float(shake.rms),
        residual_rms_px=float(residual),
        stabilised=bool(shake.stabilised),
        fps_in=fps_in,
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


def _working_frames(clip: Clip, first: int, stop: int, fps: float | None) -> tuple[np.ndarray, float]:
    """The trimmed frames ``(T, H, W, 3)`` and their rate: resampled first to ``fps`` when it
    is lower than the clip's, so the frames the output would not keep are neither steadied
    nor cropped (a 60-fps phone clip read at 20 fps is steadied in a third of the time)."""
    frames = clip.frames[first:stop]
    fps_in = float(clip.fps)
    if fps is None or fps >= fps_in:
        return frames, clip.fps

    return resample(Clip(frames, fps_in), fps).frames, float(fps)


@dataclass(frozen=True)
class _Shake:
    """The camera's shake, measured and (when ``stabilised``) removed.

    Attributes:
        measured: ``(T, 2)`` shifts against the reference frame, in analysis pixels.
        applied: The shifts compensated (``measured``, or zeros when not stabilised).
        steady: ``(T, h, w)`` the analysis frames with ``applied`` removed.
        stabilised: Whether the shifts were compensated.
        rms: RMS of ``measured`` about its mean, in input pixels.
        valid: ``(h, w)`` the pixels every steadied frame still sees.
    """

    measured: np.ndarray
    applied: np.ndarray
    steady: np.ndarray
    stabilised: bool
    rms: float
    valid: np.ndarray


def _steady(
    gray: np.ndarray, reference: int, roi_a: tuple | None, scale: float, stabilise: bool
) -> _Shake:
    """Measure the camera's shake on the analysis frames and remove it (when ``stabilise``
    and it is large enough to matter); refuse a pan, which leaves too little of the frame in view."""
    measured, steadied = np.zeros((len(gray), 2)), None
    if stabilise:
        measured, steadied = measure_shake(gray, reference, roi_a, MIN_SHAKE_RMS_PX * scale)
    stabilised = steadied is not None
    applied = measured if stabilised else np.zeros_like(measured)
    valid = valid_mask(gray.shape[1:], applied)
    if valid.mean() < 0.25:  # a pan, not a shake: too little of the frame stays in view
        raise UserInputError(
            f"the camera moves by up to {np.abs(applied).max() / scale:.0f} px: too much to steady (a pan?); "
            "use footage from a camera held still, or --no-stabilise"
        )
    steady = steadied if steadied is not None else gray
    return _Shake(measured, applied, steady, stabilised, rms_about_mean(measured) / scale, valid)


def _edge_warnings(edge: float, error_fraction: float) -> list[str]:
    """Refuse a subject that reaches the frame's edge in more than ``error_fraction`` of the
    frames (how the renderer would frame it cannot be found); warn when it does in fewer."""
    if edge > error_fraction:
        raise UserInputError(
            f"the moving region reaches the edge of the frame in {edge:.0%} of the frames: the subject "
            "leaves the frame, so how the renderer would frame it cannot be found; use footage that shows "
            "it whole, or give --roi x,y,w,h (input pixels) to frame it yourself"
        )
    if edge > 0:
        return [f"the moving region reaches the frame's edge in {edge:.0%} of the frames"]
    return []


def _framed(
    frames: np.ndarray, fps: float, square: tuple, shifts: np.ndarray, settings: PrepareSettings
) -> tuple[Clip, bool, dict[str, float]]:
    """Crop the steadied ``square``, freeze the static background, resample: the prepared
    clip, whether the square reached beyond the frame, and what freezing did."""
    cropped, padded = crop_square(frames, square, shifts, settings.size)
    static: dict[str, float] = {}
    if settings.freeze_background:
        cropped, static = freeze_static(cropped)
    out = Clip(cropped, fps)
    if settings.fps is not None:
        out = resample(out, settings.fps)
    return out, padded, static
