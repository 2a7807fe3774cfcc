"""Tests of physinfer_flag.cloth: the solver facade (per-run inputs, determinism, batching)."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.errors import SimulationFailed, UserInputError
from physinfer_flag.cloth import ClothPhysics, ClothSolver, FlagRun
from physinfer_flag.cloth_mesh import build_flag_mesh
from physinfer_flag.cloth_wind import WindState, sample_wind
from physinfer_flag.material import load_material

FPS = 25.0


def make_solver(substeps: int = 48, nu: int = 16, nv: int = 11, **physics) -> ClothSolver:
    mesh = build_flag_mesh(width=1.5, height=1.0, nu=nu, nv=nv, pin_mode="edge", top_z=2.95)
    settings = {"dt": 1.0 / (FPS * substeps), "strain_limit": 0.05, "damping": 1e-4, **physics}
    return ClothSolver(mesh=mesh, material=load_material(), physics=ClothPhysics(**settings), substeps=substeps)


def flag_run(speed: float = 5.0, seed: int = 0, area_weight: float = 0.135) -> FlagRun:
    wind = sample_wind(WindState(speed=speed, z_ref=2.45), duration=10.0)
    return FlagRun(area_weight=area_weight, bending=load_material().bending, wind=wind, seed=seed)


@pytest.fixture(scope="module")
def solver():
    return make_solver()


def test_inverse_mass_and_pins(solver):
    inv = solver.inverse_mass(0.1)
    assert np.all(inv[solver.mesh.pinned] == 0)
    free = ~solver.mesh.pinned
    total = (1 / inv[free]).sum() + 0.1 * solver.mesh.node_area[solver.mesh.pinned].sum()
    assert total == pytest.approx(0.1 * 1.5)
    with pytest.raises(UserInputError):
        solver.inverse_mass(0.0)


def test_hinge_curves_pick_the_row_of_each_direction(solver):
    table = np.arange(15, dtype=float).reshape(3, 5)
    curves = solver.hinge_curves(table)
    for row in range(3):
        sel = np.isclose(solver.mesh.hinge_direction, row)
        np.testing.assert_array_equal(curves[sel], np.tile(table[row], (sel.sum(), 1)))


def test_initial_state_is_seeded_small_and_out_of_plane(solver):
    x0, v0 = solver.initial_state(0)
    x1, _ = solver.initial_state(1)
    again, _ = solver.initial_state(0)
    np.testing.assert_array_equal(x0, again)
    assert not np.array_equal(x0, x1)
    offset = x0 - solver.mesh.rest
    assert np.abs(offset[:, 1]).max() == pytest.approx(solver.perturbation)
    np.testing.assert_array_equal(offset[:, [0, 2]], 0.0)
    np.testing.assert_array_equal(offset[solver.mesh.pinned], 0.0)
    np.testing.assert_array_equal(v0, 0.0)


def test_run_is_deterministic_and_seed_dependent(solver):
    a = solver.run(flag_run(seed=0), warmup_frames=10, n_frames=10)
    b = solver.run(flag_run(seed=0), warmup_frames=10, n_frames=10)
    c = solver.run(flag_run(seed=1), warmup_frames=10, n_frames=10)
    assert a.shape == (10, solver.mesh.n_vertices, 3) and a.dtype == np.float32
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 1e-3


def test_batch_matches_single_runs(solver):
    runs = [flag_run(speed=3.0, seed=0), flag_run(speed=7.0, seed=2, area_weight=0.1)]
    batch, status = solver.run_batch(runs, warmup_frames=5, n_frames=5)
    np.testing.assert_array_equal(status[:, 0], 0)
    for k, run in enumerate(runs):
        np.testing.assert_allclose(batch[k], solver.run(run, warmup_frames=5, n_frames=5), atol=1e-6)


def test_too_large_a_step_is_reported_as_a_failed_simulation():
    unstable = make_solver(substeps=8)
    with pytest.raises(SimulationFailed, match="cloth simulation"):
        unstable.run(flag_run(speed=8.0, area_weight=0.1), warmup_frames=25, n_frames=5)
    batch, status = unstable.run_batch([flag_run(speed=8.0, area_weight=0.1)], warmup_frames=25, n_frames=5)
    assert status[0, 0] != 0


def test_physics_settings_are_validated():
    with pytest.raises(UserInputError, match="dt"):
        ClothPhysics(dt=0.5).validate()
    with pytest.raises(UserInputError, match="strain_limit"):
        ClothPhysics(strain_limit=1.5).validate()
