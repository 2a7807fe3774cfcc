"""Scene ranges (issue 23, item 0): datasets that vary a scene setting per simulation, and
posterior estimators trained on them that take the setting as an input.

``dataset generate --scene-range NAME=LOW:HIGH`` draws each simulation's setting (keyed, so
a dataset is a function of its seed), simulates and renders it in that scene and records it
per clip; ``posterior train`` appends the settings to the embedding; ``infer --scene-set``
gives them at inference, and a scene outside the trained ranges is refused. The flag and
sbi are real; the flags are small and the clips short so that it runs in seconds.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from physinfer import ParameterSpace, ParameterSpec
from physinfer.errors import UserInputError
from physinfer.plugins import load_registry
from physinfer.scene import default_scene, parse_scene_ranges, sample_scene, scene_context

#: Small flags (11 × 7 grids and less than twice that) simulate in a fraction of a second.
RANGES = ("flag_length=0.5:0.7", "flag_height=0.3:0.45")


@pytest.fixture(scope="module")
def flag():
    return load_registry()[0].phenomenon("flag")


@pytest.mark.parametrize(
    ("item", "expected"),
    [
        ("flag_lenght=1:2", "--scene-range: unknown scene setting(s) flag_lenght for 'flag'; known:"),
        ("pinning=hoist:corners", "--scene-range pinning=hoist:corners: only float settings can be ranged"),
        ("flag_length=1", "--scene-range flag_length=1: give LOW:HIGH"),
        ("flag_length=3:1", "--scene-range flag_length=3:1: LOW must be below HIGH"),
        ("flag_length=0.1:3", "--scene-range flag_length=0.1:3: out of range; give 0.5 to 4 m"),
        ("flag_length=a:3", "--scene-range flag_length=a:3: give a number"),
    ],
)
def test_bad_scene_ranges_are_one_clear_line(flag, item, expected):
    with pytest.raises(UserInputError) as caught:
        parse_scene_ranges(flag, [item])
    assert str(caught.value).startswith(expected)


def test_ranges_are_drawn_log_uniformly_and_deterministically(flag):
    ranges = parse_scene_ranges(flag, ["flag_length=0.9:3", "flag_height=0.6:2"])
    assert ranges == {"flag_length": (0.9, 3.0), "flag_height": (0.6, 2.0)}
    draws = [sample_scene(np.random.default_rng(i), ranges) for i in range(4000)]
    lengths = np.array([d["flag_length"] for d in draws])
    assert lengths.min() >= 0.9 and lengths.max() <= 3.0
    # Log-uniform: the median is the geometric mean of the ends (1.64 m), not the mean (1.95).
    assert np.median(lengths) == pytest.approx(np.sqrt(0.9 * 3.0), rel=0.03)
    assert sample_scene(np.random.default_rng(7), ranges) == draws[7]
    assert scene_context(ranges, draws[0]) == pytest.approx(
        [np.log(draws[0]["flag_height"]), np.log(draws[0]["flag_length"])]
    )


@pytest.fixture(scope="module")
def ranged_set(tmp_path_factory, physinfer_cli) -> Path:
    """60 + 10 simulations of small flags whose size varies, 1-s clips at 32 px."""
    root = tmp_path_factory.mktemp("scene-ranges") / "flags"
    ranges = [a for r in RANGES for a in ("--scene-range", r)]
    proc = physinfer_cli(
        "dataset", "generate", "--plugin", "flag", "--sims", "60,0,10", "--renders-per-sim", "1",
        "--frames", "25", "--size", "32", "--workers", "0", "--seed", "3", *ranges, "--out", str(root),
        "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    return root


def test_a_ranged_dataset_simulates_each_clip_in_its_own_scene(ranged_set, physinfer_cli):
    from physinfer.datasets.loader import ClipDataset

    config = json.loads((ranged_set / "dataset.json").read_text())["config"]
    assert config["scene_ranges"] == {"flag_height": [0.3, 0.45], "flag_length": [0.5, 0.7]}
    data = ClipDataset(ranged_set, None)
    assert data.scene_ranges == config["scene_ranges"] and len(data.scenes) == 70
    lengths = [s["flag_length"] for s in data.scenes]
    assert min(lengths) >= 0.5 and max(lengths) <= 0.7 and len(set(lengths)) == 70
    for i in (0, 1, 2):
        extent = np.ptp(data.trajectory(int(data.sim_ids[i])).vertices[0], axis=0)
        assert extent[0] == pytest.approx(data.scenes[i]["flag_length"], rel=0.15)  # along the wind
    # A resume with another range is refused with the difference, before anything runs.
    proc = physinfer_cli(
        "dataset", "generate", "--plugin", "flag", "--sims", "60,0,10", "--renders-per-sim", "1",
        "--frames", "25", "--size", "32", "--workers", "0", "--seed", "3", "--scene-range",
        "flag_length=0.5:0.8", "--scene-range", RANGES[1], "--out", str(ranged_set), "--json",
    )  # fmt: skip
    assert proc.returncode == 2
    assert "scene_ranges.flag_length: [0.5, 0.7] there, [0.5, 0.8] now" in proc.json()["error"]


def test_a_setting_cannot_be_both_fixed_and_ranged(physinfer_cli, tmp_path):
    proc = physinfer_cli(
        "dataset", "generate", "--plugin", "flag", "--sims", "2,0,0", "--scene-set", "flag_length=1",
        "--scene-range", "flag_length=0.9:2", "--out", str(tmp_path / "d"), "--json",
    )  # fmt: skip
    assert proc.returncode == 2
    assert "flag_length: given both --scene-set and --scene-range" in proc.json()["error"]


@pytest.fixture(scope="module")
def ranged_estimator(ranged_set, physinfer_cli) -> Path:
    out = ranged_set.parent / "sizes.safetensors"
    proc = physinfer_cli(
        "posterior", "train", "--plugin", "flag", "--data", str(ranged_set), "--out", str(out),
        "--embedder", "spectral", "--embedder-frames", "25", "--max-epochs", "5", "--device", "cpu",
        "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.json()["scene_ranges"] == {"flag_height": [0.3, 0.45], "flag_length": [0.5, 0.7]}
    return out


def test_an_estimator_trained_across_sizes_takes_the_size_and_refuses_sizes_outside(
    ranged_estimator, ranged_set, physinfer_cli, tmp_path, flag
):
    from physinfer.posterior.estimator import PosteriorEstimator

    estimator = PosteriorEstimator.load(ranged_estimator)
    ranges = estimator.config.scene_ranges
    assert ranges == {"flag_height": [0.3, 0.45], "flag_length": [0.5, 0.7]}
    assert estimator.config.x_dim == estimator.config.embedding_dim + 2
    inside = ["--scene-set", "flag_length=0.6", "--scene-set", "flag_height=0.4"]
    proc = physinfer_cli(
        "infer", "--plugin", "flag", "--posterior", str(ranged_estimator), *inside,
        "--out", str(tmp_path / "in"), "--samples", "200", "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.json()["scene"]["flag_length"] == 0.6
    # The default 1.5 m flag lies outside the trained sizes: refused, naming the range.
    proc = physinfer_cli(
        "infer", "--plugin", "flag", "--posterior", str(ranged_estimator),
        "--out", str(tmp_path / "out"), "--samples", "200", "--json",
    )  # fmt: skip
    assert proc.returncode == 2
    assert "flag_length=1.5 (trained on 0.5..0.7)" in proc.json()["error"]
    # A fixed setting other than the training clips' is refused too.
    corners = {**default_scene(flag), "flag_length": 0.6, "flag_height": 0.4, "pinning": "corners"}
    with pytest.raises(UserInputError, match="its other settings were"):
        estimator.check_scene(flag, corners)
    # Both sizes outside: refine's one-line note keeps the whole reason (it holds "; "), not the remedy.
    from physinfer.posterior.infer_workflow import _first_clause

    with pytest.raises(UserInputError) as refused:
        estimator.check_scene(flag, {**default_scene(flag), "flag_length": 2.0, "flag_height": 1.0})
    reason = _first_clause(refused.value)
    assert "flag_height=1 (trained on 0.3..0.45); flag_length=2 (trained on 0.5..0.7)" in reason
    assert "dataset generate" not in reason and "dataset generate" in str(refused.value)
    # Calibration runs on the held-out split with each clip's size as input.
    proc = physinfer_cli(
        "evaluate", "calibration", "--plugin", "flag", "--posterior", str(ranged_estimator),
        "--data", str(ranged_set), "--samples", "100", "--out", str(tmp_path / "cal"), "--json",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_the_size_is_an_input_the_samples_depend_on(ranged_estimator, ranged_set):
    from physinfer.posterior.estimator import PosteriorEstimator

    estimator = PosteriorEstimator.load(ranged_estimator)
    (cached,) = (ranged_set / "embeddings").glob("*-train.npz")
    with np.load(cached, allow_pickle=False) as data:
        embedding = data["x"][0]  # a training clip's embedding: in the flow's domain
    assert embedding.shape == (estimator.config.embedding_dim,)
    small = estimator.condition(embedding, {"flag_length": 0.5, "flag_height": 0.3})
    large = estimator.condition(embedding, {"flag_length": 0.7, "flag_height": 0.45})
    assert small[-1] == pytest.approx(np.log(0.5)) and small[-2] == pytest.approx(np.log(0.3))
    assert not np.allclose(estimator.sample_unit(small, 50), estimator.sample_unit(large, 50))
    with pytest.raises(UserInputError, match="takes the scene settings flag_height, flag_length"):
        estimator.condition(embedding, None)


def test_the_shipped_estimator_for_a_scene_is_the_first_that_covers_it(ranged_estimator, flag):
    from physinfer.posterior.loading import _shipped_for_scene

    default = Path(flag.default_posterior)
    record = replace(flag, scene_posteriors=(str(ranged_estimator),))
    small = {**default_scene(flag), "flag_length": 0.6, "flag_height": 0.4}
    assert _shipped_for_scene(record, default, small, "cpu")[1] == ranged_estimator
    assert _shipped_for_scene(record, default, None, "cpu")[1] == default
    # A scene nobody covers: the default's refusal, with what the others cover.
    large = {**default_scene(flag), "flag_length": 3.5}
    with pytest.raises(UserInputError) as refused:
        _shipped_for_scene(record, default, large, "cpu")
    assert "trained on clips of the default scene, not of the scene flag_length=3.5" in str(refused.value)
    assert "sizes.safetensors covers flag_height 0.3..0.45, flag_length 0.5..0.7" in str(refused.value)
    # Without scene estimators the default comes back; its refusal is the caller's to raise.
    alone = replace(flag, scene_posteriors=())
    assert _shipped_for_scene(alone, default, large, "cpu")[1] == default


def test_pairs_without_ranges_condition_on_the_embedding_alone():
    from physinfer.posterior.features import EmbeddedSet

    space = ParameterSpace([ParameterSpec("a", (0.0, 1.0))])
    x = np.ones((4, 3), dtype=np.float32)
    pairs = EmbeddedSet(space, np.zeros((4, 1), np.float32), x, np.arange(4), Path("unused"))
    assert pairs.conditions is x
