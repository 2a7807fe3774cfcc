"""Tests of physinfer_flag.simulator: θ, settings, trajectory conventions and the physics checks.

The physics checks come in a fast version (default run) and a long-record version
marked ``slow`` (``pytest -m slow``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from physinfer.errors import SimulationFailed, UserInputError
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.roles import Effect
from physinfer.testing import check_simulator
from physinfer_flag.cloth_analysis import (
    dihedral_angles,
    dominant_frequency,
    fly_edge_crosswind,
    grid_vertices,
    kinetic_energy,
    mean_fold_angle,
    spectral_centroid,
    zero_crossing_rate,
)
from physinfer_flag.cloth_wind import WindState
from physinfer_flag.material import bending_parameter_names
from physinfer_flag.simulator import (
    FlagSimConfig,
    FlagSimulator,
    flag_parameter_space,
    make_simulator,
)

BEND = bending_parameter_names()


@pytest.fixture(scope="module")
def sim() -> FlagSimulator:
    return make_simulator()


def all_bending(mult: float) -> dict[str, float]:
    return {n: mult for n in BEND}


# -- parameters and settings ---------------------------------------------------------------


def test_parameter_space_is_the_papers_table():
    space = flag_parameter_space()
    assert len(space) == 17
    assert space.names[:2] == ["wind_speed", "area_weight"]
    assert space.names[2:] == BEND
    assert space["wind_speed"].bounds == (0.0, 10.0) and space["wind_speed"].scaling == "linear"
    assert space["area_weight"].bounds == (0.10, 0.17) and space["area_weight"].scaling == "linear"
    for name in BEND:
        assert space[name].bounds == (0.1, 10.0) and space[name].scaling == "log"
        assert space[name].centre == pytest.approx(1.0)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"grid_u": 2}, "grid_u"),
        ({"pin_mode": "middle"}, "pin_mode"),
        ({"substeps": 0}, "substeps"),
        ({"fps": 25.0, "substeps": 1, "n_frames": 5}, "too large"),
        ({"pole_height": 0.5}, "pole_height"),
        ({"strain_limit": 2.0}, "strain_limit"),
    ],
)
def test_bad_settings_are_user_errors(kwargs, message):
    with pytest.raises(UserInputError, match=message):
        FlagSimConfig(**kwargs).validate()


def test_make_simulator_rejects_unknown_settings():
    with pytest.raises(UserInputError, match="unknown flag simulator setting"):
        make_simulator(resolution=3)


def test_bad_parameters_are_user_errors(sim):
    with pytest.raises(UserInputError, match="unknown parameter"):
        sim.simulate({"wind": 3.0})
    with pytest.raises(UserInputError, match="outside its bounds"):
        sim.simulate({"wind_speed": 12.0})
    with pytest.raises(UserInputError, match="seeds"):
        sim.simulate_batch([{}, {}], seeds=[0])


def test_config_round_trips_through_a_dict():
    config = FlagSimConfig(grid_u=16, grid_v=11, pin_mode="corners")
    assert FlagSimConfig(**config.to_dict()) == config
    assert config.dt == pytest.approx(1 / (25 * 48))
    assert config.warmup_frames == 50 and config.duration == pytest.approx(4.4)


def test_automatic_substeps_follow_the_grid_spacing():
    assert FlagSimConfig().steps_per_frame == 48
    assert FlagSimConfig(grid_u=61, grid_v=41).steps_per_frame == 96
    assert FlagSimConfig(grid_u=16, grid_v=11).steps_per_frame == 48  # never coarser than 1/1200 s
    assert FlagSimConfig(substeps=30).steps_per_frame == 30


# -- trajectory conventions ----------------------------------------------------------------


def test_trajectory_conventions(sim):
    traj = sim.simulate({"wind_speed": 6.0}, seed=0)
    c = sim.config
    n_nodes = c.grid_u * c.grid_v
    assert traj.vertices.shape == (60, n_nodes, 3) and traj.vertices.dtype == np.float32
    assert traj.faces.dtype == np.int32 and traj.faces.max() == n_nodes - 1
    assert traj.fps == 25.0
    uv, pole = traj.extras["uv"], traj.extras["pole"]
    assert uv.shape == (n_nodes, 2) and uv.dtype == np.float32 and uv.min() == 0 and uv.max() == 1
    assert pole.shape == (2, 3) and pole.dtype == np.float32
    np.testing.assert_allclose(pole[:, :2], 0.0)
    # The pole reaches from the ground to above the flag; the hoist edge stays on it.
    assert pole[0, 2] == 0.0 and pole[1, 2] >= traj.vertices[..., 2].max()
    hoist = uv[:, 0] == 0
    np.testing.assert_allclose(traj.vertices[:, hoist, :2], 0.0, atol=1e-6)
    assert traj.vertices[:, hoist, 2].min() > pole[0, 2]
    # In a 6 m/s wind along +x the flag streams towards +x.
    fly = uv[:, 0] == 1
    assert traj.vertices[:, fly, 0].mean() > 0.8 * c.width
    np.testing.assert_array_equal(traj.extras["grid_shape"], [c.grid_v, c.grid_u])


def test_corner_pinning_holds_only_the_corners_and_limits_strain():
    sim = make_simulator(pin_mode="corners", n_frames=20)
    traj = sim.simulate({"wind_speed": 10.0, "area_weight": 0.1})
    hoist = grid_vertices(traj)[:, :, 0]
    np.testing.assert_allclose(hoist[:, [0, -1], :2], 0.0, atol=1e-6)
    assert np.abs(hoist[:, 1:-1, :2]).max() > 0.02  # the rest of the hoist edge is free
    edges = sim.mesh.edges
    stretch = np.linalg.norm(traj.vertices[:, edges[:, 1]] - traj.vertices[:, edges[:, 0]], axis=-1)
    stretch /= sim.mesh.edge_length
    assert np.percentile(stretch, 99) < 1.08 and stretch.max() < 1.2


def test_wind_direction_setting_turns_the_flag():
    sim = make_simulator(wind_direction_deg=90.0, n_frames=10)
    traj = sim.simulate({"wind_speed": 6.0})
    fly = traj.extras["uv"][:, 0] == 1
    assert traj.vertices[:, fly, 1].mean() > 1.0 and abs(traj.vertices[:, fly, 0].mean()) < 0.5


def test_simulator_contract():
    check_simulator(make_simulator(n_frames=10, warmup_s=0.4))


def test_batch_matches_single_and_seeds_matter(sim):
    params = [{"wind_speed": 3.0}, {"wind_speed": 7.0, "area_weight": 0.1, **all_bending(3.0)}]
    batch = sim.simulate_batch(params, seeds=[4, 5])
    for traj, p, s in zip(batch, params, [4, 5], strict=True):
        # Exactly equal: the refinement's batches and noise floors rely on it (a chaotic flag
        # would amplify any rounding difference).
        np.testing.assert_array_equal(traj.vertices, sim.simulate(p, seed=s).vertices)
    other = sim.simulate(params[0], seed=6)
    assert np.abs(other.vertices - batch[0].vertices).max() > 0.01  # chaotic: seeds differ


def test_blow_up_raises_simulation_failed():
    unstable = make_simulator(substeps=8, n_frames=5, warmup_s=1.0)
    with pytest.raises(SimulationFailed):
        unstable.simulate({"wind_speed": 9.0, "area_weight": 0.1})
    with pytest.raises(SimulationFailed, match="of 2 flags failed"):
        unstable.simulate_batch([{"wind_speed": 0.0, "area_weight": 0.17, **all_bending(0.1)},
                                 {"wind_speed": 9.0, "area_weight": 0.1}], seeds=[0, 0])


def test_partial_batch_keeps_the_flags_that_did_not_fail():
    sim = make_simulator(n_frames=5, warmup_s=0.4)
    unstable = make_simulator(n_frames=5, warmup_s=0.4, substeps=8)
    good = sim.simulate_batch_partial([{"wind_speed": 3.0}], seeds=[0])
    assert good[0] is not None and good[0].is_finite()
    mixed = unstable.simulate_batch_partial([{"wind_speed": 9.0, "area_weight": 0.1}], seeds=[0])
    assert mixed == [None]


# -- effects plug into the wind --------------------------------------------------------------


class Yaw(Effect):
    """A test effect turning the wind by ``yaw_deg`` (the real effects live elsewhere)."""

    name = "test_yaw"
    description = "turns the wind"
    phenomenon = "flag"
    parameter_space = ParameterSpace([ParameterSpec("yaw_deg", (0.0, 90.0), "deg")])

    def term(self, state: WindState, params, t: float) -> WindState:
        return replace(state, yaw=np.radians(params["yaw_deg"]))


class OtherPhenomenon(Yaw):
    phenomenon = "pendulum_lab"


def test_an_effect_rewrites_the_wind_without_touching_the_solver():
    sim = make_simulator(effects=[Yaw()], n_frames=10)
    assert sim.parameter_space.names[-1] == "yaw_deg" and len(sim.parameter_space) == 18
    fly = sim.mesh.uv[:, 0] == 1
    straight = sim.simulate({"wind_speed": 6.0, "yaw_deg": 0.0}).vertices[:, fly]
    turned = sim.simulate({"wind_speed": 6.0, "yaw_deg": 90.0}).vertices[:, fly]
    assert straight[..., 0].mean() > 1.0 and turned[..., 1].mean() > 1.0
    with pytest.raises(UserInputError, match="pendulum_lab"):
        make_simulator(effects=[OtherPhenomenon()])


# -- physical checks: fast versions ---------------------------------------------------------


def test_no_wind_hangs_and_settles():
    sim = make_simulator(warmup_s=0.0, n_frames=150)
    traj = sim.simulate({"wind_speed": 0.0})
    ke = kinetic_energy(traj, 0.135 * sim.mesh.node_area)
    assert ke[-25:].mean() < 0.05 * ke[:25].mean()
    fly = grid_vertices(traj)[-1, :, -1]
    assert np.abs(fly[:, 0]).max() < 0.4  # the fly edge has swung down next to the pole
    assert fly[:, 2].mean() < sim.config.pole_height - sim.config.height  # and hangs low


def test_no_blow_up_for_eight_parameter_sets_including_corners(sim):
    space = sim.parameter_space
    rng = np.random.default_rng(8)
    units = [np.full(17, -1.0), np.full(17, 1.0), np.r_[1.0, -1.0, np.full(15, 1.0)],
             np.r_[-1.0, 1.0, np.full(15, -1.0)]] + list(rng.uniform(-1, 1, (4, 17)))
    trajs = sim.simulate_batch([space.from_unit(u) for u in units], seeds=list(range(8)))
    assert all(t.is_finite() for t in trajs)


def test_flapping_frequency_rises_with_wind_fast():
    sim = make_simulator(n_frames=100)
    slow_wind, fast_wind = sim.simulate_batch([{"wind_speed": 2.0}, {"wind_speed": 8.0}], seeds=[0, 0])
    rates = [zero_crossing_rate([fly_edge_crosswind(t)], 25.0) for t in (slow_wind, fast_wind)]
    assert rates[1] > 2.0 * rates[0]


def test_heavier_flag_hangs_lower_at_low_wind(sim):
    params = [{"wind_speed": 2.0, "area_weight": aw} for aw in (0.10, 0.10, 0.17, 0.17)]
    trajs = sim.simulate_batch(params, seeds=[0, 1, 0, 1])
    fly_z = [grid_vertices(t)[:, :, -1, 2].mean() for t in trajs]
    assert np.mean(fly_z[2:]) < np.mean(fly_z[:2]) - 0.05


def test_stiffer_flag_folds_less(sim):
    params = [{"wind_speed": 2.0, **all_bending(m)} for m in (0.1, 0.1, 10.0, 10.0)]
    folds = [mean_fold_angle(t) for t in sim.simulate_batch(params, seeds=[0, 1, 0, 1])]
    assert np.mean(folds[2:]) < 0.85 * np.mean(folds[:2])


# -- physical checks: long records (slow) -------------------------------------------------------


@pytest.mark.slow
def test_no_wind_settles_over_twenty_seconds():
    sim = make_simulator(warmup_s=0.0, n_frames=500)
    for aw in (0.10, 0.17):
        traj = sim.simulate({"wind_speed": 0.0, "area_weight": aw})
        ke = kinetic_energy(traj, aw * sim.mesh.node_area)
        per_second = ke[: 475].reshape(19, 25).mean(axis=1)
        assert per_second[-1] < 2e-3 * per_second[0]


@pytest.mark.slow
def test_no_blow_up_for_fifty_random_parameter_sets(sim):
    space = sim.parameter_space
    units = np.random.default_rng(50).uniform(-1, 1, (50, 17))
    units[0], units[1] = -1.0, 1.0
    trajs = sim.simulate_batch([space.from_unit(u) for u in units], seeds=list(range(50)))
    assert all(t.is_finite() for t in trajs)


@pytest.mark.slow
def test_flapping_frequency_rises_with_wind_long_records():
    """Spectra averaged over five fly-edge points and three seeds of 8 s, cross-checked
    by the zero-crossing rate (Taneda 1968: the frequency grows with the flow speed)."""
    sim = make_simulator(n_frames=200)
    winds, seeds = [1.0, 4.0, 7.0, 10.0], [0, 1, 2]
    trajs = sim.simulate_batch([{"wind_speed": w} for w in winds for _ in seeds],
                               seeds=[s for _ in winds for s in seeds])
    dominant, centroid, zc = [], [], []
    for k in range(len(winds)):
        sig = [fly_edge_crosswind(t) for t in trajs[k * 3:(k + 1) * 3]]
        dominant.append(dominant_frequency(sig, 25.0))
        centroid.append(spectral_centroid(sig, 25.0))
        zc.append(zero_crossing_rate(sig, 25.0))
    assert np.all(np.diff(dominant) > 0), dominant
    assert np.all(np.diff(centroid) > 0), centroid
    assert np.all(np.diff(zc) > 0), zc
    # The two estimators agree on the flapping frequency once the flag flaps.
    for d, z in zip(dominant[1:], zc[1:], strict=True):
        assert 0.4 < d / z < 2.5


@pytest.mark.slow
def test_each_direction_stiffens_its_own_folds():
    """Multiplying one direction's five samples by 10 reduces the folding of the hinges of
    that direction (0°, 45°, 90° to the warp) more than of the other two."""
    sim = make_simulator(n_frames=100)
    direction = sim.mesh.hinge_direction
    seeds = [0, 1, 2]
    settings = [{}] + [{n: 10.0 for n in BEND if n.startswith(f"bend_{d}deg")} for d in (0, 45, 90)]
    trajs = sim.simulate_batch([{"wind_speed": 2.0, **o} for o in settings for _ in seeds], seeds=seeds * 4)
    folds = []
    for k in range(len(settings)):
        theta = np.concatenate([np.abs(dihedral_angles(t.vertices, sim.mesh.hinges))
                                for t in trajs[k * 3:(k + 1) * 3]])
        folds.append(np.array([theta[:, np.isclose(direction, row)].mean() for row in (0.0, 1.0, 2.0)]))
    for row in range(3):
        ratio = folds[row + 1] / folds[0]
        others = np.delete(ratio, row)
        assert ratio[row] < 0.9 and ratio[row] < others.min(), (row, ratio)


def test_a_longer_recording_starts_with_the_shorter_one():
    from physinfer_flag.phenomenon import make_simulator as phenomenon_simulator

    assert phenomenon_simulator().config.n_frames == 60
    assert phenomenon_simulator(duration_s=8.0).config.n_frames == 200  # 25 fps
    assert phenomenon_simulator(duration_s=0.41).config.n_frames == 11  # rounded up
    params = {"wind_speed": 5.0}
    short = make_simulator(grid_u=8, grid_v=6, n_frames=6, warmup_s=0.2).simulate(params, seed=4).vertices
    long = make_simulator(grid_u=8, grid_v=6, n_frames=12, warmup_s=0.2).simulate(params, seed=4).vertices
    np.testing.assert_array_equal(long[:6], short)
