"""The dataset-directory entry points behind ``physinfer train`` / ``physinfer evaluate``.

A grating "phenomenon" goes through the real dataset engine (in process), so these tests
read the same on-disk format that FlagSim will have.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from physinfer import ParameterSpace, ParameterSpec, Trajectory
from physinfer.datasets import (
    ClipFormat,
    DatasetGenerator,
    DatasetPreset,
    SplitCounts,
    generate_dataset,
)
from physinfer.errors import UserInputError
from physinfer.types import Clip
from physinfer_flag.sdn.evaluation import RegressionConfig
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.network import SDNConfig
from physinfer_flag.sdn.synthetic import grating_wave, to_uint8
from physinfer_flag.sdn.training import TrainConfig
from physinfer_flag.sdn.workflows import (
    evaluate_triplets_in_directory,
    evaluate_wind_in_directory,
    train_from_directory,
)

TINY = SDNConfig(
    frontend=FrontEndConfig(n_frames=16, size=32), widths=(8, 16, 32), embedding_dim=16, pool_grid=2
)


class GratingGenerator(DatasetGenerator):
    """θ = (wind_speed as a temporal frequency, direction); ζ = contrast and phase."""

    phenomenon = "gratings"
    parameter_space = ParameterSpace(
        [
            ParameterSpec("wind_speed", (1.0, 8.0), "Hz"),
            ParameterSpec("direction", (0.0, 3.0), "rad"),
        ]
    )

    def simulate_batch(self, params, seeds, *, clip):
        out = []
        for p in params:
            verts = np.zeros((clip.n_frames, 3, 3), dtype=np.float32)
            extras = {"theta": np.array([p["wind_speed"], p["direction"]])}
            out.append(Trajectory(verts, np.array([[0, 1, 2]], dtype=np.int32), clip.fps, extras))
        return out

    def sample_render_params(self, rng):
        return {"contrast": float(rng.uniform(0.15, 0.45)), "phase": float(rng.uniform(0, 6.28))}

    def render(self, trajectory, render_params, *, clip):
        freq, direction = trajectory.extras["theta"]
        wave = grating_wave(
            frequency_hz=freq,
            direction_rad=direction,
            n_frames=clip.n_frames,
            size=clip.width,
            fps=clip.fps,
            wavelength_px=12.0,
            phase=render_params["phase"],
        )
        return Clip(to_uint8(0.5 + render_params["contrast"] * wave)[..., None], clip.fps)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("gratings") / "data"
    preset = DatasetPreset(
        name="tiny",
        sims=SplitCounts(12, 6, 6),
        renders=SplitCounts(36, 18, 18),
        clip=ClipFormat(n_frames=20, fps=25.0, height=32, width=32, channels=1),
    )
    generate_dataset(GratingGenerator(), root, preset=preset, seed=1, workers=0)
    return root


def test_train_then_evaluate_a_dataset_directory(tmp_path, data):
    config = TrainConfig(epochs=3, batch_size=12, progress=False)
    summary = train_from_directory(
        data, tmp_path / "model", model_config=TINY, train_config=config, device="cpu"
    )
    assert summary["epochs_completed"] == 3 and (tmp_path / "model" / "sdn.safetensors").is_file()
    json.dumps(summary)
    triplets = evaluate_triplets_in_directory(data, tmp_path / "model", device="cpu")
    assert triplets["n_triplets"] == 18 and triplets["triplet_accuracy"] > 0.5
    wind = evaluate_wind_in_directory(
        data, tmp_path / "model", config=RegressionConfig(epochs=5), device="cpu"
    )
    assert wind["n"] == 18 and np.isfinite(wind["mse"]) and 0 <= wind["acc_at_0_5"] <= 1


def test_spectral_baseline_and_bad_model_names(data):
    scores = evaluate_wind_in_directory(
        data,
        "spectral",
        config=RegressionConfig(epochs=3),
        spectral_frontend=TINY.frontend,
        device="cpu",
    )
    assert scores["n"] == 18 and scores["model"] == "spectral"
    with pytest.raises(UserInputError, match="regression baseline"):
        evaluate_triplets_in_directory(data, "resnet18")
    with pytest.raises(UserInputError, match="too short"):
        evaluate_wind_in_directory(data, "spectral", device="cpu")  # 20 stored frames, 30 needed
    with pytest.raises(UserInputError, match="no SDN weights"):
        evaluate_wind_in_directory(data, data / "missing.safetensors")
