"""The degradations of ``benchmarks/bench_real_conditions.py`` do what they say, and its quick
mode runs end to end (slow: about a minute)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
import real_conditions as rc  # noqa: E402


def test_photo_background_is_deterministic_sky_over_trees():
    a, b = rc.photo_background(90, 160, seed=3), rc.photo_background(90, 160, seed=3)
    assert a.shape == (90, 160, 3) and a.dtype == np.uint8 and np.array_equal(a, b)
    assert not np.array_equal(a, rc.photo_background(90, 160, seed=4))
    top, bottom = a[:10].astype(float).mean(axis=(0, 1)), a[-10:].astype(float).mean(axis=(0, 1))
    assert top[2] > top[0]  # blue sky above
    assert bottom[1] > bottom[2] and bottom.mean() < top.mean()  # darker green trees below


def test_composite_puts_the_render_at_its_place_and_shakes_the_view():
    rgba = np.zeros((3, 10, 10, 4), np.uint8)
    rgba[..., 0], rgba[..., 3] = 255, 255  # an opaque red square
    background = np.zeros((40 + 16, 60 + 16, 3), np.uint8)
    frames = rc.composite(rgba, background, (30, 5))
    assert frames.shape == (3, 40, 60, 3)
    ys, xs = np.nonzero(frames[0, ..., 0])
    assert (xs.min(), ys.min(), xs.max(), ys.max()) == (30, 5, 39, 14)
    moved = rc.composite(rgba, background, (30, 5), shifts=np.array([[0, 0], [2, -1], [-3, 3]]))
    ys, xs = np.nonzero(moved[1, ..., 0])
    assert (xs.min(), ys.min()) == (32, 4)


def test_shake_stays_within_its_amplitude():
    s = rc.shake(200, np.random.default_rng(0), amplitude=3)
    assert s.shape == (200, 2) and np.abs(s).max() == 3 and s.std() > 0.5


def test_white_balance_noise_and_h264_degrade_as_asked():
    rng = np.random.default_rng(1)
    frames = np.full((8, 64, 64, 3), 128, np.uint8)
    frames[:, 16:48, 16:48] = rng.integers(0, 255, (8, 32, 32, 3))
    warm = rc.white_balance(frames).astype(float).mean(axis=(0, 1, 2))
    assert warm[0] > warm[1] > warm[2]
    noisy = rc.sensor_noise(frames, rng, sigma=6.0).astype(float) - frames
    assert 5.5 < noisy[:, :8, :8].std() < 8.0
    coded = rc.h264(frames, 25.0, crf=35)
    assert coded.shape == frames.shape
    assert 1.0 < np.abs(coded.astype(float) - frames).mean() < 40.0


@pytest.mark.slow
def test_quick_mode_runs_and_reports_every_condition(tmp_path):
    env = {**os.environ, "PYOPENGL_PLATFORM": "egl"}
    out = subprocess.run(
        [
            sys.executable,
            str(BENCH / "bench_real_conditions.py"),
            "--quick",
            "--rows",
            str(tmp_path / "rows.json"),
        ],
        capture_output=True,
        text=True,
        env=env,
        check=True,
        timeout=600,
    )
    result = json.loads(out.stdout)
    conditions = result["conditions"]
    assert {
        "clean (oracle framing)",
        "clean → prepare",
        "H.264 CRF 35",
        "640×360 off-centre",
    } <= set(conditions)
    for summary in conditions.values():
        assert summary["n"] == 1 and 0 <= summary["median_wind_error"] <= 10
    rows = json.loads((tmp_path / "rows.json").read_text())
    assert len(rows) == len(conditions)
