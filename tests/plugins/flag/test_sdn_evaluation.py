"""Triplet accuracy and wind-speed regression."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer_flag.sdn.baselines import SpectralPooling
from physinfer_flag.sdn.data import as_features
from physinfer_flag.sdn.evaluation import (
    RegressionConfig,
    evaluate_triplets,
    evaluate_wind,
    make_triplets,
    regression_metrics,
    target_column,
    triplet_accuracy,
)
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.synthetic import grating_dataset

FRONT = FrontEndConfig(n_frames=16, size=32)


def test_triplets_pair_an_anchor_with_a_positive_and_a_negative():
    labels = np.array([0, 0, 0, 1, 1, 2])
    triplets = make_triplets(labels, seed=3)
    assert len(triplets) == 5  # the lone clip of label 2 cannot anchor
    a, p, n = triplets.T
    assert np.all(labels[a] == labels[p]) and np.all(a != p) and np.all(labels[a] != labels[n])
    assert len(make_triplets(labels, n_triplets=12, seed=0)) == 12
    np.testing.assert_array_equal(make_triplets(labels, seed=3), triplets)  # seeded
    with pytest.raises(UserInputError, match="no triplet"):
        make_triplets(np.array([0, 1, 2]))


def test_triplet_accuracy_counts_strictly_closer_positives():
    e = np.array([[0.0], [1.0], [3.0], [1.0]])
    triplets = np.array([[0, 1, 2], [0, 2, 1], [0, 1, 3]])  # right, wrong, tie (wrong)
    assert triplet_accuracy(e, triplets) == pytest.approx(1 / 3)


def test_regression_metrics():
    m = regression_metrics(np.array([1.0, 2.0, 3.6]), np.array([1.2, 2.5, 3.0]))
    assert m == {
        "mse": pytest.approx((0.04 + 0.25 + 0.36) / 3),
        "acc_at_0_5": pytest.approx(2 / 3),
        "n": 3,
    }


def test_spectral_features_regress_the_grating_frequency():
    train = grating_dataset(n_thetas=30, renders_per_sim=2, seed=0)
    test = grating_dataset(n_thetas=15, renders_per_sim=2, seed=1)
    pooling = SpectralPooling(frontend=FRONT, grid=2)
    config = RegressionConfig(target="frequency_hz", epochs=40, lr=3e-3, hidden=32, seed=0)
    scores = evaluate_wind(pooling, train, test, config=config, device="cpu")
    variance = float(np.var(test.theta[:, 0]))
    assert scores["n"] == len(test)
    assert scores["mse"] < 0.4 * variance  # far better than predicting the mean (bins are 1.6 Hz)
    # Cached features give the same answer as clips.
    cached = evaluate_wind(
        pooling,
        as_features(train, FRONT, device="cpu"),
        as_features(test, FRONT, device="cpu"),
        config=config,
        device="cpu",
    )
    assert cached["mse"] == pytest.approx(scores["mse"], rel=1e-4)


def test_triplet_evaluation_of_the_spectral_baseline_beats_chance():
    val = grating_dataset(n_thetas=12, renders_per_sim=3, seed=2)
    scores = evaluate_triplets(SpectralPooling(frontend=FRONT, grid=2), val, device="cpu")
    assert scores["n_triplets"] == 36 and scores["triplet_accuracy"] > 0.7


def test_regression_target_must_exist():
    data = grating_dataset(n_thetas=2, renders_per_sim=2)
    assert target_column(data, "direction_rad") == 1 and target_column(data, 0) == 0
    with pytest.raises(UserInputError, match="wind_speed"):
        target_column(data, "wind_speed")
    with pytest.raises(UserInputError, match="column 5"):
        target_column(data, 5)
