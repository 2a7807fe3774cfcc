"""The SDN's fixed front end: filters, the fused implementation against the plain one, the cache."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physinfer.errors import UserInputError
from physinfer.types import Clip
from physinfer_flag.sdn.frontend import (
    FrontEndConfig,
    ReferenceFrontEnd,
    SpectralFrontEnd,
    cache_clip_features,
    frontend_features,
    gaussian_derivative_kernel,
    gaussian_kernel,
    load_cached_features,
    prepare_video,
    save_cached_features,
    temporal_smoothing_matrix,
)
from physinfer_flag.sdn.synthetic import moving_grating

SMALL = FrontEndConfig(n_frames=20, size=48)


def random_smooth_video(n=2, t=20, size=48, seed=0) -> torch.Tensor:
    """Travelling blobs plus noise, float in [0, 1]: every pixel moves."""
    rng = np.random.default_rng(seed)
    tt = np.arange(t)[:, None, None] / 25.0
    y, x = np.mgrid[0:size, 0:size] / size
    videos = []
    for _ in range(n):
        v = 0.5 + 0.2 * np.sin(
            2 * np.pi * (3 * x + 2 * y - rng.uniform(1, 4) * tt) + rng.uniform(0, 6)
        )
        v += 0.15 * np.sin(2 * np.pi * (5 * y - rng.uniform(1, 4) * tt))
        videos.append(v + 0.02 * rng.normal(size=v.shape))
    return torch.tensor(np.stack(videos), dtype=torch.float32)


def test_filters_are_normalised():
    g = gaussian_kernel(2.0)
    assert len(g) == 13 and float(g.sum()) == pytest.approx(1.0)
    d = gaussian_derivative_kernel(2.0)
    i = torch.arange(-6, 7, dtype=torch.float64)
    assert float(d.sum()) == pytest.approx(0.0, abs=1e-15)
    assert float((d * (i + 10.0)).sum()) == pytest.approx(1.0)  # slope of a ramp, any offset
    m = temporal_smoothing_matrix(30, 1.0)
    torch.testing.assert_close(m.sum(dim=1), torch.ones(30, dtype=torch.float64))
    torch.testing.assert_close(m[15, 12:19], gaussian_kernel(1.0))


def test_fused_front_end_matches_the_plain_reference():
    video = random_smooth_video()
    with torch.no_grad():
        fused = SpectralFrontEnd(config=SMALL)(video)
        reference = ReferenceFrontEnd(config=SMALL)(video)
    assert fused.shape == reference.shape == (2, 4, 24, 24)
    power_f, power_r = fused[:, :2], reference[:, :2]
    assert float((power_f - power_r).abs().max() / power_r.abs().max()) < 1e-4
    agree = (fused[:, 2:] == reference[:, 2:]).float().mean()
    assert float(agree) > 0.99  # only near-ties between two bins may flip


def test_uint8_and_float_inputs_agree():
    video = random_smooth_video(n=1)
    as_uint8 = torch.from_numpy(np.rint(video.numpy() * 255).astype(np.uint8))
    fe = SpectralFrontEnd(config=SMALL)
    with torch.no_grad():
        torch.testing.assert_close(fe(as_uint8), fe(as_uint8.float() / 255.0))


@pytest.mark.parametrize(("direction", "moving", "still"), [(0.0, 0, 1), (np.pi / 2, 1, 0)])
def test_a_travelling_grating_shows_its_frequency_in_the_derivative_across_its_stripes(
    direction, moving, still
):
    freq = 5 * 25.0 / 20  # on a DFT bin of 20 frames
    video = moving_grating(
        frequency_hz=freq, direction_rad=direction, n_frames=20, size=48, fps=25.0, wavelength_px=16
    )
    with torch.no_grad():
        out = SpectralFrontEnd(config=SMALL)(torch.from_numpy(video)[None])[0]
    interior = (slice(4, -4), slice(4, -4))
    hz = out[2 + moving][interior]
    torch.testing.assert_close(hz, torch.full_like(hz, freq))
    # Stripes across x move nothing in the y derivative, and vice versa.
    assert float(out[still][interior].max()) < 1e-3 * float(out[moving][interior].mean())


def test_front_end_has_no_trainable_weights():
    assert list(SpectralFrontEnd().parameters()) == []
    assert list(ReferenceFrontEnd().parameters()) == []


def test_batches_and_single_clips_give_the_same_features():
    videos = (random_smooth_video(n=3).numpy() * 255).astype(np.uint8)
    together = frontend_features(videos, config=SMALL, device="cpu", batch_size=3)
    one_by_one = np.concatenate(
        [frontend_features(v[None], config=SMALL, device="cpu") for v in videos]
    )
    np.testing.assert_allclose(together, one_by_one, rtol=1e-5, atol=1e-9)
    with pytest.raises(UserInputError, match="prepare_video"):
        frontend_features(videos[:, :, :40], config=SMALL, device="cpu")


def test_cached_features_round_trip(tmp_path):
    frames = moving_grating(
        frequency_hz=2.5, direction_rad=0.4, n_frames=30, size=64, fps=25.0, wavelength_px=20
    )
    clip = Clip(np.repeat(frames[..., None], 3, axis=3), 25.0)
    written = cache_clip_features(tmp_path / "a.npz", clip, config=SMALL, device="cpu")
    read, stored = load_cached_features(tmp_path / "a.npz", SMALL)
    np.testing.assert_array_equal(read, written)
    assert stored == SMALL and read.shape == (4, 24, 24)
    with pytest.raises(UserInputError, match="recompute"):
        load_cached_features(tmp_path / "a.npz", FrontEndConfig(n_frames=20, size=48, sigma_xy=1.0))
    with pytest.raises(UserInputError, match="must be"):
        save_cached_features(tmp_path / "b.npz", read[:2], SMALL)
    (tmp_path / "c.npz").write_bytes(b"not an npz")
    with pytest.raises(UserInputError, match="cannot read"):
        load_cached_features(tmp_path / "c.npz")


def test_prepare_video_resamples_and_refuses_short_clips():
    frames = np.zeros((60, 90, 120, 3), dtype=np.uint8)
    video = prepare_video(Clip(frames, 50.0), SMALL)
    assert video.shape == (20, 48, 48) and video.dtype == np.float32
    with pytest.raises(UserInputError, match="too short"):
        prepare_video(Clip(frames[:30], 50.0), SMALL)


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="even"):
        FrontEndConfig(size=49).validate()
    with pytest.raises(UserInputError, match="unknown"):
        FrontEndConfig.from_dict({"sigma": 2})


def test_gradients_flow_through_the_fused_front_end_to_its_input():
    video = random_smooth_video(n=1).requires_grad_(True)
    fused = SpectralFrontEnd(config=SMALL)(video)
    fused[:, :2].sum().backward()
    assert (
        video.grad is not None and torch.isfinite(video.grad).all() and video.grad.abs().sum() > 0
    )
    reference = random_smooth_video(n=1).requires_grad_(True)
    ReferenceFrontEnd(config=SMALL)(reference)[:, :2].sum().backward()
    torch.testing.assert_close(video.grad, reference.grad, rtol=1e-3, atol=1e-6)
