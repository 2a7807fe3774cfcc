"""Dataset-directory entry points behind ``physinfer train`` and ``physinfer evaluate``.

Each function takes a dataset directory written by ``physinfer dataset generate`` (read
with :class:`physinfer.datasets.ClipDataset`, one split at a time), does the work and
returns the JSON-ready dictionary the command prints with ``--json``:

- :func:`train_from_directory` → :meth:`TrainResult.to_dict` (train on ``train``, select
  on ``val``);
- :func:`evaluate_triplets_in_directory` → ``{"triplet_accuracy", "n_triplets", ...}`` on
  ``test``;
- :func:`evaluate_wind_in_directory` → ``{"mse", "acc_at_0_5", "n", ...}``: a regression
  head fitted on ``train``, scored on ``test``, for the SDN or a baseline.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from torch import nn

from physinfer.errors import UserInputError
from physinfer_flag.sdn.baselines import (
    CNNLSTM,
    CNNLSTMConfig,
    ResNet18Frames,
    ResNetFramesConfig,
    SpectralPooling,
)
from physinfer_flag.sdn.data import PreparedClips
from physinfer_flag.sdn.evaluation import RegressionConfig, evaluate_triplets, evaluate_wind
from physinfer_flag.sdn.frontend import FrontEndConfig
from physinfer_flag.sdn.losses import PositiveRule
from physinfer_flag.sdn.network import SDNConfig
from physinfer_flag.sdn.training import TrainConfig, train_sdn
from physinfer_flag.sdn.weights import load_sdn

#: Names accepted by :func:`evaluate_wind_in_directory` instead of a weights path.
BASELINES = ("spectral", "resnet18", "cnn_lstm")


def open_split(data: str | Path, split: str, frontend: FrontEndConfig) -> PreparedClips:
    """One split of a generated dataset, prepared for a network with ``frontend`` settings."""
    from physinfer.datasets import ClipDataset

    return PreparedClips(ClipDataset(data, split), config=frontend)


def train_from_directory(
    data: str | Path,
    out: str | Path,
    *,
    epochs: int | None = None,
    positives: PositiveRule = "simulation",
    model_config: SDNConfig | None = None,
    train_config: TrainConfig | None = None,
    resume: bool = True,
    device: str | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Train an SDN on a dataset directory's ``train`` split, selecting on ``val``.

    Args:
        data: Dataset directory.
        out: Output directory (``sdn.safetensors``, ``checkpoint.safetensors``, ``history.json``).
        epochs: Overrides ``train_config.epochs``.
        positives: Overrides ``train_config.positives``.
        model_config: Architecture (default: the paper's SDN).
        train_config: Training settings (default: the paper's).
        resume: Continue a run found in ``out``.
        device: Torch device.
        progress: Progress bars on stderr.

    Returns:
        The run summary (:meth:`~physinfer_flag.sdn.training.TrainResult.to_dict`).
    """
    model_config = model_config or SDNConfig()
    base = train_config or TrainConfig()
    overrides: dict[str, Any] = {"positives": positives, "progress": progress}
    if epochs is not None:
        overrides["epochs"] = epochs
    config = TrainConfig.from_dict({**base.to_dict(), **overrides})
    train = open_split(data, "train", model_config.frontend)
    val = open_split(data, "val", model_config.frontend)
    if len(val) == 0:
        val = None  # type: ignore[assignment]
    result = train_sdn(
        train,
        val,
        out_dir=out,
        model_config=model_config,
        config=config,
        resume=resume,
        device=device,
        info={"data": str(Path(data).resolve()), "positives": positives},
    )
    return result.to_dict()


def evaluate_triplets_in_directory(
    data: str | Path,
    model: str | Path,
    *,
    split: str = "test",
    n_triplets: int | None = None,
    positives: PositiveRule = "simulation",
    seed: int = 0,
    spectral_frontend: FrontEndConfig | None = None,
    device: str | None = None,
    progress: bool = False,
) -> dict[str, Any]:
    """Triplet accuracy of SDN weights (or ``"spectral"``) on a split of a dataset directory.

    Args:
        data: Dataset directory.
        model: SDN weights (file or training directory) or ``"spectral"``.
        split: The split to draw triplets from.
        n_triplets: Number of triplets (default: one per clip that has a positive).
        positives: ``"simulation"`` or ``"theta"``.
        seed: Seed of the triplet draw.
        spectral_frontend: Front end of the ``"spectral"`` baseline (default: the SDN's).
        device: Torch device.
        progress: Progress bar on stderr.

    Returns:
        ``{"triplet_accuracy", "n_triplets", "split", "model"}``.
    """
    network = _embedding_model(model, spectral_frontend, device)
    dataset = open_split(data, split, network.frontend_config)  # type: ignore[arg-type]
    scores = evaluate_triplets(
        network,
        dataset,
        n_triplets=n_triplets,
        positives=positives,
        seed=seed,
        device=device,
        progress=progress,
    )
    return {**scores, "split": split, "model": str(model)}


def evaluate_wind_in_directory(
    data: str | Path,
    model: str | Path,
    *,
    config: RegressionConfig | None = None,
    n_frames: int | None = None,
    spectral_frontend: FrontEndConfig | None = None,
    device: str | None = None,
) -> dict[str, Any]:
    """Wind-speed regression on a dataset directory: head fitted on ``train``, scored on ``test``.

    Args:
        data: Dataset directory.
        model: SDN weights (file or training directory), or a baseline name:
            ``"spectral"`` (fixed), ``"resnet18"`` or ``"cnn_lstm"`` (trained from scratch
            with the head, as the paper).
        config: Regression settings; the learned baselines are always fine-tuned.
        n_frames: Frames read by a learned baseline (default: 20 for ResNet-18, 10 for
            CNN+LSTM, as the paper).
        spectral_frontend: Front end of the ``"spectral"`` baseline, whose ``fps`` and
            ``size`` also prepare the learned baselines' clips (default: the SDN's).
        device: Torch device.

    Returns:
        ``{"mse", "acc_at_0_5", "n", "model"}`` on the test split.
    """
    config = config or RegressionConfig()
    backbone, frontend = regression_backbone(model, n_frames, spectral_frontend, device)
    if isinstance(backbone, (ResNet18Frames, CNNLSTM)):
        config = dataclasses.replace(config, finetune=True)
    train = open_split(data, "train", frontend)
    test = open_split(data, "test", frontend)
    scores = evaluate_wind(backbone, train, test, config=config, device=device)
    return {**scores, "model": str(model)}


def _embedding_model(
    model: str | Path, spectral: FrontEndConfig | None, device: str | None
) -> nn.Module:
    if str(model) == "spectral":
        return SpectralPooling(frontend=spectral or FrontEndConfig())
    if str(model) in BASELINES:
        raise UserInputError(
            f"{model} is a regression baseline; triplets are evaluated for SDN weights or 'spectral'"
        )
    return load_sdn(model, device)


def regression_backbone(
    model: str | Path, n_frames: int | None, spectral: FrontEndConfig | None, device: str | None
) -> tuple[nn.Module, FrontEndConfig]:
    """The backbone and the clip preparation it needs (frames, size, fps).

    ``model``: SDN weights or a baseline name (``spectral``, ``resnet18``, ``cnn_lstm``; the
    learned baselines freshly initialised, reading ``n_frames`` or the paper's 20 / 10);
    ``spectral`` gives the size and rate of the clips (default: the SDN's).
    """
    name = str(model)
    frontend = spectral or FrontEndConfig()
    if name == "spectral":
        return SpectralPooling(frontend=frontend), frontend
    if name == "resnet18":
        frames = n_frames or 20
        resnet = ResNet18Frames(config=ResNetFramesConfig(n_frames=frames))
        return resnet, dataclasses.replace(frontend, n_frames=max(4, frames))
    if name == "cnn_lstm":
        if frontend.size < CNNLSTM.min_side:
            raise UserInputError(
                f"the CNN+LSTM baseline needs clips of at least {CNNLSTM.min_side} px (its AlexNet strides), "
                f"got {frontend.size}; use a larger size"
            )
        frames = n_frames or 10
        lstm = CNNLSTM(config=CNNLSTMConfig(n_frames=frames))
        return lstm, dataclasses.replace(frontend, n_frames=max(4, frames))
    network = load_sdn(model, device)
    return network, network.config.frontend
