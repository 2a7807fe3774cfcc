"""The refusals of ``physinfer prepare``: a region of interest outside the frame, a framing
rule that gives no square, a trim that keeps too little, a static video."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from physinfer.errors import UserInputError
from physinfer.framing.settings import Box
from physinfer.types import Clip


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
