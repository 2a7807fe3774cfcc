""":mod:`physinfer.framing` on generated, H.264-encoded videos: a moving patch over a static
texture, with and without camera shake, and the inputs it must refuse.

The flag's own framing on composited flag renders is tested in
``tests/plugins/flag/test_prepare.py``.
"""

import json

import numpy as np
import pytest
from PIL import Image

from physinfer.conditioning import check_one_subject
from physinfer.errors import UserInputError
from physinfer.framing import PrepareSettings, default_framing, prepare_clip
from physinfer.testing.footage import textured_background
from physinfer.types import Clip
from physinfer.video import read_video, write_video

#: Where the moving patch is in the 640×360 test videos: (x, y, w, h).
PATCH = (380, 90, 160, 120)


def patch_video(
    path, *, size=(360, 640), patch=PATCH, n=30, fps=25.0, shifts=None, seed=0, moving=True
):
    """Write an mp4 of a patch whose stripes travel, over a static texture with sensor noise.

    ``shifts`` ``(n, 2)``: the camera's ``(dx, dy)`` in pixels per frame (content moves by it).
    """
    height, width = size
    margin = 12
    background = textured_background(height + 2 * margin, width + 2 * margin, seed)
    x, y, w, h = patch
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    rng = np.random.default_rng(seed + 1)
    shifts = np.zeros((n, 2)) if shifts is None else shifts
    frames = np.empty((n, height, width, 3), np.uint8)
    for t in range(n):
        phase = 1.7 * t / fps if moving else 0.0
        stripes = np.sin(2 * np.pi * (xx / 23.0 - phase)) * np.cos(
            2 * np.pi * (yy / 31.0 + 0.6 * phase)
        )
        canvas = background.copy()
        colour = (128 + 90 * stripes)[..., None] * np.array([1.0, 0.5, 0.3])
        canvas[margin + y : margin + y + h, margin + x : margin + x + w] = colour.astype(np.uint8)
        # The camera moved by (dx, dy): the content appears moved by it (bilinear, sub-pixel).
        left, top = margin - shifts[t][0], margin - shifts[t][1]
        view = Image.fromarray(canvas).resize(
            (width, height), Image.Resampling.BILINEAR, box=(left, top, left + width, top + height)
        )
        noisy = np.asarray(view, np.float32) + rng.normal(0, 2.0, (height, width, 3))
        frames[t] = np.clip(noisy, 0, 255).astype(np.uint8)
    write_video(path, Clip(frames, fps))
    return path


def iou(a, b):
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    inter = max(0, min(ax + aw, bx + bw) - max(ax, bx)) * max(
        0, min(ay + ah, by + bh) - max(ay, by)
    )
    return inter / (aw * ah + bw * bh - inter)


@pytest.fixture(scope="module")
def still_camera(tmp_path_factory):
    return read_video(patch_video(tmp_path_factory.mktemp("prep") / "still.mp4"))


def test_the_moving_patch_is_found_framed_scaled_and_resampled(still_camera):
    result = prepare_clip(still_camera, settings=PrepareSettings(size=96, fps=20.0))
    assert iou(result.box, PATCH) >= 0.8, result.box
    assert result.square == pytest.approx(default_framing(result.box))
    assert result.roi_source == "found" and not result.stabilised and result.shake_rms_px < 0.25
    assert (
        result.clip.frames.shape == (24, 96, 96, 3) and result.clip.fps == 20.0
    )  # 1.2 s at 20 fps
    assert result.fps_in == 25.0 and result.frames_kept == (0, 30) and not result.warnings
    summary = json.loads(json.dumps(result.to_dict()))
    assert summary["box"] == pytest.approx(list(result.box), abs=0.01) and summary["size"] == 96


def test_trim_and_a_given_roi(still_camera):
    roi = (370.0, 80.0, 180.0, 140.0)
    result = prepare_clip(
        still_camera, settings=PrepareSettings(roi=roi, start_s=0.2, duration_s=0.8)
    )
    assert result.roi_source == "given" and result.box == roi
    assert result.frames_kept == (5, 25) and result.clip.n_frames == 20


@pytest.mark.parametrize("kind", ["whole pixels", "sub-pixel"])
def test_camera_shake_is_measured_and_removed(tmp_path, kind):
    rng = np.random.default_rng(3)
    shifts = rng.uniform(-3.0, 3.0, (20, 2))
    if kind == "whole pixels":
        shifts = np.round(shifts)
    clip = read_video(patch_video(tmp_path / "shaky.mp4", shifts=shifts, seed=5, n=20))
    result = prepare_clip(clip)
    truth = shifts - shifts[10]  # against the reference, the middle frame
    error = np.linalg.norm(result.shifts - truth, axis=1)
    assert result.stabilised and result.shake_rms_px > 1.5
    assert error.max() <= 1.0 and np.sqrt((error**2).mean()) <= 0.5, error
    assert result.residual_rms_px <= 1.0
    # The box is found in the reference frame's pixels, where the patch sits moved by its shift.
    moved = (PATCH[0] + shifts[10][0], PATCH[1] + shifts[10][1], PATCH[2], PATCH[3])
    assert iou(result.box, moved) >= 0.75


def test_a_static_video_is_refused(tmp_path):
    clip = read_video(patch_video(tmp_path / "still.mp4", moving=False, n=10))
    frames = np.repeat(clip.frames[:1], 10, axis=0)  # exactly still
    with pytest.raises(UserInputError, match="the video is static"):
        prepare_clip(Clip(frames, 25.0))


def test_a_video_where_nothing_stands_out_is_refused_naming_roi(tmp_path):
    clip = read_video(patch_video(tmp_path / "noise.mp4", moving=False, n=16))  # sensor noise only
    with pytest.raises(UserInputError, match="no moving region found") as info:
        prepare_clip(clip)
    assert "--roi x,y,w,h" in str(info.value)


def test_a_subject_that_leaves_the_frame_is_refused(tmp_path):
    clip = read_video(patch_video(tmp_path / "edge.mp4", patch=(540, 90, 100, 120), n=16))
    with pytest.raises(UserInputError, match="reaches the edge of the frame in 100% of the frames"):
        prepare_clip(clip)


@pytest.mark.parametrize("roi", [(600, 10, 100, 100), (-5, 0, 50, 50), (10, 10, 0, 20)])
def test_a_roi_outside_the_frame_is_refused(still_camera, roi):
    with pytest.raises(UserInputError, match="is not inside the 640×360 frame"):
        prepare_clip(still_camera, settings=PrepareSettings(roi=roi))


@pytest.mark.parametrize("roi", [(0, 0, 0, 0), (600, 10, 100, 100)])
def test_an_empty_or_outside_roi_is_refused_before_the_one_subject_check(still_camera, roi):
    # The motion embedder's one-subject check cropped first: an empty --roi crashed the tracker
    # ("zero-size array to reduction operation maximum") instead of naming the option.
    with pytest.raises(UserInputError, match="is not inside the 640×360 frame"):
        check_one_subject(still_camera, roi, 20.0)


def test_cli_writes_video_json_and_overlay_and_asks_for_fps(still_camera, tmp_path, physinfer_cli):
    out = tmp_path / "out" / "prepared.mp4"
    write_video(tmp_path / "in.mp4", Clip(still_camera.frames[:12], still_camera.fps))
    proc = physinfer_cli(
        "prepare", "--plugin", "pendulum_lab", "--target", str(tmp_path / "in.mp4"), "--out", str(out), "--json"
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert (
        data["roi_source"] == "found"
        and data["embedder"] == "grid_spectrum"
        and data["fps_out"] == 25.0
    )
    assert json.loads((tmp_path / "out" / "prepared.json").read_text()) == data
    with Image.open(tmp_path / "out" / "prepared_overlay.png") as overlay:
        assert overlay.format == "PNG" and overlay.size[0] >= 640
    assert read_video(out).frames.shape[1:] == (224, 224, 3)
    frames = tmp_path / "frames"
    frames.mkdir()
    for index, frame in enumerate(still_camera.frames[:3]):
        Image.fromarray(frame).save(frames / f"{index:03d}.png")
    proc = physinfer_cli(
        "prepare", "--plugin", "pendulum_lab", "--target", str(frames), "--out", str(out), "--overwrite", "--json"
    )  # fmt: skip
    assert proc.returncode == 2 and "pass it with --fps" in json.loads(proc.stdout)["error"]


def test_the_api_prepares_without_writing_and_draws_the_overlay(still_camera, tmp_path):
    from matplotlib.figure import Figure

    import physinfer

    write_video(tmp_path / "in.mp4", Clip(still_camera.frames[:12], still_camera.fps))
    video = physinfer.prepare("pendulum_lab", target=tmp_path / "in.mp4", size=64, no_render_estimate=True)
    assert video.clip.frames.shape[1:] == (64, 64, 3) and video.paths == {}
    assert video.to_dict()["roi_source"] == "found" and video.render_estimate is None
    assert isinstance(video.plot(), Figure) and list(tmp_path.iterdir()) == [tmp_path / "in.mp4"]
    with pytest.raises(UserInputError, match="would overwrite --target"):
        physinfer.prepare("pendulum_lab", target=tmp_path / "in.mp4", out=tmp_path / "in.mp4")
