import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.parameters import ParameterSpace, ParameterSpec, parse_float_assignments


def space():
    return ParameterSpace(
        [ParameterSpec("wind_speed", (0.0, 10.0), "m/s"), ParameterSpec("k", (0.1, 10.0), scaling="log")]
    )


def test_round_trip_and_centre():
    s = space()
    params = {"wind_speed": 7.5, "k": 3.0}
    np.testing.assert_allclose(list(s.from_unit(s.to_unit(params)).values()), [7.5, 3.0])
    centre = s.from_unit(np.zeros(2))
    assert centre["wind_speed"] == pytest.approx(5.0)
    assert centre["k"] == pytest.approx(1.0)  # geometric centre on a log scale
    assert s.to_unit({"wind_speed": 0.0, "k": 10.0}).tolist() == pytest.approx([-1.0, 1.0])


def test_complete_checks_names_and_bounds():
    s = space()
    assert s.complete({"k": 2.0}) == {"wind_speed": 5.0, "k": 2.0}
    with pytest.raises(UserInputError, match=r"wind_speed=12 is outside its bounds \[0, 10\] m/s"):
        s.complete({"wind_speed": 12})
    with pytest.raises(UserInputError, match="unknown parameter 'wnd'; known parameters: wind_speed, k"):
        s.complete({"wnd": 1})


def test_invalid_specs_are_refused():
    with pytest.raises(ValueError, match="log scaling needs positive bounds"):
        ParameterSpec("k", (0.0, 1.0), scaling="log")
    with pytest.raises(ValueError, match="low < high"):
        ParameterSpec("k", (1.0, 1.0))
    with pytest.raises(ValueError, match="duplicate"):
        ParameterSpace([ParameterSpec("a", (0, 1)), ParameterSpec("a", (0, 2))])


def test_serialisation_round_trip():
    s = space()
    assert ParameterSpace.from_dict(s.to_dict()) == s


def test_parse_assignments_errors():
    assert parse_float_assignments(["a=1", "b = 2.5"]) == {"a": 1.0, "b": 2.5}
    with pytest.raises(UserInputError, match="expects NAME=VALUE"):
        parse_float_assignments(["a"])
    with pytest.raises(UserInputError, match="not a number"):
        parse_float_assignments(["a=x"])


def test_at_bounds_names_the_side_in_linear_and_log_ranges_and_skips_an_off_default():
    space = ParameterSpace(
        [
            ParameterSpec("speed", (1.0, 10.0)),
            ParameterSpec("weight", (0.01, 1.0), scaling="log"),
            ParameterSpec("intensity", (0.0, 0.5), default=0.0),  # an effect, off at its lower bound
        ]
    )
    assert space.at_bounds({"speed": 10.0, "weight": 0.01, "intensity": 0.5}) == {
        "speed": "upper", "weight": "lower", "intensity": "upper"
    }
    assert space.at_bounds({"speed": 9.995, "weight": 0.01002, "intensity": 0.0}) == {"speed": "upper", "weight": "lower"}
    assert space.at_bounds({"speed": 9.9, "weight": 0.02, "intensity": 0.25}) == {}
    assert space.at_bounds({"speed": 1.0}) == {"speed": "lower"}, "parameters not given are not checked"
