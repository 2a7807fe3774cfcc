"""Tests of physinfer_hanging_cloth.evaluation: leave-one-fabric-out PCA + regression, Pearson R."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physinfer.embedders import GridSpectrumConfig, GridSpectrumEmbedder
from physinfer.errors import UserInputError
from physinfer.video import write_video
from physinfer_hanging_cloth.data import load_dataset
from physinfer_hanging_cloth.evaluation import (
    embed_videos,
    evaluate_embeddings,
    leave_one_group_out,
    pearson,
    plot_bars,
)
from physinfer_hanging_cloth.units import OZ_PER_YD2_IN_G_PER_M2

N_FABRICS = 12


def write_table(root: Path, area_weight_unit: str, area_weight_scale: float, stiffness: np.ndarray,
                area_weight: np.ndarray) -> None:
    lines = [f"fabric,area_weight_1 [{area_weight_unit}],area_weight_2 [{area_weight_unit}],"
             "stiffness_1 [lbf*in^2],stiffness_2 [lbf*in^2]"]
    for i in range(len(stiffness)):
        aw = float(area_weight[i]) * area_weight_scale
        st = float(stiffness[i])
        lines.append(f"f{i:02d},{aw * 0.98!r},{aw * 1.02!r},{st * 0.9!r},{st * 1.1!r}")
    root.mkdir(parents=True, exist_ok=True)
    (root / "ground_truth.csv").write_text("\n".join(lines) + "\n")
    (root / "videos").mkdir(exist_ok=True)
    for i in range(len(stiffness)):
        for k in (1, 2, 3):
            (root / "videos" / f"f{i:02d}_W{k}.mp4").write_bytes(b"")


@pytest.fixture(scope="module")
def truth():
    rng = np.random.default_rng(0)
    return np.exp(rng.uniform(np.log(0.0075), np.log(0.1), N_FABRICS)), np.exp(rng.uniform(np.log(1.7), np.log(16.7), N_FABRICS))


def informative_features(dataset, rng, noise=0.1):
    """Embeddings that carry the log truths linearly, plus nuisance dimensions and noise."""
    t = dataset.targets()
    n = len(dataset.videos)
    signal = np.stack([t["stiffness"], t["area_weight"]], axis=1)
    mixing = rng.standard_normal((2, 40))
    return signal @ mixing + noise * rng.standard_normal((n, 40)) + rng.standard_normal((1, 40))


def test_pearson():
    assert pearson(np.array([1, 2, 3.0]), np.array([2, 4, 6.5])) == pytest.approx(0.9986, abs=1e-3)
    assert pearson(np.array([1, 2, 3.0]), np.array([3, 2, 1.0])) == pytest.approx(-1.0)
    assert np.isnan(pearson(np.ones(3), np.array([1, 2, 3.0])))


def test_informative_embeddings_score_high_and_noise_scores_low(tmp_path, truth):
    write_table(tmp_path / "d", "oz/yd^2", 1.0, *truth)
    dataset = load_dataset(tmp_path / "d")
    rng = np.random.default_rng(1)
    good = evaluate_embeddings(dataset, informative_features(dataset, rng))
    assert good.pearson_stiffness > 0.95 and good.pearson_area_weight > 0.95
    assert good.n_videos == 3 * N_FABRICS and good.n_fabrics == N_FABRICS
    assert good.pca_dims == min(50, 3 * (N_FABRICS - 1) - 1, 40)
    noise = evaluate_embeddings(dataset, rng.standard_normal((3 * N_FABRICS, 40)))
    assert abs(noise.pearson_stiffness) < 0.6 and abs(noise.pearson_area_weight) < 0.6


def test_a_fabric_never_trains_its_own_prediction():
    # Each group's rows share a random feature vector and a random target: only memorising
    # the held-out group itself could predict it; leave-one-group-out must not.
    rng = np.random.default_rng(2)
    groups = np.repeat(np.arange(15), 3)
    features = np.repeat(rng.standard_normal((15, 30)), 3, axis=0)
    targets = np.repeat(rng.standard_normal((15, 1)), 3, axis=0)
    predictions, _ = leave_one_group_out(features, targets, groups, pca_dims=50)
    assert abs(pearson(predictions[:, 0], targets[:, 0])) < 0.7
    # The same model scored in-sample (no folds) memorises them.
    from sklearn.linear_model import LinearRegression

    in_sample = LinearRegression().fit(features, targets).predict(features)
    assert pearson(in_sample[:, 0], targets[:, 0]) > 0.99


def test_a_unit_change_leaves_r_unchanged(tmp_path, truth):
    write_table(tmp_path / "oz", "oz/yd^2", 1.0, *truth)
    write_table(tmp_path / "gsm", "g/m^2", OZ_PER_YD2_IN_G_PER_M2, *truth)
    in_oz, in_gsm = load_dataset(tmp_path / "oz"), load_dataset(tmp_path / "gsm")
    assert in_gsm.fabrics["f00"].area_weight == pytest.approx(in_oz.fabrics["f00"].area_weight)
    features = informative_features(in_oz, np.random.default_rng(3), noise=1.0)
    a, b = evaluate_embeddings(in_oz, features), evaluate_embeddings(in_gsm, features)
    assert a.pearson_area_weight == pytest.approx(b.pearson_area_weight, abs=1e-9)
    assert a.pearson_stiffness == pytest.approx(b.pearson_stiffness, abs=1e-9)
    # A scaled unit (every value ×c) shifts log truth and predictions alike: R stays.
    write_table(tmp_path / "scaled", "oz/yd^2", 7.5, *truth)
    c = evaluate_embeddings(load_dataset(tmp_path / "scaled"), features)
    assert c.pearson_area_weight == pytest.approx(a.pearson_area_weight, abs=1e-9)
    np.testing.assert_allclose(c.predictions["area_weight"] - a.predictions["area_weight"], np.log(7.5), atol=1e-9)


def test_mismatched_or_non_finite_embeddings_are_refused(tmp_path, truth):
    write_table(tmp_path / "d", "oz/yd^2", 1.0, *truth)
    dataset = load_dataset(tmp_path / "d")
    with pytest.raises(UserInputError, match="embeddings"):
        evaluate_embeddings(dataset, np.zeros((5, 3)))
    bad = np.zeros((len(dataset.videos), 3))
    bad[0, 0] = np.nan
    with pytest.raises(UserInputError, match="NaN"):
        evaluate_embeddings(dataset, bad)


def test_embed_videos_reads_real_videos_and_refuses_short_ones(tmp_path, truth):
    root = tmp_path / "d"
    write_table(root, "oz/yd^2", 1.0, truth[0][:3], truth[1][:3])
    rng = np.random.default_rng(4)
    for path in (root / "videos").iterdir():
        write_video(path, rng.integers(0, 255, (12, 32, 32, 3), dtype=np.uint8), fps=25.0)
    dataset = load_dataset(root)
    embedder = GridSpectrumEmbedder(config=GridSpectrumConfig(n_frames=10, size=16, grid=2, n_bands=4, f_max=5.0))
    calls = []
    embeddings = embed_videos(dataset, embedder, on_video=lambda done, total: calls.append((done, total)), batch=4)
    assert embeddings.shape == (9, 2 * 2 * (4 + 4)) and np.isfinite(embeddings).all()
    assert calls == [(4, 9), (8, 9), (9, 9)]
    long_embedder = GridSpectrumEmbedder(config=GridSpectrumConfig(n_frames=20, size=16, grid=2, n_bands=4))
    with pytest.raises(UserInputError, match="lasts"):
        embed_videos(dataset, long_embedder)


def test_bar_chart_is_written(tmp_path, truth):
    write_table(tmp_path / "d", "oz/yd^2", 1.0, *truth)
    dataset = load_dataset(tmp_path / "d")
    result = evaluate_embeddings(dataset, informative_features(dataset, np.random.default_rng(5)))
    path = plot_bars(result, tmp_path / "out" / "bouman.png", label="test")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert result.summary().keys() >= {"pearson_stiffness", "pearson_area_weight", "n_videos", "n_fabrics"}
