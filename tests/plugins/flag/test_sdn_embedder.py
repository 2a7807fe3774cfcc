"""The flag embedders: SDN (weights from a file) and the parameter-free spectral one."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import physinfer_flag.sdn.embedder as embedder_module
from physinfer.errors import UserInputError
from physinfer.testing import check_embedder
from physinfer.types import Clip
from physinfer_flag.sdn.embedder import SDNEmbedder, SpectralEmbedder, SpectralEmbedderConfig
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.network import SDN, SDNConfig
from physinfer_flag.sdn.synthetic import moving_grating
from physinfer_flag.sdn.weights import save_sdn

SMALL_FRONT = FrontEndConfig(n_frames=16, size=32)
TINY = SDNConfig(frontend=SMALL_FRONT, widths=(8, 16, 32), embedding_dim=12, pool_grid=2)


def grating_clip(freq=2.5, direction=0.3, phase=0.0, n_frames=40, fps=50.0, size=(60, 80)) -> Clip:
    """An RGB clip at another frame rate and size than the embedders use."""
    frames = moving_grating(
        frequency_hz=freq,
        direction_rad=direction,
        n_frames=n_frames,
        size=max(size),
        fps=fps,
        wavelength_px=25,
        phase=phase,
    )[:, : size[0], : size[1]]
    return Clip(np.repeat(frames[..., None], 3, axis=3), fps)


@pytest.fixture
def weights(tmp_path):
    torch.manual_seed(0)
    return save_sdn(SDN(config=TINY), tmp_path / "sdn.safetensors")


def test_sdn_embedder_follows_the_contract_and_its_weights(weights):
    embedder = SDNEmbedder(model=weights, device="cpu")
    assert (embedder.fps, embedder.n_frames, embedder.size, embedder.dim) == (25.0, 16, 32, 12)
    e = check_embedder(embedder, grating_clip())
    assert e.shape == (12,) and e.dtype == np.float32
    clips = [grating_clip(freq=f) for f in (1.0, 2.5, 4.0)]
    together = SDNEmbedder(model=weights, device="cpu", batch_size=2).embed_many(clips)
    np.testing.assert_allclose(
        together, np.stack([embedder.embed(c) for c in clips]), rtol=1e-5, atol=1e-6
    )


def test_sdn_embedder_accepts_a_network_in_memory(weights):
    from physinfer_flag.sdn.weights import load_sdn

    clip = grating_clip()
    np.testing.assert_array_equal(
        SDNEmbedder(model=load_sdn(weights, "cpu")).embed(clip),
        SDNEmbedder(model=weights).embed(clip),
    )


def test_missing_default_weights_say_how_to_make_them(tmp_path, monkeypatch):
    monkeypatch.setattr(embedder_module, "DEFAULT_WEIGHTS", tmp_path / "absent.safetensors")
    with pytest.raises(UserInputError, match="make pretrained"):
        SDNEmbedder()
    with pytest.raises(UserInputError, match="no SDN weights"):
        SDNEmbedder(model=tmp_path / "nothing-here.safetensors")


def test_spectral_embedder_follows_the_contract_and_separates_frequencies():
    embedder = SpectralEmbedder(
        config=SpectralEmbedderConfig(frontend=SMALL_FRONT, grid=4), device="cpu"
    )
    assert embedder.dim == 4 * 16
    base = check_embedder(embedder, grating_clip(freq=2.5, phase=0.0))
    same_physics = embedder.embed(grating_clip(freq=2.5, phase=1.7))  # another "render"
    other_physics = embedder.embed(grating_clip(freq=6.0, phase=0.0))
    assert np.linalg.norm(base - same_physics) < 0.5 * np.linalg.norm(base - other_physics)


def test_spectral_embedder_defaults_and_refuses_weights():
    embedder = SpectralEmbedder(device="cpu")
    assert (embedder.fps, embedder.n_frames, embedder.size, embedder.dim) == (25.0, 30, 224, 196)
    with pytest.raises(UserInputError, match="no weights"):
        SpectralEmbedder(model="some.safetensors")
    with pytest.raises(UserInputError, match="grid"):
        SpectralEmbedder(config=SpectralEmbedderConfig(frontend=SMALL_FRONT, grid=40))


def test_spectral_embedder_reads_the_frames_it_is_told():
    """``n_frames`` (``refine --embedder-frames``) replaces the front end's 30 and nothing else."""
    config = SpectralEmbedderConfig(frontend=SMALL_FRONT, grid=4)
    longer = SpectralEmbedder(config=config, device="cpu", n_frames=32)
    assert longer.n_frames == 32 and longer.config.frontend == FrontEndConfig(n_frames=32, size=32)
    clip = grating_clip(n_frames=80)  # 40 frames at 25 fps after resampling
    assert not np.allclose(longer.embed(clip), SpectralEmbedder(config=config, device="cpu").embed(clip))
    with pytest.raises(UserInputError, match="needs at least 48 frames"):
        SpectralEmbedder(config=config, device="cpu", n_frames=48).embed(clip)
    with pytest.raises(UserInputError, match="n_frames must be at least 4"):
        SpectralEmbedder(config=config, n_frames=2)


def test_spectral_shape_appends_the_weighted_mean_image_to_the_spectral_features():
    config = SpectralEmbedderConfig(frontend=SMALL_FRONT, grid=4, shape_grid=2, shape_weight=10.0)
    shaped = SpectralEmbedder(config=config, device="cpu")
    plain = SpectralEmbedder(config=SpectralEmbedderConfig(frontend=SMALL_FRONT, grid=4), device="cpu")
    assert shaped.dim == 4 * 16 + 4
    clip = grating_clip(size=(32, 32), fps=25.0)
    clip.frames[:, :, :16] = 0  # the left half dark all the time: the mean shape sees it
    features = check_embedder(shaped, clip)
    np.testing.assert_allclose(features[:64], plain.embed(clip), rtol=1e-6)
    left, right = features[64:].reshape(2, 2).T
    assert np.all(left == 0) and np.all(right > 2.0), "cells of the mean image, times the weight"


def test_spectral_shape_embedder_is_registered_with_a_16x16_mean_image():
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    embedder = registry.embedder("spectral_shape", model=None, device="cpu")
    assert embedder.dim == 196 + 256 and embedder.config.shape_grid == 16
    with pytest.raises(UserInputError, match="shape_grid"):
        SpectralEmbedder(config=SpectralEmbedderConfig(frontend=SMALL_FRONT, shape_grid=64))
