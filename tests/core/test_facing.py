"""Which way round a target shows its subject (:mod:`physinfer.facing`): a phenomenon's reading
decides, ``--mirror``/``--no-mirror`` override it, the region of interest turns with the frame,
and a reading that cannot tell leaves the video alone and says so."""

from __future__ import annotations

import logging
from types import SimpleNamespace

import numpy as np
import pytest

from physinfer.conditioning import Conditioning, condition_target
from physinfer.facing import face, mirror_roi
from physinfer.types import Clip


def _clip() -> Clip:
    frames = np.zeros((4, 20, 30, 3), np.uint8)
    frames[:, :, :5] = 200  # a bright band on the left
    return Clip(frames, 25.0)


def _reading(value: float, seen: list | None = None):
    def facing(clip: Clip) -> float:
        if seen is not None:
            seen.append(clip.frames.shape)
        return value

    return SimpleNamespace(name="flag", facing=facing, framing=None)


def test_a_target_read_as_mirrored_is_mirrored_back_and_its_region_with_it(caplog):
    with caplog.at_level(logging.WARNING):
        clip, roi, facing = face(_reading(-3.0), _clip(), (2, 1, 10, 8), None)
    assert clip.frames[0, 0, -1, 0] == 200 and clip.frames[0, 0, 0, 0] == 0
    assert roi == (18, 1, 10, 8) and facing.mirrored and not facing.unclear
    assert facing.to_dict() == {"mirrored": True, "by": "read from the video", "evidence": -3.0, "note": facing.note}
    assert "other way round" in caplog.text and "--no-mirror" in caplog.text


def test_a_target_read_the_renderer_s_way_is_left_alone_quietly(caplog):
    original = _clip()
    with caplog.at_level(logging.WARNING):
        clip, roi, facing = face(_reading(2.0), original, None, None)
    assert clip is original and roi is None and not facing.mirrored and facing.note is None
    assert caplog.text == ""


def test_a_reading_that_cannot_tell_leaves_the_video_and_names_the_way_out(caplog):
    original = _clip()
    with caplog.at_level(logging.WARNING):
        clip, _roi, facing = face(_reading(-0.6), original, None, None)
    assert clip is original and facing.unclear and not facing.mirrored
    assert "cannot tell" in caplog.text and "--mirror" in caplog.text


def test_the_user_s_word_wins_and_the_reading_is_not_made():
    seen: list = []
    phenomenon = _reading(5.0, seen)
    clip, _roi, facing = face(phenomenon, _clip(), None, True)
    assert facing.mirrored and facing.evidence is None and facing.to_dict()["by"] == "--mirror"
    assert clip.frames[0, 0, -1, 0] == 200 and seen == []
    clip, _roi, facing = face(_reading(-5.0), _clip(), None, False)
    assert not facing.mirrored and facing.to_dict()["by"] == "--no-mirror"


def test_a_subject_without_a_side_is_used_as_given_unless_the_user_mirrors_it():
    pendulum = SimpleNamespace(name="pendulum", facing=None, framing=None)
    original = _clip()
    assert face(pendulum, original, None, None) == (original, None, None)
    clip, _roi, facing = face(pendulum, original, None, True)
    assert facing.mirrored and clip.frames[0, 0, -1, 0] == 200


def test_the_reading_sees_only_the_region_of_interest():
    seen: list = []
    face(_reading(2.0, seen), _clip(), (3, 2, 12, 9), None)
    assert seen == [(4, 9, 12, 3)]


@pytest.mark.parametrize("width", [30, 31])
def test_mirroring_a_region_twice_gives_it_back(width):
    assert mirror_roi(mirror_roi((4, 2, 7, 5), width), width) == (4, 2, 7, 5)


def test_conditioning_records_the_decision_and_frames_the_mirrored_video():
    phenomenon = _reading(-4.0)
    clip, _zeta, record = condition_target(
        phenomenon, None, _clip(), Conditioning(prepare=False, estimate_render=False), {}
    )
    assert record["facing"]["mirrored"] and clip.frames[0, 0, -1, 0] == 200
