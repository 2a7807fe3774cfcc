"""How good an embedding is: triplet accuracy, and wind-speed regression with a head.

Triplet accuracy (Veit et al. 2017), as the paper's Table 2: triplets (anchor, positive,
negative) are drawn from a split, the positive sharing the anchor's simulation (or θ
group) and the negative not; a triplet is right when the anchor is strictly closer to
the positive.

Wind regression, as the paper's Table 3: a regression head (two-layer perceptron) is
fitted on the training split to predict the wind speed and scored on the test split by
the mean squared error and the fraction of predictions within 0.5 m/s (Acc@0.5). The
backbone is either kept fixed (its embedding is the input of the head: SDN, spectral
baseline) or trained with the head (``finetune``; the ResNet-18 and CNN+LSTM baselines).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from physinfer.errors import UserInputError
from physinfer_flag.sdn.data import SDNDataset, as_features
from physinfer_flag.sdn.frontend import FrontEndConfig, SpectralFrontEnd
from physinfer_flag.sdn.losses import PositiveRule, positive_labels
from physinfer_flag.sdn.network import SDN
from physinfer_flag.sdn.progress import progress_bar
from physinfer_flag.sdn.settings import resolve_device

ACC_TOLERANCE = 0.5

# -- triplets --------------------------------------------------------------------------


def make_triplets(
    labels: np.ndarray, *, n_triplets: int | None = None, seed: int = 0
) -> np.ndarray:
    """Random (anchor, positive, negative) index triplets.

    Every clip whose label occurs at least twice can be an anchor. With ``n_triplets``
    unset, each such clip anchors one triplet; otherwise anchors are drawn (without
    replacement while possible).

    Args:
        labels: ``(N,)`` labels; equal labels are positives.
        n_triplets: Number of triplets, or ``None`` for one per possible anchor.
        seed: Seed of the draw.

    Returns:
        ``(M, 3)`` int64 indices.

    Raises:
        UserInputError: when no triplet exists (no repeated label, or a single label).
    """
    labels = np.asarray(labels)
    rng = np.random.default_rng(seed)
    values, counts = np.unique(labels, return_counts=True)
    anchors = np.flatnonzero(np.isin(labels, values[counts >= 2]))
    if len(anchors) == 0 or len(values) < 2:
        raise UserInputError(
            "no triplet can be formed: need at least two clips of one simulation and clips of another"
        )
    if n_triplets is not None:
        anchors = rng.choice(anchors, size=n_triplets, replace=n_triplets > len(anchors))
    triplets = np.empty((len(anchors), 3), dtype=np.int64)
    for row, a in enumerate(anchors):
        same = np.flatnonzero(labels == labels[a])
        positives = same[same != a]
        negatives = np.flatnonzero(labels != labels[a])
        triplets[row] = (a, rng.choice(positives), rng.choice(negatives))
    return triplets


def triplet_accuracy(embeddings: np.ndarray, triplets: np.ndarray) -> float:
    """Fraction of triplets whose anchor is strictly closer to the positive than the negative.

    Args:
        embeddings: ``(N, D)`` embeddings.
        triplets: ``(M, 3)`` indices from :func:`make_triplets`.
    """
    e = np.asarray(embeddings, dtype=np.float64)
    a, p, n = e[triplets[:, 0]], e[triplets[:, 1]], e[triplets[:, 2]]
    d_pos = np.square(a - p).sum(axis=1)
    d_neg = np.square(a - n).sum(axis=1)
    return float(np.mean(d_pos < d_neg))


# -- embedding a dataset ---------------------------------------------------------------


def module_for(model: nn.Module, dataset: SDNDataset) -> nn.Module:
    """The module that maps this dataset's inputs to ``model``'s output.

    An SDN reads cached features through its head; a module that reads features
    (``input_kind == "features"``) gets a front end in front of it for clip datasets.

    Raises:
        UserInputError: when the dataset holds features and the model needs clips.
    """
    kind = getattr(model, "input_kind", "clips")
    if dataset.kind == kind:
        return model
    if dataset.kind == "features" and isinstance(model, SDN):
        return model.head
    if dataset.kind == "clips" and kind == "features":
        frontend = SpectralFrontEnd(config=model.frontend_config)  # type: ignore[attr-defined]
        return nn.Sequential(frontend, model)
    raise UserInputError(
        f"{type(model).__name__} reads video clips but the dataset holds cached front-end features; "
        "give it the clip dataset"
    )


def batch_tensor(batch: np.ndarray, device: torch.device) -> torch.Tensor:
    """A dataset batch as a tensor on ``device`` (uint8 clips stay uint8)."""
    return torch.from_numpy(np.ascontiguousarray(batch)).to(device)


@torch.inference_mode()
def embed_dataset(
    model: nn.Module,
    dataset: SDNDataset,
    *,
    device: str | None = None,
    batch_size: int = 32,
    progress: bool = False,
) -> np.ndarray:
    """Outputs of ``model`` (in eval mode) for every clip of ``dataset``.

    Returns:
        ``(N, D)`` float32.
    """
    target = resolve_device(device)
    module = module_for(model, dataset).to(target)
    was_training = module.training
    module.eval()
    chunks = []
    with progress_bar(progress) as bar:
        task = bar.add_task("embedding", total=len(dataset), info="")
        for start in range(0, len(dataset), batch_size):
            idx = np.arange(start, min(len(dataset), start + batch_size))
            chunks.append(
                module(batch_tensor(dataset.get_batch(idx), target)).float().cpu().numpy()
            )
            bar.advance(task, len(idx))
    module.train(was_training)
    return np.concatenate(chunks) if chunks else np.zeros((0, 0), dtype=np.float32)


def evaluate_triplets(
    model: nn.Module,
    dataset: SDNDataset,
    *,
    n_triplets: int | None = None,
    positives: PositiveRule = "simulation",
    seed: int = 0,
    device: str | None = None,
    batch_size: int = 32,
    progress: bool = False,
) -> dict[str, float | int]:
    """Triplet accuracy of ``model`` on a split (the CLI's ``evaluate triplets``).

    Args:
        model: An embedding network (SDN, a baseline, or the spectral pooling).
        dataset: The split (clips, or cached features for an SDN).
        n_triplets: Number of triplets (default: one per clip that has a positive).
        positives: ``"simulation"`` or ``"theta"`` (see :mod:`physinfer_flag.sdn.losses`).
        seed: Seed of the triplet draw.
        device: Torch device.
        batch_size: Clips per forward pass.
        progress: Show a progress bar on stderr.

    Returns:
        ``{"triplet_accuracy": float, "n_triplets": int}``.
    """
    labels = positive_labels(dataset.sim_ids, dataset.group_ids, positives)
    triplets = make_triplets(labels, n_triplets=n_triplets, seed=seed)
    embeddings = embed_dataset(
        model, dataset, device=device, batch_size=batch_size, progress=progress
    )
    return {
        "triplet_accuracy": triplet_accuracy(embeddings, triplets),
        "n_triplets": int(len(triplets)),
    }


# -- wind-speed regression -------------------------------------------------------------


@dataclass(frozen=True)
class RegressionConfig:
    """Settings of the regression head and its training.

    Attributes:
        target: The regressed parameter: a name in the dataset's ``theta_names`` or a
            column index.
        epochs: Passes over the training split.
        batch_size: Clips per step.
        lr: Adam learning rate.
        weight_decay: Adam weight decay.
        hidden: Width of the head's hidden layer.
        finetune: Train the backbone with the head (otherwise its output is fixed).
        seed: Seed of initialisation and batch order.
        progress: Show a progress bar on stderr.
    """

    target: str | int = "wind_speed"
    epochs: int = 30
    batch_size: int = 32
    lr: float = 1e-3
    weight_decay: float = 0.0
    hidden: int = 256
    finetune: bool = False
    seed: int = 0
    progress: bool = False

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if self.epochs < 1 or self.batch_size < 1 or self.hidden < 1:
            raise ValueError("epochs, batch_size and hidden must be positive")
        if self.lr <= 0 or self.weight_decay < 0:
            raise ValueError("lr must be positive and weight_decay non-negative")


def target_column(dataset: SDNDataset, target: str | int) -> int:
    """Column of θ that ``target`` names.

    Raises:
        UserInputError: unknown name or index out of range.
    """
    n = np.asarray(dataset.theta).shape[1]
    if isinstance(target, int):
        if not 0 <= target < n:
            raise UserInputError(f"θ has {n} columns; column {target} does not exist")
        return target
    names = list(dataset.theta_names)
    if target not in names:
        raise UserInputError(
            f"the dataset has no parameter {target!r}; it has {', '.join(names) or 'no names'}"
        )
    return names.index(target)


class RegressionHead(nn.Module):
    """Batch-normalised input, then a two-layer perceptron to one value.

    The input normalisation matters for fixed embeddings, whose scale the contrastive
    loss leaves free.

    Shapes:
        ``(N, in_dim)`` → ``(N,)``.
    """

    def __init__(self, in_dim: int, hidden: int = 256) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.BatchNorm1d(in_dim), nn.Linear(in_dim, hidden), nn.ReLU(), nn.Linear(hidden, 1)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Predictions in normalised units."""
        return self.net(x).squeeze(-1)


class Regressor(nn.Module):
    """A backbone, a regression head and the target's normalisation.

    Args:
        backbone: Maps an input batch to ``(N, D)`` features (its ``out_dim``).
        head: :class:`RegressionHead` on ``D`` features.
        mean: Training-set mean of the target.
        std: Training-set standard deviation of the target.

    Shapes:
        backbone input → ``(N,)`` predictions in the target's units.
    """

    def __init__(self, backbone: nn.Module, head: RegressionHead, mean: float, std: float) -> None:
        super().__init__()
        self.backbone, self.head = backbone, head
        self.register_buffer("mean", torch.tensor(float(mean)))
        self.register_buffer("std", torch.tensor(float(std)))

    def normalised(self, x: torch.Tensor) -> torch.Tensor:
        """Predictions in standardised units (what the loss sees)."""
        return self.head(self.backbone(x))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Predictions in the target's units."""
        return self.normalised(x) * self.std + self.mean


class _Embeddings:
    """Fixed backbone outputs as a tiny dataset (the head of a frozen backbone trains on these)."""

    def __init__(self, values: np.ndarray) -> None:
        self.values = values

    def get_batch(self, indices: np.ndarray) -> np.ndarray:
        return self.values[indices]


def frontend_config_of(model: nn.Module) -> FrontEndConfig | None:
    """The front-end settings whose features ``model`` can read, or ``None`` (clips only)."""
    if isinstance(model, SDN):
        return model.config.frontend
    if getattr(model, "input_kind", "clips") == "features":
        return model.frontend_config  # type: ignore[attr-defined, no-any-return]
    return None


def train_regressor(
    backbone: nn.Module,
    train: SDNDataset,
    *,
    config: RegressionConfig | None = None,
    device: str | None = None,
) -> Regressor:
    """Fit a regression head (and, with ``finetune``, the backbone) on a training split.

    Args:
        backbone: A module with ``out_dim`` (SDN, SDN head, a baseline, spectral pooling).
        train: The training split.
        config: Head and training settings.
        device: Torch device.

    Returns:
        The fitted :class:`Regressor`, in eval mode.
    """
    config = config or RegressionConfig()
    config.validate()
    target = resolve_device(device)
    column = target_column(train, config.target)
    y = np.asarray(train.theta, dtype=np.float64)[:, column]
    mean, std = float(y.mean()), float(y.std()) or 1.0
    y_norm = torch.tensor((y - mean) / std, dtype=torch.float32)
    torch.manual_seed(config.seed)
    head = RegressionHead(int(backbone.out_dim), config.hidden)
    regressor = Regressor(backbone, head, mean, std).to(target)
    if config.finetune:
        features_config = frontend_config_of(backbone)
        if features_config is not None:
            # The front end is fixed: compute its output once, not every epoch.
            train = as_features(train, features_config, device=str(target))
        module = module_for(backbone, train)
        inputs: SDNDataset | _Embeddings = train
        regressor.train()
        parameters = list(regressor.parameters())

        def forward(x: torch.Tensor) -> torch.Tensor:
            return head(module(x))

    else:
        # A fixed backbone is run once; the head then trains on its outputs.
        embeddings = embed_dataset(
            backbone, train, device=str(target), batch_size=config.batch_size
        )
        inputs = _Embeddings(embeddings)
        head.train()
        parameters = list(head.parameters())
        forward = head
    optimizer = torch.optim.Adam(parameters, lr=config.lr, weight_decay=config.weight_decay)
    rng = np.random.default_rng(config.seed)
    n = len(y)
    with progress_bar(config.progress) as bar:
        task = bar.add_task("regression head", total=config.epochs, info="")
        for _ in range(config.epochs):
            order = rng.permutation(n)
            for start in range(0, n, config.batch_size):
                idx = order[start : start + config.batch_size]
                if len(idx) < 2 <= n:
                    continue  # a batch of one breaks batch norm in training mode
                x = batch_tensor(inputs.get_batch(idx), target)
                loss = F.mse_loss(forward(x), y_norm[idx].to(target))
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
            bar.advance(task)
    return regressor.eval()


@torch.inference_mode()
def predict(
    regressor: Regressor, dataset: SDNDataset, *, device: str | None = None, batch_size: int = 32
) -> np.ndarray:
    """Predictions of a fitted regressor for every clip, ``(N,)`` float64."""
    target = resolve_device(device)
    regressor = regressor.to(target).eval()
    module = module_for(regressor.backbone, dataset)
    out = []
    for start in range(0, len(dataset), batch_size):
        idx = np.arange(start, min(len(dataset), start + batch_size))
        x = batch_tensor(dataset.get_batch(idx), target)
        out.append(
            (regressor.head(module(x)) * regressor.std + regressor.mean).double().cpu().numpy()
        )
    return np.concatenate(out) if out else np.zeros(0)


def regression_metrics(predicted: np.ndarray, true: np.ndarray) -> dict[str, float | int]:
    """``{"mse", "acc_at_0_5", "n"}``: mean squared error and the fraction within 0.5."""
    predicted, true = np.asarray(predicted, dtype=np.float64), np.asarray(true, dtype=np.float64)
    err = predicted - true
    return {
        "mse": float(np.mean(err**2)),
        "acc_at_0_5": float(np.mean(np.abs(err) <= ACC_TOLERANCE)),
        "n": int(len(err)),
    }


def evaluate_wind(
    backbone: nn.Module,
    train: SDNDataset,
    test: SDNDataset,
    *,
    config: RegressionConfig | None = None,
    device: str | None = None,
) -> dict[str, float | int]:
    """Fit a regression head on ``train`` and score it on ``test`` (the CLI's ``evaluate wind``).

    Returns:
        ``{"mse": float, "acc_at_0_5": float, "n": int}`` on ``test``.
    """
    config = config or RegressionConfig()
    regressor = train_regressor(backbone, train, config=config, device=device)
    column = target_column(test, config.target)
    predicted = predict(regressor, test, device=device, batch_size=config.batch_size)
    return regression_metrics(predicted, np.asarray(test.theta)[:, column])
