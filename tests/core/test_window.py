"""The part of a video compared (``--start``/``--end``) and the note on a still opening or ending.

A phone clip of a pendulum often opens on a hand holding the bob; a simulation moves from its
first frame, so those seconds were compared with motion that never happened.
"""

import logging

import numpy as np
import pytest

from physinfer.conditioning import Conditioning, note_still_ends, still_ends
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


def moving_video(tmp_path, frames: int = 100, fps: float = 20.0):
    """A bar crossing the frame once (its place tells the frame), written to mp4."""
    from physinfer.video import write_video

    size = 64
    pixels = np.zeros((frames, size, size, 3), np.uint8)
    for t in range(frames):
        pixels[t, :, int(t * (size - 4) / (frames - 1)) : int(t * (size - 4) / (frames - 1)) + 4] = 220
    return write_video(tmp_path / "bar.mp4", Clip(pixels, fps)), pixels


def bar_place(frame: np.ndarray) -> float:
    """The bar's centre column."""
    profile = np.clip(frame[..., 0].mean(axis=0) - 60.0, 0.0, None)
    return float((profile * np.arange(len(profile))).sum() / profile.sum())


def test_the_part_read_is_the_frames_between_start_and_end(tmp_path):
    from physinfer.target import read_target_video

    path, pixels = moving_video(tmp_path)  # 5 s at 20 fps
    part = read_target_video(path, start_s=1.0, end_s=3.5)
    assert part.n_frames == 50 and part.fps == 20.0
    assert bar_place(part.frames[0]) == pytest.approx(bar_place(pixels[20]), abs=1)
    assert bar_place(part.frames[-1]) == pytest.approx(bar_place(pixels[69]), abs=1)
    assert read_target_video(path, start_s=4.0).n_frames == 20


def test_a_part_of_a_long_video_is_read_past_the_memory_budget(tmp_path):
    """A 1080p phone video fills the reading budget in about 11 s: --start beyond that must
    still find its part, not the first seconds or "past the end"."""
    from physinfer.target import read_target_video

    path, pixels = moving_video(tmp_path)
    budget = 30 * 64 * 64 * 3  # 30 frames
    part = read_target_video(path, start_s=3.0, max_bytes=budget)
    assert part.n_frames == 30
    assert bar_place(part.frames[0]) == pytest.approx(bar_place(pixels[60]), abs=1)


@pytest.mark.parametrize(
    ("start", "end", "words"),
    [
        (6.0, None, "--start 6 s is past the end of"),
        (0.0, 7.0, "--end 7 s is past the end of"),
    ],
)
def test_a_part_outside_the_video_is_refused_saying_how_long_it_is(tmp_path, start, end, words):
    from physinfer.target import read_target_video

    path, _ = moving_video(tmp_path)
    with pytest.raises(UserInputError, match=words) as caught:
        read_target_video(path, start_s=start, end_s=end)
    assert "(5.00 s long)" in str(caught.value)


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
        record = note_still_ends(bar_clip(30, 120, 16), None)
    assert record["start_s"] == pytest.approx(1.5, abs=0.06)
    assert "the first 1.5 s of the video (--start 1.5 leaves them out)" in record["hint"]
    assert "the last 0.8 s (--end 7.5 leaves them out)" in record["hint"]
    assert "a simulation moves from its first frame" in caplog.text
    # Read from --start 2, the --start said is a second of the whole video.
    hint = note_still_ends(bar_clip(30, 120, 16), None, 2.0)["hint"]
    assert "--start 3.5 leaves them out" in hint and "--end 9.5 leaves them out" in hint
    assert note_still_ends(bar_clip(4, 120, 4), None) is None


def test_a_video_longer_than_the_budget_holds_is_read_whole_at_a_smaller_size(tmp_path, monkeypatch, caplog):
    """At 1920 px a 1080p phone video filled the 2-GiB budget in about 11 s: a pendulum's 25-s
    swing was measured on its first 11 s. Decoded smaller, all of it is read (a note says so)."""
    import physinfer.target as target

    path, _ = moving_video(tmp_path)  # 100 frames of 64 × 64
    monkeypatch.setattr(target, "TARGET_MIN_READ_SIDE", 16)  # the shipped floor is 640 px
    with caplog.at_level(logging.WARNING):
        whole = target.read_target_video(path, max_bytes=30 * 64 * 64 * 3)
    assert whole.n_frames == 100 and max(whole.frames.shape[1:3]) < 64
    assert "is read at 34×34 (not 64×64) so that its 5.0 s fit in memory" in caplog.text
    monkeypatch.setattr(target, "TARGET_MIN_READ_SIDE", 60)  # no smaller than that: cut instead
    with caplog.at_level(logging.WARNING):
        cut = target.read_target_video(path, max_bytes=30 * 64 * 64 * 3)
    assert cut.n_frames < 100 and "only its first" in caplog.text


def test_prepare_takes_end_as_refine_does_and_refuses_it_beside_duration(tmp_path):
    """``prepare --end`` keeps the frames ``refine --end`` compares; ``--duration`` says the same."""
    import physinfer

    video, _ = moving_video(tmp_path, frames=100, fps=20.0)
    given = {"target": video, "roi": "0,0,64,64", "no_render_estimate": True, "start": 1.0}
    by_end = physinfer.prepare("pendulum_lab", end=3.5, **given)
    by_duration = physinfer.prepare("pendulum_lab", duration=2.5, **given)
    assert by_end.clip.n_frames == by_duration.clip.n_frames
    np.testing.assert_array_equal(by_end.clip.frames, by_duration.clip.frames)
    with pytest.raises(UserInputError, match="--end 3.5 and --duration 2.5 both say where the part kept ends"):
        physinfer.prepare("pendulum_lab", target=video, end=3.5, duration=2.5)
    with pytest.raises(UserInputError, match="--end 1: give a second of the video after --start"):
        physinfer.prepare("pendulum_lab", target=video, start=2.0, end=1.0)
