"""Tests of physinfer_flag.effects: each effect rewrites the wind as it says and moves the flag."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.plugins import load_registry
from physinfer_flag.cloth_wind import WindState, sample_wind
from physinfer_flag.effects import WindGusts, WindInclination, WindShear, WindYaw, unit_ou_path
from physinfer_flag.simulator import make_simulator

#: A coarse, short flag: the effects' influence shows within a second of simulated time.
SMALL = {"grid_u": 16, "grid_v": 11, "n_frames": 10, "warmup_s": 1.0}
BASE = WindState(speed=6.0, z_ref=2.45, seed=7)


def _schedule(effect, params, seed=7, duration=60.0):
    return sample_wind(
        WindState(speed=6.0, z_ref=2.45, seed=seed), duration=duration, effects=[effect], params=params
    ).table


def test_ou_path_statistics_and_determinism():
    path = unit_ou_path(3, 0.5, 40_000)
    assert path.mean() == pytest.approx(0.0, abs=0.1)
    assert path.std() == pytest.approx(1.0, abs=0.1)
    lag = 50  # 0.5 s = one time scale: correlation exp(-1)
    corr = np.corrcoef(path[:-lag], path[lag:])[0, 1]
    assert corr == pytest.approx(math.exp(-1.0), abs=0.08)
    np.testing.assert_array_equal(path, unit_ou_path(3, 0.5, 40_000))
    # A longer path extends a shorter one (blocks are seeded one by one).
    np.testing.assert_array_equal(unit_ou_path(3, 0.5, 1500), path[:1500])
    assert not np.allclose(path[:1000], unit_ou_path(4, 0.5, 1000))


def test_gusts_fluctuate_the_speed_with_the_given_intensity():
    table = _schedule(WindGusts(), {"gust_intensity": 0.2, "gust_timescale": 0.5})
    speed = table[:, 0]
    assert speed.mean() == pytest.approx(6.0, rel=0.05)
    assert speed.std() == pytest.approx(0.2 * 6.0, rel=0.2)
    np.testing.assert_array_equal(table[:, 1:], 0.0)  # yaw and shear untouched
    # Deterministic per seed, different across seeds.
    again = _schedule(WindGusts(), {"gust_intensity": 0.2, "gust_timescale": 0.5})
    np.testing.assert_array_equal(table, again)
    other = _schedule(WindGusts(), {"gust_intensity": 0.2, "gust_timescale": 0.5}, seed=8)
    assert not np.allclose(table[:, 0], other[:, 0])


def test_gusts_time_scale_sets_how_fast_the_speed_changes():
    fast = _schedule(WindGusts(), {"gust_intensity": 0.2, "gust_timescale": 0.2})[:, 0]
    slow = _schedule(WindGusts(), {"gust_intensity": 0.2, "gust_timescale": 5.0})[:, 0]
    assert np.abs(np.diff(fast)).mean() > 3 * np.abs(np.diff(slow)).mean()


def test_gusts_off_at_zero_intensity_and_speed_never_negative():
    table = _schedule(WindGusts(), {"gust_intensity": 0.0, "gust_timescale": 1.0})
    np.testing.assert_array_equal(table[:, 0], 6.0)
    strong = _schedule(WindGusts(), {"gust_intensity": 0.5, "gust_timescale": 1.0}, duration=600.0)
    assert strong[:, 0].min() >= 0.0


def test_shear_yaw_and_inclination_set_their_columns():
    table = _schedule(WindShear(), {"shear_exponent": 0.3}, duration=1.0)
    np.testing.assert_allclose(table, np.tile([6.0, 0.0, 0.3, 0.0], (len(table), 1)))
    table = _schedule(WindYaw(), {"wind_yaw_deg": -30.0}, duration=1.0)
    np.testing.assert_allclose(table, np.tile([6.0, math.radians(-30.0), 0.0, 0.0], (len(table), 1)))
    table = _schedule(WindInclination(), {"wind_inclination_deg": 15.0}, duration=1.0)
    np.testing.assert_allclose(table, np.tile([6.0, 0.0, 0.0, math.radians(15.0)], (len(table), 1)))


@pytest.mark.parametrize("effect", [WindGusts(), WindShear(), WindYaw(), WindInclination()])
def test_defaults_are_the_baseline_and_bounds_are_checked(effect):
    sim = make_simulator([effect], **SMALL)
    base = make_simulator([], **SMALL).simulate({"wind_speed": 6.0}, seed=3).vertices
    # Every effect is off at its defaults: the augmented model reproduces the baseline.
    np.testing.assert_array_equal(sim.simulate({"wind_speed": 6.0}, seed=3).vertices, base)
    spec = effect.parameter_space.specs[0]
    with pytest.raises(UserInputError, match="outside its bounds"):
        sim.simulate({"wind_speed": 6.0, spec.name: spec.bounds[1] + 1.0}, seed=3)


@pytest.fixture(scope="module")
def baseline_motion():
    return make_simulator([], **SMALL).simulate({"wind_speed": 6.0}, seed=3).vertices


def test_yaw_turns_the_flag_about_the_pole(baseline_motion):
    sim = make_simulator([WindYaw()], **SMALL)
    left = sim.simulate({"wind_speed": 6.0, "wind_yaw_deg": 40.0}, seed=3).vertices
    right = sim.simulate({"wind_speed": 6.0, "wind_yaw_deg": -40.0}, seed=3).vertices
    # Counter-clockwise yaw blows towards +y: the fly end follows, by about sin(40°) of its reach.
    assert left[..., 1].mean() > 0.3 > abs(baseline_motion[..., 1].mean())
    assert right[..., 1].mean() < -0.3


def test_inclination_lifts_or_lowers_the_flag(baseline_motion):
    sim = make_simulator([WindInclination()], **SMALL)
    up = sim.simulate({"wind_speed": 6.0, "wind_inclination_deg": 25.0}, seed=3).vertices
    down = sim.simulate({"wind_speed": 6.0, "wind_inclination_deg": -25.0}, seed=3).vertices
    # An updraft lifts the fly end, a downdraft lowers it; neither turns the flag sideways.
    height = [v[..., 2].mean() for v in (down, baseline_motion, up)]
    assert height[0] + 0.02 < height[1] < height[2] - 0.02
    assert abs(up[..., 1].mean()) < 0.1 and abs(down[..., 1].mean()) < 0.1


def test_shear_changes_the_shape_between_top_and_bottom(baseline_motion):
    sim = make_simulator([WindShear()], **SMALL)
    sheared = sim.simulate({"wind_speed": 3.0, "shear_exponent": 0.6}, seed=3).vertices
    plain = make_simulator([], **SMALL).simulate({"wind_speed": 3.0}, seed=3).vertices
    nv, nu = SMALL["grid_v"], SMALL["grid_u"]
    top_minus_bottom = [
        (v.reshape(len(v), nv, nu, 3)[:, -1, -1, 2] - v.reshape(len(v), nv, nu, 3)[:, 0, -1, 2]).mean()
        for v in (sheared, plain)
    ]
    # More wind at the top than at the bottom changes how the fly edge hangs between them.
    assert not np.allclose(sheared, plain)
    assert top_minus_bottom[0] != pytest.approx(top_minus_bottom[1], abs=1e-3)


def test_gusts_change_the_motion_and_depend_on_the_seed(baseline_motion):
    sim = make_simulator([WindGusts()], **SMALL)
    params = {"wind_speed": 6.0, "gust_intensity": 0.4, "gust_timescale": 0.3}
    a = sim.simulate(params, seed=3).vertices
    assert np.abs(a - baseline_motion).max() > 0.05
    np.testing.assert_array_equal(a, sim.simulate(params, seed=3).vertices)


def test_effects_are_registered_for_the_flag():
    registry, _ = load_registry()
    names = ("wind_gusts", "wind_shear", "wind_yaw", "wind_inclination")
    assert set(names) <= set(registry.effects_of("flag"))
    for name in names:
        effect = registry.effect(name, phenomenon="flag")
        assert effect.name == name and effect.description
        assert registry.get("effects", name).description == effect.description
