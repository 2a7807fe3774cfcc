"""Which way a filmed flag flies (``Phenomenon.facing``; core mirrors a target read as flying left).

The renderer's flag flies to the right from a pole on its left. Where a video moves tells
the side, read in the moving region's box (:func:`physinfer.framing.find_moving_box`, on a
small grey copy), in one of two ways by the box's shape:

- **flying** (the box wider than tall): the fly end flaps most, so the motion in the box's
  right third exceeds its left third's;
- **hanging** (a light wind, the box taller than wide): the cloth hangs from the top of the
  pole, so in the box's upper half the motion lies next to the pole, on the left; its fly
  end swings below, on either side, and misleads the first reading (log-ratios -0.3 to
  -1.4 at winds under 1.5 m/s).

Measured on 64 renders (2026-11-27, random looks and seeds; winds 0.3-9.5 m/s, 24 of them
under 2.3 m/s): the log-ratio of the two thirds' motion (right over left; the upper half's
left over right when hanging) was above :data:`CLEAR_LOG_RATIO` in 62, between 0 and it in
2 (winds 2.3 and 2.9 m/s, "cannot tell"), below 0 in none; on 80 others passed through the
camera model of :mod:`physinfer.as_given` and pasted into a wider frame, 75 right, 5 cannot
tell, none wrong (``benchmarks/bench_facing.py``). A mirrored render reads exactly the
negative. docs/real-videos.md.
"""

from __future__ import annotations

import numpy as np

from physinfer.errors import UserInputError
from physinfer.framing import analysis_frames, find_moving_box, motion_energy
from physinfer.types import Clip

#: Longer side in pixels of the grey copy the side is read on.
READ_SIDE = 160
#: Frames read at most (evenly spread over the clip).
READ_FRAMES = 120
#: A box at least this many times as tall as wide holds a hanging flag.
HANGING_ASPECT = 1.0
#: Log-ratio of the two sides' motion that tells the side (the evidence's unit).
CLEAR_LOG_RATIO = 0.3


def flag_facing(clip: Clip) -> float:
    """Evidence that ``clip`` shows the flag flying right (positive) or left (negative),
    in units of :data:`CLEAR_LOG_RATIO`; 0 when nothing in it stands out as moving."""
    frames = clip.frames
    if len(frames) > READ_FRAMES:
        frames = frames[np.linspace(0, len(frames) - 1, READ_FRAMES).round().astype(int)]
    gray, _ = analysis_frames(frames, READ_SIDE)
    energy = motion_energy(gray)
    try:
        box, stats = find_moving_box(energy, np.ones(energy.shape, bool))
    except UserInputError:  # nothing moves: the conditioning after this says so
        return 0.0
    x, y, w, h = (int(round(v)) for v in box)
    motion = np.clip(energy[y : y + h, x : x + w] - stats["background"], 0.0, None)
    if h >= HANGING_ASPECT * w:
        return -_right_over_left(motion[: max(1, h // 2)]) / CLEAR_LOG_RATIO
    return _right_over_left(motion) / CLEAR_LOG_RATIO


def _right_over_left(motion: np.ndarray) -> float:
    """Log of the motion in the right third of ``motion``'s columns over the left third's."""
    profile = motion.sum(axis=0)
    third = max(1, len(profile) // 3)
    return float(np.log((profile[-third:].sum() + 1e-9) / (profile[:third].sum() + 1e-9)))
