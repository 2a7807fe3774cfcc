"""The frames ``physinfer prepare`` works on and makes: the small grayscale copy the analysis
runs on, and the output's squares cut from the input (moved by each frame's shift) and scaled."""

from __future__ import annotations

import math

import numpy as np

from physinfer.framing.settings import Box
from physinfer.video import to_gray

ANALYSIS_SIDE = 640
"""Longer side in pixels of the grayscale copy the analysis runs on (a 1920×1080 video is
analysed at 640×360; shifts are measured to 1/20 of its pixel)."""


def analysis_frames(frames: np.ndarray, side: int = ANALYSIS_SIDE) -> tuple[np.ndarray, float]:
    """Grayscale float32 frames shrunk so the longer side is at most ``side`` pixels.

    Returns:
        ``(T, h, w)`` luma in [0, 1] and the scale factor (analysis px per input px).
    """
    from PIL import Image

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
