"""Tests of physinfer_hanging_cloth.units: unit spellings, factors and the stiffness convention."""

from __future__ import annotations

import math

import pytest

from physinfer.errors import UserInputError
from physinfer_hanging_cloth.simulator import AREA_WEIGHT_BOUNDS, BENDING_MULTIPLIER_BOUNDS
from physinfer_hanging_cloth.units import (
    LBF_IN2_IN_N_M2,
    MIDDLE_MULTIPLIER,
    OZ_PER_YD2_IN_G_PER_M2,
    REAL_AREA_WEIGHT_OZ_YD2,
    REAL_STIFFNESS_LBF_IN2,
    kg_m2_to_oz_yd2,
    multiplier_to_stiffness,
    normalise_unit,
    oz_yd2_to_kg_m2,
    stiffness_to_multiplier,
    unit_factor,
)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("oz/yd²", "oz/yd^2"),
        (" OZ / YD^2 ", "oz/yd^2"),
        ("g/m2", "g/m^2"),
        ("lbf·in²", "lbf*in^2"),
        ("lbf in^2", "lbf*in^2"),
        ("lbf*in**2", "lbf*in^2"),
        ("µN·m²", "un*m^2"),
        ("N.m^2", "n*m^2"),
    ],
)
def test_normalise_unit_spellings(text, expected):
    assert normalise_unit(text) == expected


def test_unit_factors_convert_to_canonical_units():
    assert unit_factor("area_weight", "oz/yd^2") == 1.0
    assert unit_factor("area_weight", "g/m²") == pytest.approx(1 / OZ_PER_YD2_IN_G_PER_M2)
    assert 339.05747 * unit_factor("area_weight", "g/m^2") == pytest.approx(10.0)
    assert unit_factor("area_weight", "kg/m^2") == pytest.approx(1000 / OZ_PER_YD2_IN_G_PER_M2)
    assert unit_factor("stiffness", "lbf·in²") == 1.0
    assert LBF_IN2_IN_N_M2 * unit_factor("stiffness", "N*m^2") == pytest.approx(1.0)
    assert unit_factor("stiffness", "mN*m^2") == pytest.approx(1e-3 / LBF_IN2_IN_N_M2)


@pytest.mark.parametrize(("quantity", "unit"), [("area_weight", "lbf*in^2"), ("stiffness", "oz/yd^2"), ("stiffness", "")])
def test_unknown_or_wrong_quantity_unit_is_refused(quantity, unit):
    with pytest.raises(UserInputError, match="unit"):
        unit_factor(quantity, unit)


def test_area_weight_conversion_round_trip():
    assert oz_yd2_to_kg_m2(1.0) == pytest.approx(0.033905747)
    assert kg_m2_to_oz_yd2(oz_yd2_to_kg_m2(7.3)) == pytest.approx(7.3)


def test_stiffness_convention_is_proportional_with_the_middle_at_six():
    middle = math.sqrt(REAL_STIFFNESS_LBF_IN2[0] * REAL_STIFFNESS_LBF_IN2[1])
    assert stiffness_to_multiplier(middle) == pytest.approx(MIDDLE_MULTIPLIER)
    assert stiffness_to_multiplier(2 * middle) == pytest.approx(2 * MIDDLE_MULTIPLIER)
    assert multiplier_to_stiffness(stiffness_to_multiplier(0.05)) == pytest.approx(0.05)


def test_real_ranges_lie_inside_the_parameter_bounds():
    low, high = (stiffness_to_multiplier(s) for s in REAL_STIFFNESS_LBF_IN2)
    assert BENDING_MULTIPLIER_BOUNDS[0] < low < high < BENDING_MULTIPLIER_BOUNDS[1]
    low, high = (oz_yd2_to_kg_m2(w) for w in REAL_AREA_WEIGHT_OZ_YD2)
    assert AREA_WEIGHT_BOUNDS[0] < low < high < AREA_WEIGHT_BOUNDS[1]
