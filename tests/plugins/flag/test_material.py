"""Tests of physinfer_flag.material: the camel-ponte-roma tables and the bending multipliers."""

from __future__ import annotations

import json

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer_flag.material import (
    ClothMaterial,
    bending_length,
    bending_multipliers,
    bending_parameter_names,
    load_material,
    scaled_bending,
)


def test_bending_names_are_direction_major_and_readable():
    names = bending_parameter_names()
    assert len(names) == 15
    assert names[:5] == ["bend_0deg_c00", "bend_0deg_c05", "bend_0deg_c10", "bend_0deg_c15", "bend_0deg_c20"]
    assert names[5] == "bend_45deg_c00" and names[-1] == "bend_90deg_c20"
    assert len(set(names)) == 15 and all(n.isidentifier() for n in names)


def test_shipped_material_matches_the_paper_data():
    mat = load_material()
    assert mat.name == "camel-ponte-roma"
    assert mat.density == pytest.approx(0.284)
    assert mat.bending.shape == (3, 5) and mat.stretching.shape == (6, 4)
    assert mat.bending[0, 0] == pytest.approx(3.6348366e-05)
    samples = mat.stretching_samples()
    assert samples.shape == (2, 5, 4)
    # Strain 0 repeats row 0 for every direction; strain 1/6 holds rows 1-5 in order.
    np.testing.assert_array_equal(samples[0], np.tile(mat.stretching[0], (5, 1)))
    np.testing.assert_array_equal(samples[1], mat.stretching[1:])


def test_bending_length_is_about_three_centimetres():
    # The figure: (B / (rho_A g))^(1/3) ~ 3 cm for this fabric.
    assert 0.02 < bending_length(load_material(), 0.13) < 0.04


def test_multipliers_scale_each_entry_independently():
    mat = load_material()
    names = bending_parameter_names()
    params = {n: 1.0 for n in names}
    params["bend_45deg_c10"] = 10.0
    params["bend_90deg_c00"] = 0.1
    mult = bending_multipliers(params)
    scaled = scaled_bending(mat, mult)
    assert scaled[1, 2] == pytest.approx(10 * mat.bending[1, 2])
    assert scaled[2, 0] == pytest.approx(0.1 * mat.bending[2, 0])
    untouched = np.ones((3, 5), bool)
    untouched[1, 2] = untouched[2, 0] = False
    np.testing.assert_array_equal(scaled[untouched], mat.bending[untouched])


def test_missing_or_bad_multipliers_are_user_errors():
    names = bending_parameter_names()
    with pytest.raises(UserInputError, match="bend_90deg_c20"):
        bending_multipliers({n: 1.0 for n in names[:-1]})
    with pytest.raises(UserInputError, match="positive"):
        bending_multipliers({**{n: 1.0 for n in names}, names[3]: -1.0})


def test_load_material_reports_bad_files(tmp_path):
    with pytest.raises(UserInputError, match="cannot read cloth material"):
        load_material(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"density": 0.2, "bending": [[1, 2]], "stretching": [[0] * 4] * 6}))
    with pytest.raises(UserInputError, match="bending must be 3x5"):
        load_material(bad)
    good = tmp_path / "mine.json"
    good.write_text(json.dumps({"density": 0.2, "bending": [[1e-5] * 5] * 3, "stretching": [[10.0] * 4] * 6}))
    assert load_material(good).name == "mine"


def test_material_rejects_negative_bending():
    with pytest.raises(UserInputError, match="negative"):
        ClothMaterial("x", 0.1, -np.ones((3, 5)), np.ones((6, 4)))
