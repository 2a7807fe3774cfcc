"""Tests of physinfer_hanging_cloth.generate: synthetic fabrics and a Bouman-format dataset."""

from __future__ import annotations

import json

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.video import read_video
from physinfer_hanging_cloth.data import load_dataset, load_ground_truth
from physinfer_hanging_cloth.generate import (
    SyntheticSettings,
    generate_dataset,
    sample_fabrics,
    table_text,
)
from physinfer_hanging_cloth.simulator import hanging_cloth_parameter_space
from physinfer_hanging_cloth.units import REAL_AREA_WEIGHT_OZ_YD2, REAL_STIFFNESS_LBF_IN2

TINY = SyntheticSettings(n_fabrics=3, n_frames=3, image_size=32, seed=5)


def test_fabrics_span_the_real_ranges_and_are_reproducible():
    settings = SyntheticSettings()
    fabrics = sample_fabrics(settings)
    assert len(fabrics) == 30 and fabrics[0].name == "fabric01" and fabrics[-1].name == "fabric30"
    stiffness = np.array([np.mean(f.stiffness) for f in fabrics])
    weight = np.array([np.mean(f.area_weight) for f in fabrics])
    assert REAL_STIFFNESS_LBF_IN2[0] * 0.9 < stiffness.min() and stiffness.max() < REAL_STIFFNESS_LBF_IN2[1] * 1.1
    assert REAL_AREA_WEIGHT_OZ_YD2[0] * 0.9 < weight.min() and weight.max() < REAL_AREA_WEIGHT_OZ_YD2[1] * 1.1
    assert np.ptp(np.log(stiffness)) > 1.5 and np.ptp(np.log(weight)) > 1.5  # spread over the ranges
    assert all(f.stiffness[0] != f.stiffness[1] for f in fabrics)  # two different measurements
    space = hanging_cloth_parameter_space()
    for fabric in fabrics:
        space.complete(fabric.params())  # inside the bounds
    assert sample_fabrics(settings) == fabrics
    assert sample_fabrics(SyntheticSettings(seed=1)) != fabrics


def test_table_round_trips_through_the_loader(tmp_path):
    fabrics = sample_fabrics(TINY)
    (tmp_path / "ground_truth.csv").write_text(table_text(fabrics))
    truth = load_ground_truth(tmp_path / "ground_truth.csv")
    assert list(truth) == [f.name for f in fabrics]
    for f in fabrics:
        assert truth[f.name].stiffness == pytest.approx(np.mean(f.stiffness))
        assert truth[f.name].area_weight == pytest.approx(np.mean(f.area_weight))


def test_generate_writes_the_bouman_layout_and_resumes(tmp_path):
    out = tmp_path / "bouman"
    progress = []
    summary = generate_dataset(out, TINY, on_video=lambda done, total: progress.append(done))
    assert summary["written"] == 9 and summary["kept"] == 0 and progress == [1, 2, 3]
    dataset = load_dataset(out)
    assert dataset.n_fabrics == 3 and len(dataset.videos) == 9
    clip = read_video(dataset.videos[0].path)
    assert clip.frames.shape == (3, 32, 32, 3) and clip.fps == pytest.approx(25.0)
    stored = json.loads((out / "synthetic.json").read_text())
    assert stored["settings"]["seed"] == 5 and len(stored["fabrics"]) == 3
    # The fan levels of one fabric differ; its look does not change between them.
    a, c = (read_video(v.path).frames for v in dataset.videos[:3:2])
    assert not np.array_equal(a, c)
    (out / "videos" / "fabric02_W2.mp4").unlink()
    again = generate_dataset(out, TINY)
    assert again["written"] == 1 and again["kept"] == 8
    with pytest.raises(UserInputError, match="other settings"):
        generate_dataset(out, SyntheticSettings(n_fabrics=3, n_frames=3, image_size=32, seed=6))


def test_generate_refuses_foreign_data_and_bad_settings(tmp_path):
    (tmp_path / "d" / "videos").mkdir(parents=True)
    with pytest.raises(UserInputError, match="not made by this generator"):
        generate_dataset(tmp_path / "d", TINY)
    for bad in (SyntheticSettings(n_fabrics=2), SyntheticSettings(n_frames=1), SyntheticSettings(image_size=8)):
        with pytest.raises(UserInputError):
            generate_dataset(tmp_path / "e", bad)
