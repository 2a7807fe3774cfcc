"""Tests of physinfer_flag.cloth_analysis on synthetic trajectories with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.types import Trajectory
from physinfer_flag.cloth_analysis import (
    FEATURES,
    clip_features,
    dominant_frequency,
    effect_size,
    fly_edge_crosswind,
    kinetic_energy,
    mean_fold_angle,
    spectral_centroid,
    zero_crossing_rate,
)
from physinfer_flag.cloth_mesh import grid_faces


def waving_sheet(freq: float, amp: float = 0.1, nu: int = 31, nv: int = 21, frames: int = 200) -> Trajectory:
    """A flat sheet whose cross-wind offset is a travelling wave at ``freq`` Hz."""
    u, v = np.meshgrid(np.linspace(0, 1.5, nu), np.linspace(0, 1.0, nv))
    t = np.arange(frames)[:, None, None] / 25.0
    y = amp * (u / 1.5) * np.sin(2 * np.pi * (freq * t - u / 1.5))
    verts = np.stack([np.broadcast_to(u, y.shape), y, np.broadcast_to(2 + v, y.shape)], axis=-1)
    return Trajectory(verts.reshape(frames, -1, 3).astype(np.float32), grid_faces(nu, nv), 25.0,
                      {"grid_shape": np.array([nv, nu], np.int32)})


def test_frequency_estimators_find_the_wave():
    sig = [fly_edge_crosswind(waving_sheet(3.0))]
    assert sig[0].shape == (200, 5)
    assert dominant_frequency(sig, 25.0) == pytest.approx(3.0, abs=0.13)
    assert spectral_centroid(sig, 25.0) == pytest.approx(3.0, abs=0.3)
    assert zero_crossing_rate(sig, 25.0) == pytest.approx(3.0, abs=0.1)


def test_kinetic_energy_of_a_translating_sheet():
    traj = waving_sheet(0.0)
    moving = Trajectory(traj.vertices + np.arange(traj.n_frames)[:, None, None].astype(np.float32) * [0.04, 0, 0],
                        traj.faces, 25.0, traj.extras)
    mass = np.full(traj.vertices.shape[1], 0.01)
    np.testing.assert_allclose(kinetic_energy(moving, mass), 0.5 * mass.sum() * 1.0**2, rtol=1e-4)


def test_flat_sheet_has_no_folds_and_a_wave_has_some():
    assert mean_fold_angle(waving_sheet(0.0, amp=0.0)) == pytest.approx(0.0, abs=1e-6)
    assert mean_fold_angle(waving_sheet(2.0, amp=0.3)) > 0.01


def test_clip_features_of_a_known_wave():
    feats = clip_features(waving_sheet(2.0))
    assert tuple(feats) == FEATURES
    assert feats["reach"] == pytest.approx(1.5)
    assert feats["height"] == pytest.approx(2.5)
    assert feats["frequency"] == pytest.approx(2.0, abs=0.3)
    assert 0.0 < feats["amplitude"] < 0.1 and feats["fold"] > 0.0


def test_effect_size():
    assert effect_size([1.0, 2.0, 3.0], [1.0, 2.0, 3.0]) == 0.0
    assert effect_size([0.0, 1.0], [10.0, 11.0]) == pytest.approx(10 / np.sqrt(0.5))


def test_grid_needs_the_flag_extras():
    traj = waving_sheet(1.0)
    with pytest.raises(UserInputError, match="grid_shape"):
        fly_edge_crosswind(Trajectory(traj.vertices, traj.faces, 25.0))
