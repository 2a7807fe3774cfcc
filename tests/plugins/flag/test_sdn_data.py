"""The SDN dataset interface: array datasets, θ groups, the generated-dataset adapter."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer_flag.sdn.data import (
    ArrayDataset,
    PreparedClips,
    SDNDataset,
    as_features,
    group_ids_from_theta,
    subset,
)
from physinfer_flag.sdn.frontend import FrontEndConfig, frontend_features
from physinfer_flag.sdn.synthetic import grating_dataset

FRONT = FrontEndConfig(n_frames=16, size=32)


class StoredClips:
    """The attributes of physinfer.datasets.ClipDataset that PreparedClips reads."""

    def __init__(self, frames: np.ndarray, fps: float, params: np.ndarray) -> None:
        self.frames, self.fps, self.params = frames, fps, params
        self.sim_ids = np.arange(len(frames)) // 2
        self.param_names = ["wind_speed", "area_weight"]

    def clips(self, indices):
        return self.frames[np.asarray(indices)]


def test_array_dataset_reads_batches_in_the_order_asked():
    data = grating_dataset(n_thetas=3, renders_per_sim=2)
    assert isinstance(data, SDNDataset) and len(data) == 6
    batch = data.get_batch(np.array([4, 1, 3]))
    np.testing.assert_array_equal(batch, data.inputs[[4, 1, 3]])
    part = subset(data, [5, 0])
    np.testing.assert_array_equal(part.sim_ids, data.sim_ids[[5, 0]])
    np.testing.assert_array_equal(part.group_ids, data.group_ids[[5, 0]])


def test_array_dataset_refuses_inconsistent_arrays():
    clips = np.zeros((4, 16, 32, 32), dtype=np.uint8)
    with pytest.raises(UserInputError, match="uint8"):
        ArrayDataset(inputs=clips.astype(np.float32), sim_ids=np.zeros(4), theta=np.zeros((4, 1)))
    with pytest.raises(UserInputError, match="sim_ids"):
        ArrayDataset(inputs=clips, sim_ids=np.zeros(3), theta=np.zeros((4, 1)))
    with pytest.raises(UserInputError, match="frontend_config"):
        ArrayDataset(
            inputs=np.zeros((4, 4, 16, 16), np.float32),
            sim_ids=np.zeros(4),
            theta=np.zeros((4, 1)),
            kind="features",
        )


def test_theta_groups_are_identical_theta_rows():
    theta = np.array([[1.0, 2.0], [3.0, 0.0], [1.0, 2.0], [1.0, 2.5]])
    groups = group_ids_from_theta(theta)
    assert groups[0] == groups[2] and len(set(groups.tolist())) == 3


def test_features_are_computed_once_and_checked_against_the_network():
    data = grating_dataset(n_thetas=2, renders_per_sim=2)
    features = as_features(data, FRONT, device="cpu")
    assert features.kind == "features" and features.inputs.shape == (4, 4, 16, 16)
    np.testing.assert_allclose(
        features.inputs, frontend_features(data.inputs, config=FRONT, device="cpu")
    )
    assert as_features(features, FRONT) is features
    with pytest.raises(UserInputError, match="recompute"):
        as_features(features, FrontEndConfig(n_frames=16, size=32, sigma_t=2.0))


def test_prepared_clips_adapts_a_generated_dataset():
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (4, 40, 48, 64, 3), dtype=np.uint8)
    params = np.array([[1.0, 0.1], [1.0, 0.1], [5.0, 0.2], [1.0, 0.1]])
    view = PreparedClips(StoredClips(rgb, 50.0, params), config=FRONT)
    batch = view.get_batch(np.array([2, 0]))
    assert batch.shape == (2, 16, 32, 32) and batch.dtype == np.uint8
    assert view.theta_names == ("wind_speed", "area_weight")
    assert view.group_ids[0] == view.group_ids[1] == view.group_ids[3] != view.group_ids[2]
    # Stored clips already in the network's format are only cut.
    ready = rng.integers(0, 256, (2, 20, 32, 32), dtype=np.uint8)
    np.testing.assert_array_equal(
        PreparedClips(StoredClips(ready, 25.0, params[:2]), config=FRONT).get_batch([1]),
        ready[[1], :16],
    )
    with pytest.raises(UserInputError, match="16"):
        PreparedClips(StoredClips(ready[:, :10], 25.0, params[:2]), config=FRONT).get_batch([0])
