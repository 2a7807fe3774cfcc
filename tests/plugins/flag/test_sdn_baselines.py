"""Baselines for the wind-speed table: multi-frame ResNet-18, CNN+LSTM, spectral pooling."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physinfer.errors import UserInputError
from physinfer_flag.sdn.baselines import (
    CNNLSTM,
    CNNLSTMConfig,
    ResNet18Frames,
    ResNetFramesConfig,
    SpectralPooling,
)
from physinfer_flag.sdn.evaluation import RegressionConfig, evaluate_wind
from physinfer_flag.sdn.frontend import FrontEndConfig, SpectralFrontEnd
from physinfer_flag.sdn.network import count_parameters
from physinfer_flag.sdn.synthetic import grating_dataset, moving_grating


def test_default_sizes_match_the_paper():
    assert count_parameters(ResNet18Frames()) == pytest.approx(11.2e6, rel=0.01)
    assert count_parameters(CNNLSTM()) == pytest.approx(66.4e6, rel=0.01)


def test_resnet18_frames_averages_per_frame_features():
    torch.manual_seed(0)
    model = ResNet18Frames(config=ResNetFramesConfig(n_frames=4, widths=(4, 8, 8, 16))).eval()
    clip = torch.randint(0, 256, (2, 6, 48, 48), dtype=torch.uint8)
    with torch.no_grad():
        out = model(clip)
        reversed_frames = model(clip[:, [3, 2, 1, 0]])
    assert out.shape == (2, 16)
    torch.testing.assert_close(out, reversed_frames)  # temporal average: order does not matter
    with pytest.raises(UserInputError, match="T>=4"):
        model(clip[:, :3])


def test_cnn_lstm_depends_on_frame_order_and_trains():
    torch.manual_seed(0)
    model = CNNLSTM(
        config=CNNLSTMConfig(n_frames=3, conv_widths=(4, 8, 8, 8, 8), fc_width=16, hidden=8)
    ).eval()
    clip = torch.randint(0, 256, (2, 3, 64, 64), dtype=torch.uint8)
    with torch.no_grad():
        out = model(clip)
        shuffled = model(clip[:, [2, 0, 1]])
    assert out.shape == (2, 8) and not torch.allclose(out, shuffled)
    model.train()
    model(clip).sum().backward()
    assert model.features[0].weight.grad.abs().sum() > 0


def test_cnn_lstm_names_its_smallest_input_instead_of_failing_inside_torch():
    model = CNNLSTM(config=CNNLSTMConfig(n_frames=2, conv_widths=(4, 4, 4, 4, 4), fc_width=8, hidden=4)).eval()
    side = CNNLSTM.min_side
    with torch.no_grad():
        assert model(torch.zeros(1, 2, side, side, dtype=torch.uint8)).shape == (1, 4)
        with pytest.raises(RuntimeError):  # the constant is tight: one pixel less fails in the stack itself
            model.features(torch.zeros(1, 1, side - 1, side - 1))
        with pytest.raises(UserInputError, match=f"at least {side} px"):
            model(torch.zeros(1, 2, side - 1, side - 1, dtype=torch.uint8))
    from physinfer_flag.sdn.workflows import regression_backbone

    with pytest.raises(UserInputError, match=f"at least {side} px"):
        regression_backbone("cnn_lstm", 10, FrontEndConfig(size=48), "cpu")


def test_learned_baselines_fine_tune_with_a_regression_head():
    train = grating_dataset(n_thetas=6, renders_per_sim=2, n_frames=4, size=64, seed=0)
    test = grating_dataset(n_thetas=3, renders_per_sim=2, n_frames=4, size=64, seed=1)
    config = RegressionConfig(
        target="frequency_hz", epochs=2, batch_size=4, hidden=8, finetune=True
    )
    for model in (
        ResNet18Frames(config=ResNetFramesConfig(n_frames=4, widths=(4, 4, 8, 8))),
        CNNLSTM(
            config=CNNLSTMConfig(n_frames=4, conv_widths=(4, 4, 4, 4, 4), fc_width=8, hidden=4)
        ),
    ):
        before = [p.detach().clone() for p in model.parameters()]
        scores = evaluate_wind(model, train, test, config=config, device="cpu")
        assert scores["n"] == 6 and np.isfinite(scores["mse"])
        assert any(not torch.equal(a, b) for a, b in zip(before, model.parameters(), strict=True))


def test_spectral_pooling_reports_the_grating_frequency_per_cell():
    config = FrontEndConfig(n_frames=20, size=48)
    freq = 5 * 25.0 / 20
    video = moving_grating(
        frequency_hz=freq, direction_rad=0.0, n_frames=20, size=48, fps=25.0, wavelength_px=16
    )
    pooling = SpectralPooling(frontend=config, grid=3)
    with torch.no_grad():
        out = pooling(SpectralFrontEnd(config=config)(torch.from_numpy(video)[None]))
    assert out.shape == (1, pooling.out_dim) == (1, 36)
    hz_x = out[0, 18:27]  # power-weighted frequency of the x derivative, 9 cells
    torch.testing.assert_close(hz_x, torch.full_like(hz_x, freq), rtol=1e-4, atol=1e-4)
    assert list(pooling.parameters()) == []
