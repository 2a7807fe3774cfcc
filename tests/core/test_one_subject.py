"""The one-subject check says where things move in the user's own pixels, with or without --roi."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.conditioning import check_one_subject
from physinfer.errors import UserInputError
from physinfer.types import Clip


def two_movers(height: int = 120, width: int = 240, frames: int = 50, fps: float = 25.0) -> Clip:
    """A big square swinging on the left and a small one bobbing on the right."""
    video = np.full((frames, height, width, 3), 200, np.uint8)
    for i, t in enumerate(np.arange(frames) / fps):
        x = int(60 + 15 * np.sin(2 * np.pi * t))
        video[i, 50:74, x : x + 24] = 30
        y = int(60 + 10 * np.sin(2 * np.pi * 1.7 * t))
        video[i, y : y + 12, 170:182] = 30
    return Clip(video, fps)


def refusal(clip: Clip, roi: tuple[float, float, float, float] | None) -> str:
    with pytest.raises(UserInputError) as caught:
        check_one_subject(clip, roi, 25.0)
    return str(caught.value)


def test_the_regions_are_named_in_the_video_s_pixels_also_inside_a_roi():
    clip = two_movers()
    whole = refusal(clip, None)
    inside = refusal(clip, (20.0, 30.0, 200.0, 80.0))
    assert "2 things move in this video" in whole and "give the subject's region with --roi" in whole
    # Before: the boxes were the crop's (x 26 for 46) and the advice asked for the --roi already given.
    assert "2 things move in --roi 20,30,200,80" in inside and "around the subject alone" in inside
    boxes = ["46,50,52,24", "170,50,12,32"]
    assert all(f"x,y,w,h {box} (" in whole for box in boxes)
    assert all(f"x,y,w,h {box} (" in inside for box in boxes)
    check_one_subject(clip, (20.0, 30.0, 110.0, 80.0), 25.0)  # the big square alone passes
