"""The SDN weights file: one safetensors file that says how to rebuild its network.

Format ``physinfer-sdn/1``: the tensors of :class:`~physinfer_flag.sdn.network.SDN`'s
``state_dict`` (only the trainable head has any; batch-norm statistics included), and
in the safetensors header metadata (strings only):

- ``format``: ``"physinfer-sdn/1"``;
- ``config``: JSON of :class:`~physinfer_flag.sdn.network.SDNConfig`, the front end
  nested (fps, n_frames, size, filters, k) — everything needed to rebuild the network;
- ``embedding_dim``, ``n_frames``, ``fps``, ``size``: copies of the key settings, readable
  without parsing the config;
- ``info``: JSON of free-form provenance (training data, epochs, metrics, command).

Floating tensors may be stored as float16 (``save_sdn(half=True)``, half the size for a
file shipped in the repository). Loading never unpickles anything. A path may name the
file or a training output directory holding ``sdn.safetensors``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from safetensors import safe_open
from safetensors.torch import save_file

from physinfer.errors import UserInputError
from physinfer.io import atomic_path, to_jsonable
from physinfer_flag.sdn.network import SDN, SDNConfig
from physinfer_flag.sdn.settings import resolve_device

WEIGHTS_FORMAT = "physinfer-sdn/1"
WEIGHTS_FILE = "sdn.safetensors"
DEFAULT_WEIGHTS = Path(__file__).resolve().parent.parent / "data" / "sdn_default.safetensors"


def save_sdn(
    model: SDN, path: str | Path, *, info: Mapping[str, Any] | None = None, half: bool = False
) -> Path:
    """Write a network to a weights file (atomically).

    Args:
        model: The network.
        path: Destination ``.safetensors`` file.
        info: Provenance stored as JSON in the metadata.
        half: Store floating tensors as float16 (half the size, for a file shipped in
            the repository); they are cast back to float32 on load.

    Returns:
        The path written.
    """
    path = Path(path)
    c = model.config
    metadata = {
        "format": WEIGHTS_FORMAT,
        "config": json.dumps(c.to_dict(), sort_keys=True),
        "embedding_dim": str(c.embedding_dim),
        "n_frames": str(c.frontend.n_frames),
        "fps": repr(float(c.frontend.fps)),
        "size": str(c.frontend.size),
        "info": json.dumps(to_jsonable(dict(info or {})), sort_keys=True, allow_nan=False),
    }
    tensors = {}
    for name, t in model.state_dict().items():
        t = t.detach().cpu()
        tensors[name] = (t.half() if half and t.is_floating_point() else t).contiguous()
    with atomic_path(path, suffix=".safetensors") as tmp:
        save_file(tensors, str(tmp), metadata=metadata)
    return path


def resolve_weights_path(path: str | Path) -> Path:
    """The weights file named by ``path`` (a file, or a directory holding ``sdn.safetensors``).

    Raises:
        UserInputError: when nothing is there.
    """
    path = Path(path)
    if path.is_dir():
        path = path / WEIGHTS_FILE
    if not path.is_file():
        raise UserInputError(
            f"no SDN weights at {path}; pass a .safetensors file written by `physinfer train` "
            "or its output directory"
        )
    return path


def read_sdn_metadata(path: str | Path) -> dict[str, Any]:
    """The metadata of a weights file: ``config`` (SDNConfig), ``info`` (dict) and the rest.

    Raises:
        UserInputError: unreadable file or not an SDN weights file.
    """
    path = resolve_weights_path(path)
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
    except Exception as exc:  # safetensors raises its own error types for corrupt headers
        raise UserInputError(
            f"cannot read {path} as safetensors ({type(exc).__name__}: {exc})"
        ) from None
    if meta.get("format") != WEIGHTS_FORMAT:
        raise UserInputError(
            f"{path} is not an SDN weights file (format {meta.get('format')!r}, expected {WEIGHTS_FORMAT!r})"
        )
    try:
        config = SDNConfig.from_dict(json.loads(meta["config"]))
        info = json.loads(meta.get("info", "{}"))
    except (KeyError, json.JSONDecodeError, TypeError) as exc:
        raise UserInputError(f"{path}: damaged SDN metadata ({exc})") from None
    return {**meta, "config": config, "info": info}


def load_sdn(path: str | Path, device: str | torch.device | None = None) -> SDN:
    """Rebuild a network from a weights file, in eval mode.

    Args:
        path: A ``.safetensors`` file from :func:`save_sdn`, or a directory holding one.
        device: Torch device (default: cuda if available, else cpu).

    Returns:
        The network on ``device``.

    Raises:
        UserInputError: missing or damaged file, or tensors that do not fit the config.
    """
    path = resolve_weights_path(path)
    meta = read_sdn_metadata(path)
    model = SDN(config=meta["config"])
    target = resolve_device(device)
    tensors: dict[str, torch.Tensor] = {}
    with safe_open(str(path), framework="pt", device="cpu") as f:
        for name in f.keys():  # noqa: SIM118 - safe_open is not a mapping
            tensors[name] = f.get_tensor(name)
    try:
        model.load_state_dict(tensors, strict=True)
    except RuntimeError as exc:
        raise UserInputError(
            f"{path}: the tensors do not fit the stored architecture ({exc})"
        ) from None
    return model.to(target).eval()


def export_weights(
    source: str | Path,
    destination: str | Path = DEFAULT_WEIGHTS,
    *,
    half: bool = True,
    info: Mapping[str, Any] | None = None,
) -> Path:
    """Copy trained weights to a shippable file (by default the plugin's default weights).

    Args:
        source: Weights file or training output directory.
        destination: Where to write (default: ``physinfer_flag/data/sdn_default.safetensors``).
        half: Store float16 (half the size; see :func:`save_sdn`).
        info: Provenance added to the source's (e.g. the command that made it).

    Returns:
        The path written.
    """
    meta = read_sdn_metadata(source)
    model = load_sdn(source, "cpu")
    return save_sdn(model, destination, info={**meta["info"], **dict(info or {})}, half=half)
