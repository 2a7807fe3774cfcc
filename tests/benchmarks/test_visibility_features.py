"""The slow-motion statistics of ``benchmarks/bench_effect_visibility.py`` (gusts' signature)."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
import bench_effect_visibility as vis  # noqa: E402


def _flag(z_of_t: np.ndarray) -> np.ndarray:
    """``(T, 4, 3)`` vertices: a square whose height follows ``z_of_t``."""
    square = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1]], dtype=np.float64)
    return square[None] + np.stack([np.zeros_like(z_of_t), np.zeros_like(z_of_t), z_of_t], axis=1)[:, None, :]


def test_flapping_averages_out_and_slow_breathing_does_not():
    fps, t = 25.0, np.arange(200) / 25.0
    fast = vis.slow_pose_features(_flag(0.1 * np.sin(2 * np.pi * 5.0 * t)), fps)  # 5 Hz: whole periods per window
    slow = vis.slow_pose_features(_flag(0.1 * np.sin(2 * np.pi * 0.125 * t)), fps)  # one 8-s breath
    assert fast == pytest.approx([0.0, 0.0], abs=1e-9)
    assert slow[0] == 0.0 and slow[1] == pytest.approx(0.1 / np.sqrt(2), rel=0.1)


def test_window_means_drop_the_partial_window_and_need_two():
    assert vis.window_means(np.arange(60.0), fps=25.0).tolist() == [12.0, 37.0]
    with pytest.raises(SystemExit, match="two 1-s windows"):
        vis.window_means(np.arange(40.0), fps=25.0)
