"""The SDN network and its weights file: shapes, gradients, save/load."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from safetensors.torch import save_file

from physinfer.errors import UserInputError
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.network import SDN, SDNConfig, count_parameters
from physinfer_flag.sdn.weights import WEIGHTS_FILE, load_sdn, read_sdn_metadata, save_sdn

TINY = SDNConfig(
    frontend=FrontEndConfig(n_frames=16, size=32), widths=(8, 16, 32), embedding_dim=12, pool_grid=2
)


def clips(n=3, t=16, size=32, seed=0) -> torch.Tensor:
    return torch.from_numpy(
        np.random.default_rng(seed).integers(0, 256, (n, t, size, size), dtype=np.uint8)
    )


def test_shape_contract_and_longer_clips_are_cut():
    torch.manual_seed(0)
    model = SDN(config=TINY).eval()
    with torch.no_grad():
        out = model(clips())
        longer = model(torch.cat([clips(), clips(seed=1)[:, :4]], dim=1))
    assert out.shape == (3, 12) and torch.isfinite(out).all()
    torch.testing.assert_close(out, longer)
    with pytest.raises(UserInputError, match="T>=16"):
        model(clips(t=10))
    with pytest.raises(UserInputError, match="front-end features"):
        model.embed_features(torch.zeros(2, 3, 16, 16))


def test_gradients_reach_every_2d_layer():
    torch.manual_seed(0)
    model = SDN(config=TINY).train()
    model(clips(n=4)).square().sum().backward()
    named = dict(model.named_parameters())
    assert all(name.startswith("head.") for name in named)
    convs = [n for n in named if "conv" in n]
    assert len(convs) == 6  # two per basic block
    for name, p in named.items():
        assert p.grad is not None and torch.isfinite(p.grad).all(), name
        if "conv" in name or name.startswith("head.linear"):
            assert p.grad.abs().sum() > 0, name


def test_default_architecture_is_paper_sized():
    model = SDN()
    assert model.out_dim == 512
    c = model.config.frontend
    assert (c.n_frames, c.fps, c.size, c.sigma_t, c.sigma_xy, c.k) == (30, 25.0, 224, 1.0, 2.0, 1)
    assert 2.0e6 < count_parameters(model) < 3.0e6  # the paper: 2.6 M


def test_weights_round_trip_with_metadata(tmp_path):
    torch.manual_seed(0)
    model = SDN(config=TINY).eval()
    path = save_sdn(model, tmp_path / WEIGHTS_FILE, info={"epochs": 3, "note": "test"})
    meta = read_sdn_metadata(path)
    assert meta["config"] == TINY and meta["info"] == {"epochs": 3, "note": "test"}
    assert (meta["embedding_dim"], meta["n_frames"], meta["size"], float(meta["fps"])) == (
        "12",
        "16",
        "32",
        25.0,
    )
    for source in (path, tmp_path):  # the file or its directory
        loaded = load_sdn(source, "cpu")
        assert not loaded.training
        with torch.no_grad():
            torch.testing.assert_close(loaded(clips()), model(clips()))


def test_half_precision_weights_load_close(tmp_path):
    torch.manual_seed(0)
    model = SDN(config=TINY).eval()
    full, half = (
        save_sdn(model, tmp_path / "full.safetensors"),
        save_sdn(model, tmp_path / "half.safetensors", half=True),
    )
    assert half.stat().st_size < 0.6 * full.stat().st_size
    loaded = load_sdn(half, "cpu")
    assert next(loaded.parameters()).dtype == torch.float32
    with torch.no_grad():
        torch.testing.assert_close(loaded(clips()), model(clips()), rtol=2e-2, atol=2e-2)


def test_foreign_or_damaged_weights_are_refused(tmp_path):
    with pytest.raises(UserInputError, match="no SDN weights"):
        load_sdn(tmp_path / "missing.safetensors")
    save_file(
        {"x": torch.zeros(2)}, str(tmp_path / "other.safetensors"), metadata={"format": "something"}
    )
    with pytest.raises(UserInputError, match="not an SDN weights file"):
        load_sdn(tmp_path / "other.safetensors")
    (tmp_path / "junk.safetensors").write_bytes(b"\x00" * 64)
    with pytest.raises(UserInputError, match="cannot read"):
        load_sdn(tmp_path / "junk.safetensors")
    wrong = TINY.to_dict() | {"embedding_dim": 7}
    torch.manual_seed(0)
    tensors = {k: v.contiguous() for k, v in SDN(config=TINY).state_dict().items()}
    save_file(
        tensors,
        str(tmp_path / "mismatch.safetensors"),
        metadata={"format": "physinfer-sdn/1", "config": json.dumps(wrong)},
    )
    with pytest.raises(UserInputError, match="do not fit"):
        load_sdn(tmp_path / "mismatch.safetensors")


def test_config_round_trips_through_json():
    data = json.loads(json.dumps(TINY.to_dict()))
    assert SDNConfig.from_dict(data) == TINY
    with pytest.raises(UserInputError, match="unknown"):
        SDNConfig.from_dict({**data, "depth": 3})
    with pytest.raises(UserInputError, match="invalid"):
        SDNConfig.from_dict({**data, "widths": []})


def test_export_keeps_provenance_and_adds_to_it(tmp_path):
    from physinfer_flag.sdn.weights import export_weights

    torch.manual_seed(0)
    save_sdn(SDN(config=TINY), tmp_path / WEIGHTS_FILE, info={"epoch": 7})
    out = export_weights(
        tmp_path, tmp_path / "shipped.safetensors", info={"command": "make pretrained"}
    )
    assert read_sdn_metadata(out)["info"] == {"epoch": 7, "command": "make pretrained"}
    assert load_sdn(out, "cpu").config == TINY
