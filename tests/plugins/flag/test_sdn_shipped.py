"""The SDN weights shipped in the repository (``make pretrained``) load and embed."""

from __future__ import annotations

import numpy as np

from physinfer.types import Clip
from physinfer_flag.sdn.embedder import SDNEmbedder
from physinfer_flag.sdn.synthetic import grating_wave, to_uint8
from physinfer_flag.sdn.weights import DEFAULT_WEIGHTS, read_sdn_metadata


def test_shipped_weights_are_small_and_say_how_they_were_made():
    assert DEFAULT_WEIGHTS.is_file(), "run `make pretrained`"
    assert DEFAULT_WEIGHTS.stat().st_size < 6_000_000
    meta = read_sdn_metadata(DEFAULT_WEIGHTS)
    frontend = meta["config"].frontend
    assert (frontend.n_frames, frontend.fps, frontend.size) == (60, 25.0, 224)
    assert meta["config"].embedding_dim == 512
    assert meta["info"]["scores"]["val_triplet_accuracy"] > 0.8
    assert "flagsim-cpu" in meta["info"]["data"]


def test_default_embedder_tells_motions_apart():
    sdn = SDNEmbedder(device="cpu")
    assert (sdn.n_frames, sdn.dim) == (60, 512)

    def clip(freq_hz: float, phase: float) -> Clip:
        wave = grating_wave(
            frequency_hz=freq_hz, direction_rad=0.3, n_frames=60, size=224, fps=25.0,
            wavelength_px=40.0, phase=phase,
        )  # fmt: skip
        return Clip(to_uint8(0.5 + 0.3 * wave)[..., None], 25.0)

    slow_a, slow_b, fast = sdn.embed_many([clip(1.0, 0.0), clip(1.0, 1.0), clip(2.5, 0.0)])
    assert np.all(np.isfinite(fast)) and fast.shape == (512,)
    # Same motion from another phase is closer than another frequency.
    assert np.linalg.norm(slow_a - slow_b) < np.linalg.norm(slow_a - fast)
