"""What :func:`physinfer.framing.prepare_clip` takes and gives: the framing rule, the
settings, and the prepared clip with what was found."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
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
