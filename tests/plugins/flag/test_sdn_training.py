"""Contrastive training of the SDN on tiny moving-grating datasets: learning, checkpoints, resume."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from physinfer.errors import UserInputError
from physinfer_flag.sdn.data import ArrayDataset, as_features, subset
from physinfer_flag.sdn.evaluation import evaluate_triplets
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.network import SDN, SDNConfig
from physinfer_flag.sdn.synthetic import grating_dataset
from physinfer_flag.sdn.training import (
    HISTORY_FILE,
    TrainConfig,
    label_batches,
    read_checkpoint,
    train_sdn,
)
from physinfer_flag.sdn.weights import load_sdn

TINY = SDNConfig(
    frontend=FrontEndConfig(n_frames=16, size=32), widths=(8, 16, 32), embedding_dim=16, pool_grid=2
)
FAST = TrainConfig(epochs=6, batch_size=16, progress=False)


# Wide contrast and a moving distractor over half of each clip: an untrained network is
# fooled often (about 0.75 triplet accuracy), so passing the test needs learning.
NUISANCE = {"contrast_range": (0.03, 0.45), "distractor": 1.0}


@pytest.fixture(scope="module")
def splits():
    train = grating_dataset(n_thetas=20, seeds_per_theta=2, renders_per_sim=3, seed=0, **NUISANCE)
    val = grating_dataset(n_thetas=15, seeds_per_theta=2, renders_per_sim=3, seed=1, **NUISANCE)
    # Features once for the whole module: the front end is fixed, so this is what training sees.
    return as_features(train, TINY.frontend, device="cpu"), as_features(
        val, TINY.frontend, device="cpu"
    )


def test_label_batches_cover_every_clip_once_with_positives():
    labels = np.repeat(np.arange(10), 5)
    batches = label_batches(labels, batch_size=12, clips_per_label=4, rng=np.random.default_rng(0))
    everything = np.concatenate(batches)
    assert sorted(everything.tolist()) == list(range(50))
    assert all(len(b) <= 12 for b in batches)
    assert all(
        len(np.unique(labels[b])) < len(b) for b in batches[:-1]
    )  # positives in each full batch


def test_training_lowers_the_loss_and_beats_chance_and_the_untrained_network(tmp_path, splits):
    train, val = splits
    torch.manual_seed(FAST.seed)  # train_sdn starts from this very initialisation
    untrained = evaluate_triplets(SDN(config=TINY), val, device="cpu")["triplet_accuracy"]
    result = train_sdn(train, val, out_dir=tmp_path, model_config=TINY, config=FAST, device="cpu")
    losses = [h["train_loss"] for h in result.history]
    assert len(losses) == FAST.epochs and losses[-1] < 0.5 * losses[0]
    model = load_sdn(result.weights, "cpu")
    scores = evaluate_triplets(model, val, device="cpu")
    assert scores["n_triplets"] == len(val)
    assert scores["triplet_accuracy"] > 0.8  # chance is 0.5
    assert scores["triplet_accuracy"] > untrained + 0.05
    assert scores["triplet_accuracy"] == pytest.approx(result.best["val_triplet_accuracy"])
    history = json.loads((tmp_path / HISTORY_FILE).read_text())
    assert history["best"]["epoch"] == result.best_epoch
    assert json.dumps(result.to_dict())  # what `physinfer train --json` prints


def test_resuming_continues_exactly_where_a_run_stopped(tmp_path, splits):
    train, val = splits
    three, one = (TrainConfig(epochs=n, batch_size=16, progress=False) for n in (3, 1))
    straight = train_sdn(
        train, val, out_dir=tmp_path / "a", model_config=TINY, config=three, device="cpu"
    )
    first = train_sdn(
        train, val, out_dir=tmp_path / "b", model_config=TINY, config=one, device="cpu"
    )
    assert first.epochs_completed == 1
    resumed = train_sdn(
        train, val, out_dir=tmp_path / "b", model_config=TINY, config=three, device="cpu"
    )
    assert resumed.epochs_completed == 3
    np.testing.assert_allclose(
        [h["train_loss"] for h in resumed.history],
        [h["train_loss"] for h in straight.history],
        rtol=1e-5,
    )
    a, _, _ = read_checkpoint(tmp_path / "a" / "checkpoint.safetensors")
    b, _, _ = read_checkpoint(tmp_path / "b" / "checkpoint.safetensors")
    for name in a:
        torch.testing.assert_close(a[name], b[name], rtol=1e-4, atol=1e-5)
    again = train_sdn(
        train, val, out_dir=tmp_path / "b", model_config=TINY, config=three, device="cpu"
    )
    assert again.history == resumed.history  # a finished run has nothing left to do


def test_resume_refuses_other_settings_or_data(tmp_path, splits):
    train, val = splits
    config = TrainConfig(epochs=1, batch_size=16, progress=False)
    train_sdn(train, val, out_dir=tmp_path, model_config=TINY, config=config, device="cpu")
    with pytest.raises(UserInputError, match="lr"):
        train_sdn(
            train,
            val,
            out_dir=tmp_path,
            model_config=TINY,
            config=TrainConfig(epochs=2, lr=1e-3, batch_size=16, progress=False),
            device="cpu",
        )
    with pytest.raises(UserInputError, match="train fingerprint"):
        train_sdn(
            subset(train, np.arange(60)),
            val,
            out_dir=tmp_path,
            model_config=TINY,
            config=config,
            device="cpu",
        )
    fresh = train_sdn(
        train,
        val,
        out_dir=tmp_path,
        model_config=TINY,
        config=TrainConfig(epochs=1, lr=1e-3, batch_size=16, progress=False),
        resume=False,
        device="cpu",
    )
    assert fresh.epochs_completed == 1


def test_positives_across_simulation_seeds(tmp_path, splits):
    train, val = splits
    result = train_sdn(
        train,
        val,
        out_dir=tmp_path,
        model_config=TINY,
        config=TrainConfig(epochs=2, batch_size=16, positives="theta", progress=False),
        device="cpu",
    )
    scores = evaluate_triplets(
        load_sdn(result.weights, "cpu"), val, positives="theta", device="cpu"
    )
    assert scores["triplet_accuracy"] > 0.6
    no_groups = ArrayDataset(
        inputs=train.inputs,
        sim_ids=train.sim_ids,
        theta=train.theta,
        kind="features",
        frontend_config=TINY.frontend,
    )
    with pytest.raises(UserInputError, match="group ids"):
        train_sdn(
            no_groups,
            None,
            out_dir=tmp_path / "x",
            model_config=TINY,
            config=TrainConfig(epochs=1, positives="theta", progress=False),
        )


def test_clip_datasets_must_match_the_network(tmp_path):
    wrong_fps = grating_dataset(n_thetas=3, renders_per_sim=2, fps=30.0)
    with pytest.raises(UserInputError, match="fps"):
        train_sdn(wrong_fps, None, out_dir=tmp_path, model_config=TINY, config=FAST, device="cpu")
    singletons = grating_dataset(n_thetas=4, renders_per_sim=1)
    with pytest.raises(UserInputError, match="no positive pairs"):
        train_sdn(singletons, None, out_dir=tmp_path, model_config=TINY, config=FAST, device="cpu")
