"""The part of a video compared (``--start``/``--end``) and the note on a still opening or ending.

A phone clip of a pendulum often opens on a hand holding the bob; a simulation moves from its
first frame, so those seconds were compared with motion that never happened.
"""

import logging

import numpy as np
import pytest

from physinfer.conditioning import Conditioning, cut_window, note_still_ends, still_ends
from physinfer.errors import UserInputError
from physinfer.types import Clip


def bar_clip(still_before: int, moving: int, still_after: int, fps: float = 20.0, size: int = 48) -> Clip:
    """A bar swinging left and right, held still for the given numbers of frames before and after."""
    frames = np.zeros((still_before + moving + still_after, size, size, 3), np.uint8)
    for t in range(len(frames)):
        phase = min(max(t - still_before, 0), moving - 1)
        left = int((size - 8) * (0.5 + 0.5 * np.sin(2 * np.pi * phase / 20)))
        frames[t, :, left : left + 8] = 200
    return Clip(frames, fps)


def test_the_window_keeps_the_frames_between_start_and_end():
    clip = bar_clip(0, 100, 0)  # 5 s at 20 fps
    kept, record = cut_window(clip, 1.0, 3.5)
    assert np.array_equal(kept.frames, clip.frames[20:70]) and kept.fps == clip.fps
    assert record == {"start_s": 1.0, "end_s": 3.5, "frames": 50, "video_s": 5.0}
    same, none = cut_window(clip, 0.0, None)
    assert same is clip and none is None
    assert cut_window(clip, 4.0, None)[0].n_frames == 20


@pytest.mark.parametrize(
    ("start", "end", "words"),
    [
        (6.0, None, "--start 6 s is past the end of the video (5.00 s, 100 frames at 20 fps)"),
        (0.0, 7.0, "--end 7 s is past the end of the video"),
        (4.98, None, "--start 4.98 keeps 0 frame(s) of the 5.00-s video"),
    ],
)
def test_a_window_outside_the_video_is_refused_saying_how_long_it_is(start, end, words):
    with pytest.raises(UserInputError, match=words.replace("(", r"\(").replace(")", r"\)")):
        cut_window(bar_clip(0, 100, 0), start, end)


def test_a_window_that_is_no_window_is_refused_before_any_video_is_read():
    with pytest.raises(UserInputError, match="--start -1"):
        Conditioning(start_s=-1.0)
    with pytest.raises(UserInputError, match=r"--end 2: give a second of the video after --start \(3\)"):
        Conditioning(start_s=3.0, end_s=2.0)


def test_still_seconds_at_either_end_are_measured_and_a_swing_s_turning_points_are_not():
    lead, tail = still_ends(bar_clip(30, 120, 16))
    assert lead == pytest.approx(1.5, abs=0.06) and tail == pytest.approx(0.8, abs=0.06)
    assert max(still_ends(bar_clip(0, 160, 0))) < 0.2


def test_the_note_gives_the_start_and_end_that_leave_the_still_seconds_out(caplog):
    with caplog.at_level(logging.WARNING):
        record = note_still_ends(bar_clip(30, 120, 16), None, None)
    assert record["start_s"] == pytest.approx(1.5, abs=0.06)
    assert "the first 1.5 s of the video (--start 1.5 leaves them out)" in record["hint"]
    assert "the last 0.8 s (--end 7.5 leaves them out)" in record["hint"]
    assert "a simulation moves from its first frame" in caplog.text
    # In a window, the --start said is a second of the whole video.
    window = {"start_s": 2.0, "end_s": 10.3}
    assert "--start 3.5 leaves them out" in note_still_ends(bar_clip(30, 120, 16), None, window)["hint"]
    assert note_still_ends(bar_clip(4, 120, 4), None, None) is None
