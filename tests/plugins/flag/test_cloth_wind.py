"""Tests of physinfer_flag.cloth_wind: the wind schedule the solver reads per substep."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.roles import Effect
from physinfer_flag.cloth_wind import (
    WindSchedule,
    WindState,
    sample_wind,
    shear_factor,
    wind_at_time,
)


class LinearRamp(Effect):
    """A test effect: the speed grows by ``ramp`` m/s per second, the yaw is fixed."""

    name = "test_ramp"
    description = "speed ramp"
    phenomenon = "flag"
    parameter_space = ParameterSpace([ParameterSpec("ramp", (0.0, 2.0), "m/s^2")])

    def term(self, state: WindState, params, t: float) -> WindState:
        return replace(state, speed=state.speed + params["ramp"] * t, yaw=0.25, shear_exponent=0.1)


def test_constant_wind_is_one_sample():
    sched = sample_wind(WindState(speed=4.0, z_ref=2.0), duration=3.0, direction=0.5)
    assert sched.table.shape == (1, 4)
    np.testing.assert_array_equal(sched.table[0], [4.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(sched.scalars(), [sched.dt, 2.0, 0.5])
    assert wind_at_time(sched.table, sched.dt, 2.7) == (4.0, 0.0, 0.0, 0.0)


def test_effects_rewrite_every_sample():
    sched = sample_wind(WindState(speed=4.0, z_ref=2.0, seed=3), duration=1.0, effects=[LinearRamp()],
                        params={"ramp": 2.0}, dt=0.1)
    assert sched.table.shape[0] >= 11
    np.testing.assert_allclose(sched.table[:11, 0], 4.0 + 2.0 * 0.1 * np.arange(11))
    np.testing.assert_allclose(sched.table[:, 1:], np.tile([0.25, 0.1, 0.0], (sched.table.shape[0], 1)))
    speed, yaw, shear, inclination = wind_at_time(sched.table, sched.dt, 0.55)
    assert inclination == 0.0
    assert speed == pytest.approx(4.0 + 2.0 * 0.55) and yaw == pytest.approx(0.25) and shear == pytest.approx(0.1)
    # Before the start and after the end the samples are held.
    assert wind_at_time(sched.table, sched.dt, -1.0)[0] == pytest.approx(4.0)
    assert wind_at_time(sched.table, sched.dt, 100.0)[0] == pytest.approx(sched.table[-1, 0])


def test_shear_profile():
    assert shear_factor(5.0, 0.0, 2.0) == 1.0
    assert shear_factor(4.0, 0.5, 1.0) == pytest.approx(2.0)
    assert shear_factor(-1.0, 0.2, 2.0) == pytest.approx((0.05 / 2.0) ** 0.2)  # floored height


def test_a_wind_table_of_another_width_is_refused():
    # The compiled solver reads four columns without bounds checks.
    with pytest.raises(ValueError, match=r"\(K, 4\)"):
        WindSchedule(dt=0.01, table=np.zeros((5, 3)), z_ref=1.0, direction=0.0)
