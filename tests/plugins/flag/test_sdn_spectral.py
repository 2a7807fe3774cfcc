"""The spectral decomposition layer: frequencies in Hz, periodogram power, shape contract."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physinfer.errors import UserInputError
from physinfer_flag.sdn.spectral import (
    SpectralDecomposition,
    SpectralSettings,
    frequencies_hz,
    periodogram,
    spectral_decomposition,
)

FPS = 25.0
T = 30


def tone_video(
    freq_hz: float, amplitude: float, *, n=2, c=3, h=4, w=5, offset=3.0, seed=0
) -> torch.Tensor:
    """``(n, c, T, h, w)``: every pixel a sinusoid at ``freq_hz`` with its own phase."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / FPS
    phase = rng.uniform(0, 2 * np.pi, (n, c, 1, h, w))
    x = offset + amplitude * np.sin(2 * np.pi * freq_hz * t[None, None, :, None, None] + phase)
    return torch.tensor(x, dtype=torch.float64)


@pytest.mark.parametrize("method", ["fft", "matmul"])
@pytest.mark.parametrize("cycles", [1, 5, 11])
def test_every_pixel_oscillating_at_f_returns_f_with_the_periodogram_power(method, cycles):
    freq = cycles * FPS / T  # on a DFT bin
    amplitude = 0.7
    out = spectral_decomposition(
        tone_video(freq, amplitude), SpectralSettings(k=1, fps=FPS, method=method)
    )
    assert out.shape == (2, 6, 4, 5)
    power, hz = out[:, :3], out[:, 3:]
    torch.testing.assert_close(hz, torch.full_like(hz, freq), rtol=0, atol=1e-9)
    # Periodic Hann sums to T/2, so |F| = A·T/4 at the bin and I = |F|²/T = A²·T/16.
    torch.testing.assert_close(
        power, torch.full_like(power, amplitude**2 * T / 16), rtol=1e-6, atol=0
    )


def test_power_scales_with_amplitude_squared_and_frequency_does_not_move():
    settings = SpectralSettings(fps=FPS)
    freq = 4 * FPS / T
    weak = spectral_decomposition(tone_video(freq, 0.1), settings)
    strong = spectral_decomposition(tone_video(freq, 0.3), settings)
    torch.testing.assert_close(strong[:, :3], 9 * weak[:, :3])
    torch.testing.assert_close(strong[:, 3:], weak[:, 3:])


def test_literal_algorithm_without_detrending_reports_the_static_offset_at_zero_hz():
    literal = SpectralSettings(fps=FPS, detrend=False, exclude_dc=False)
    out = spectral_decomposition(tone_video(5 * FPS / T, 0.1, offset=3.0), literal)
    assert torch.all(out[:, 3:] == 0.0)
    default = spectral_decomposition(
        tone_video(5 * FPS / T, 0.1, offset=3.0), SpectralSettings(fps=FPS)
    )
    assert torch.allclose(default[:, 3:], torch.tensor(5 * FPS / T, dtype=torch.float64))


def test_top_k_peaks_are_ordered_and_laid_out_channel_major():
    t = torch.arange(T, dtype=torch.float64) / FPS
    f1, f2 = 3 * FPS / T, 8 * FPS / T
    # Channel 0: strong f1 + weak f2; channel 1: strong f2 + weak f1.
    ch0 = 1.0 * torch.sin(2 * torch.pi * f1 * t) + 0.5 * torch.sin(2 * torch.pi * f2 * t)
    ch1 = 1.0 * torch.sin(2 * torch.pi * f2 * t) + 0.5 * torch.sin(2 * torch.pi * f1 * t)
    x = torch.stack([ch0, ch1])[None, :, :, None, None].expand(1, 2, T, 3, 3)
    out = spectral_decomposition(x, SpectralSettings(k=2, fps=FPS))
    assert out.shape == (1, 8, 3, 3)
    hz = out[0, 4:, 0, 0]
    torch.testing.assert_close(hz, torch.tensor([f1, f2, f2, f1], dtype=torch.float64))
    power = out[0, :4, 0, 0]
    assert power[0] > power[1] and power[2] > power[3]
    torch.testing.assert_close(power[1] / power[0], torch.tensor(0.25, dtype=torch.float64))


@pytest.mark.parametrize("k", [1, 3])
def test_shape_contract(k):
    x = torch.randn(3, 2, 20, 7, 9)
    out = SpectralDecomposition(settings=SpectralSettings(k=k, fps=FPS))(x)
    assert out.shape == (3, 2 * k * 2, 7, 9)
    assert out.dtype == x.dtype


def test_fft_and_matmul_implementations_agree():
    x = torch.randn(2, 2, T, 8, 8, dtype=torch.float64)
    a = spectral_decomposition(x, SpectralSettings(k=2, fps=FPS, method="fft"))
    b = spectral_decomposition(x, SpectralSettings(k=2, fps=FPS, method="matmul"))
    torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-12)


def test_periodogram_matches_numpy():
    rng = np.random.default_rng(1)
    signals = rng.normal(size=(5, T))
    expected = (
        np.abs(np.fft.rfft((signals - signals.mean(-1, keepdims=True)) * np.hanning(T + 1)[:-1]))
        ** 2
        / T
    )
    for method in ("fft", "matmul"):
        got = periodogram(
            torch.tensor(signals), SpectralSettings(fps=FPS, method=method, exclude_dc=False)
        )
        np.testing.assert_allclose(got.numpy(), expected, rtol=1e-9, atol=1e-12)


def test_zero_padding_refines_the_frequency_of_an_off_bin_tone():
    freq = 3.3  # between the 0.83 Hz bins of 30 frames
    coarse = spectral_decomposition(tone_video(freq, 1.0), SpectralSettings(fps=FPS))
    fine = spectral_decomposition(tone_video(freq, 1.0), SpectralSettings(fps=FPS, n_fft=8 * T))
    assert (coarse[:, 3:] - freq).abs().max() <= FPS / T / 2 + 1e-9
    assert (fine[:, 3:] - freq).abs().max() <= FPS / (8 * T) / 2 + 1e-9
    assert frequencies_hz(SpectralSettings(fps=FPS, n_fft=8 * T), T)[0] == pytest.approx(
        FPS / (8 * T)
    )


def test_gradients_flow_to_the_input_through_the_peak_power():
    x = torch.randn(1, 1, T, 3, 3, requires_grad=True)
    spectral_decomposition(x, SpectralSettings(fps=FPS))[:, 0].sum().backward()
    assert x.grad is not None and torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0


def test_bad_inputs_are_refused():
    with pytest.raises(UserInputError, match=r"\(N, C, T, H, W\)"):
        spectral_decomposition(torch.zeros(2, T, 4, 4), SpectralSettings())
    with pytest.raises(UserInputError, match="frequency bins"):
        spectral_decomposition(torch.zeros(1, 1, 6, 2, 2), SpectralSettings(k=4))
    with pytest.raises(ValueError):
        SpectralSettings(k=0).validate()


def test_a_single_tone_has_one_peak_not_its_window_neighbours():
    out = spectral_decomposition(tone_video(6 * FPS / T, 1.0), SpectralSettings(k=2, fps=FPS))
    strongest, second = out[:, 0::2][:, :3], out[:, 1::2][:, :3]
    assert torch.all(second < 1e-12 * strongest)
