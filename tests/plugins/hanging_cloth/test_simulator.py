"""Tests of physinfer_hanging_cloth.simulator: θ, settings, the hanging scene and its physics."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.errors import SimulationFailed, UserInputError
from physinfer.testing import check_simulator
from physinfer_hanging_cloth.fan import FanSettings
from physinfer_hanging_cloth.simulator import (
    AREA_WEIGHT_BOUNDS,
    BENDING_MULTIPLIER_BOUNDS,
    HangingClothConfig,
    HangingClothSimulator,
    hanging_cloth_parameter_space,
    hanging_mesh,
    make_simulator,
)

#: A small, short scene for fast tests (8 cm grid, 0.4 s warm-up, 6 frames).
FAST = {"spacing": 0.08, "warmup_s": 0.4, "n_frames": 6}


def fold(traj, nu, nv):
    """Mean absolute second difference of the out-of-plane coordinate along the rows."""
    grid = traj.vertices.reshape(traj.n_frames, nv, nu, 3)
    return float(np.abs(np.diff(grid[..., 1], 2, axis=2)).mean())


def test_parameter_space():
    space = hanging_cloth_parameter_space()
    assert space.names == ["bending_multiplier", "area_weight"]
    assert space["bending_multiplier"].bounds == BENDING_MULTIPLIER_BOUNDS
    assert space["area_weight"].bounds == AREA_WEIGHT_BOUNDS
    assert {s.scaling for s in space} == {"log"}


def test_contract_and_fan_level_of_the_batch():
    sim = make_simulator((), **FAST)
    check_simulator(sim)
    params = sim.parameter_space.defaults()
    one = make_simulator((), fan_level="W3", **FAST).simulate(params, seed=2)
    batch = sim.simulate_videos([params, params], seeds=[2, 2], fan_levels=["W1", "W3"])
    np.testing.assert_allclose(batch[1].vertices, one.vertices, atol=1e-4)
    assert not np.allclose(batch[0].vertices, batch[1].vertices, atol=1e-3)


def test_trajectory_conventions():
    sim = make_simulator((), **FAST)
    traj = sim.simulate(sim.parameter_space.defaults(), seed=0)
    nu, nv = sim.config.grid
    assert traj.vertices.shape == (FAST["n_frames"], nu * nv, 3) and traj.fps == 25.0
    assert traj.extras["uv"].shape == (nu * nv, 2)
    np.testing.assert_array_equal(traj.extras["grid_shape"], [nv, nu])
    top = traj.vertices[:, (nv - 1) * nu :]
    # The top row hangs still on the rod, gathered to `gather` of the width, centred on x = 0.
    np.testing.assert_allclose(top[..., 2], sim.config.rod_height, atol=1e-6)
    np.testing.assert_allclose(top[..., 1], 0.0, atol=1e-6)
    np.testing.assert_allclose(top[0, [0, -1], 0], np.array([-0.5, 0.5]) * sim.config.gather * sim.config.width, atol=1e-6)
    np.testing.assert_allclose(traj.extras["rod"][:, 0], top[0, [0, -1], 0], atol=1e-6)
    # Everything else hangs below the rod; the fan pushes the cloth towards +y.
    assert traj.vertices[..., 2].max() <= sim.config.rod_height + 1e-6
    assert traj.vertices[:, : nu, 1].mean() > 0.05


def test_mesh_keeps_the_flat_fabric_but_starts_gathered():
    config = HangingClothConfig(spacing=0.1, gather=0.5)
    mesh = hanging_mesh(config)
    nu, nv = config.grid
    assert mesh.pinned.sum() == nu and mesh.pinned[-nu:].all()
    assert np.ptp(mesh.material_uv[:, 0]) == pytest.approx(config.width)
    assert np.ptp(mesh.rest[-nu:, 0]) == pytest.approx(0.5 * config.width)
    assert np.ptp(mesh.rest[:nu, 0]) == pytest.approx(config.width)


def test_heavier_fabric_and_weaker_fan_blow_back_less():
    def reach(level, area_weight):
        sim = make_simulator((), fan_level=level, spacing=0.08, warmup_s=1.0, n_frames=10)
        traj = sim.simulate({"bending_multiplier": 6.0, "area_weight": area_weight}, seed=0)
        return float(traj.vertices[:, : sim.config.grid[0], 1].mean())  # hem's distance downwind

    assert reach("W3", 0.1) > reach("W1", 0.1) + 0.05
    assert reach("W2", 0.08) > reach("W2", 0.5) + 0.05


def test_stiffer_fabric_folds_less():
    sim = make_simulator((), n_frames=8)
    nu, nv = sim.config.grid
    trajs = sim.simulate_batch(
        [{"bending_multiplier": b, "area_weight": 0.2} for b in (1.5, 30.0)], seeds=[0, 0]
    )
    limp, stiff = (fold(t, nu, nv) for t in trajs)
    assert stiff < 0.7 * limp


def test_seed_changes_the_gusts():
    sim = make_simulator((), **FAST)
    a, b = (sim.simulate(sim.parameter_space.defaults(), seed=s) for s in (0, 1))
    assert not np.allclose(a.vertices, b.vertices)


@pytest.mark.parametrize(
    "bad",
    [
        {"width": 0.0},
        {"spacing": 0.001},
        {"rod_height": 0.1},
        {"gather": 0.1},
        {"fan_level": "W7"},
        {"n_frames": 0},
        {"substeps": 0},
        {"substeps": 2},
        {"strain_limit": 1.0},
        {"fan": FanSettings(speeds=(3.0, 2.0, 1.0))},
    ],
)
def test_bad_settings_are_refused(bad):
    with pytest.raises(UserInputError):
        HangingClothConfig(**bad).validate()


def test_unknown_setting_effects_and_out_of_bounds_parameters_are_refused():
    with pytest.raises(UserInputError, match="unknown hanging-cloth simulator setting"):
        make_simulator((), wind_speed=3.0)
    with pytest.raises(UserInputError, match="no effects"):
        HangingClothSimulator(effects=[object()])
    sim = make_simulator((), **FAST)
    with pytest.raises(UserInputError, match="outside its bounds"):
        sim.simulate({"area_weight": 5.0})
    with pytest.raises(UserInputError, match="unknown parameter"):
        sim.simulate({"wind_speed": 1.0})
    with pytest.raises(UserInputError, match="fan levels"):
        sim.simulate_videos([{}], seeds=[0, 1], fan_levels=["W1"])


def test_a_blow_up_is_reported_as_simulation_failed():
    sim = make_simulator((), spacing=0.08, warmup_s=0.4, n_frames=4, substeps=5)
    with pytest.raises(SimulationFailed, match="failed"):
        sim.simulate_batch([{"area_weight": 0.05}], seeds=[0])
