"""Tests of physinfer_hanging_cloth.fan: fan levels, turbulence and the wind schedule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer_hanging_cloth.fan import (
    FAN_LEVELS,
    FanSettings,
    fan_level_index,
    fan_schedule,
    turbulence,
)


@pytest.mark.parametrize(("text", "index"), [("W1", 0), ("w2", 1), ("3", 2), (" W3 ", 2)])
def test_fan_level_names(text, index):
    assert fan_level_index(text) == index


@pytest.mark.parametrize("text", ["W4", "W0", "fast", ""])
def test_unknown_fan_level_is_refused(text):
    with pytest.raises(UserInputError, match="fan level"):
        fan_level_index(text)


@pytest.mark.parametrize(
    "bad",
    [
        {"speeds": (2.0, 1.0, 3.0)},
        {"speeds": (1.0, 2.0)},
        {"speeds": (1.0, 2.0, 30.0)},
        {"gust_intensity": 1.5},
        {"yaw_amplitude_deg": 90.0},
        {"f_min": 4.0, "f_max": 3.0},
        {"n_modes": 0},
    ],
)
def test_bad_fan_settings_are_refused(bad):
    with pytest.raises(UserInputError):
        FanSettings(**bad).validate()


def test_turbulence_has_zero_mean_unit_spread_and_depends_on_the_seed():
    times = np.arange(0, 200, 0.01)
    noise = turbulence(3, times, FanSettings())
    assert noise.shape == (2, times.size)
    assert np.abs(noise.mean(axis=1)).max() < 0.1
    assert noise.std(axis=1) == pytest.approx([1.0, 1.0], abs=0.1)
    np.testing.assert_array_equal(noise, turbulence(3, times, FanSettings()))
    assert not np.allclose(noise, turbulence(4, times, FanSettings()))


def test_schedule_blows_along_plus_y_at_the_levels_mean_speed():
    settings = FanSettings()
    for level, speed in zip(FAN_LEVELS, settings.speeds, strict=True):
        schedule = fan_schedule(settings, level=level, seed=1, duration=60.0, z_ref=1.0)
        assert schedule.direction == pytest.approx(math.pi / 2)
        assert schedule.table.shape[1] == 4 and schedule.table.shape[0] * schedule.dt >= 60.0
        assert schedule.table[:, 0].mean() == pytest.approx(speed, rel=0.05)
        assert (schedule.table[:, 0] >= 0).all()
        assert np.degrees(schedule.table[:, 1]).std() == pytest.approx(settings.yaw_amplitude_deg, rel=0.2)
        assert (schedule.table[:, 2:] == 0).all()  # no shear, horizontal


def test_no_gusts_gives_a_steady_fan():
    schedule = fan_schedule(FanSettings(gust_intensity=0.0, yaw_amplitude_deg=0.0), level="W2", seed=0,
                            duration=2.0, z_ref=1.0)
    np.testing.assert_allclose(schedule.table[:, 0], FanSettings().speeds[1])
    np.testing.assert_allclose(schedule.table[:, 1], 0.0)
