""":func:`physinfer.static_background.freeze_static`: a noisy, H.264-encoded static background
is frozen to its median while the moving subject keeps every frame, and ``prepare`` applies
it by default."""

import numpy as np

from physinfer.framing import PrepareSettings, prepare_clip
from physinfer.static_background import freeze_static
from physinfer.types import Clip
from physinfer.video import read_video, write_video


def moving_square(n=30, size=96, noise=6.0, seed=0):
    """A textured background with sensor noise and a bright square sliding across it."""
    rng = np.random.default_rng(seed)
    background = rng.integers(60, 180, (size, size, 3)).astype(np.float32)
    frames = np.repeat(background[None], n, axis=0)
    for t in range(n):
        x = 10 + 2 * t
        frames[t, 40:60, x : x + 16] = 250.0
    frames += rng.normal(0, noise, frames.shape)
    return np.clip(frames, 0, 255).astype(np.uint8), background


def test_noise_is_frozen_where_nothing_moves_and_the_subject_kept():
    frames, background = moving_square()
    frozen, info = freeze_static(frames)
    assert 4.5 < info["noise_sigma"] < 7.5 and info["level"] >= 24
    corner = frozen[:, :30, :30].astype(float)
    # The static corner no longer flickers (but for a rare pixel whose noise exceeds 4.5 σ).
    assert np.mean(corner.std(axis=0).max(axis=-1) == 0.0) > 0.99
    assert np.abs(corner[0] - background[:30, :30]).mean() < 3.0  # ... and is the background
    path = frozen[:, 40:60, 10:76].astype(float)
    assert np.array_equal(
        frozen[:, 40:60, 10:76], frames[:, 40:60, 10:76]
    )  # the square's path is untouched
    assert path.std(axis=0).mean() > 30.0
    assert 0.6 < info["static_fraction"] < 0.9


def test_h264_flicker_is_frozen_too(tmp_path):
    frames, _ = moving_square(noise=3.0)
    coded = read_video(write_video(tmp_path / "clip.mp4", Clip(frames, 25.0))).frames
    frozen, info = freeze_static(coded)
    assert np.mean(frozen[:, :30, :30].astype(float).std(axis=0).max(axis=-1) == 0.0) > 0.99
    assert info["static_fraction"] > 0.6


def test_prepare_freezes_by_default_and_can_keep_the_noise():
    frames, _ = moving_square(n=20, size=128, noise=5.0)
    clip = Clip(frames, 25.0)
    settings = PrepareSettings(size=64, roi=(4, 30, 120, 40), stabilise=False)
    frozen = prepare_clip(clip, settings=settings)
    kept = prepare_clip(
        clip, settings=PrepareSettings(**{**settings.__dict__, "freeze_background": False})
    )
    assert frozen.static["static_fraction"] > 0.3 and kept.static == {}
    assert frozen.to_dict()["static_background"]["level"] >= 24
    flicker = lambda c: c.frames.astype(float).std(axis=0).mean()  # noqa: E731
    assert flicker(frozen.clip) < 0.6 * flicker(kept.clip)
