"""Training the SDN with the contrastive loss: resumable, one checkpoint per epoch.

The front end is fixed, so a clip dataset is turned into front-end features once (or
cached features are read directly) and only the head trains. Batches are P×K: clips
are grouped ``clips_per_label`` at a time by label (simulation or θ group), and groups
are shuffled into batches of ``batch_size``, so that every batch holds positives for
Batch All mining and every clip is seen once per epoch.

``train_sdn(train, val, out_dir=...)`` writes into ``out_dir``:

- ``checkpoint.safetensors``: network and Adam state after the last finished epoch,
  with the configuration, history and best score in its metadata (one atomic file, so
  an interrupted run resumes from a consistent state);
- ``sdn.safetensors``: the best network so far on the validation split (highest triplet
  accuracy, ties broken by lower validation loss; the last epoch without a validation
  split), in the weights format of :mod:`physinfer_flag.sdn.weights`;
- ``history.json``: per-epoch losses and scores, for people and plots.

Calling it again with the same output directory continues where it stopped; raising
``epochs`` extends a finished run.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import safe_open
from safetensors.torch import save_file

from physinfer.errors import UserInputError
from physinfer.io import atomic_path, atomic_write_json, to_jsonable
from physinfer_flag.sdn.data import SDNDataset, as_features
from physinfer_flag.sdn.evaluation import embed_dataset, make_triplets, triplet_accuracy
from physinfer_flag.sdn.losses import PositiveRule, contrastive_loss, positive_labels
from physinfer_flag.sdn.network import SDN, SDNConfig
from physinfer_flag.sdn.progress import progress_bar
from physinfer_flag.sdn.settings import resolve_device, settings_from_dict
from physinfer_flag.sdn.weights import WEIGHTS_FILE, save_sdn

CHECKPOINT_FILE = "checkpoint.safetensors"
HISTORY_FILE = "history.json"
CHECKPOINT_FORMAT = "physinfer-sdn-checkpoint/1"
# Settings that may change between a run and its resumption.
_RESUMABLE_CHANGES = ("epochs", "progress", "frontend_batch_size")


@dataclass(frozen=True)
class TrainConfig:
    """Settings of contrastive training (the paper's values by default).

    Attributes:
        epochs: Passes over the training split.
        batch_size: Clips per batch (the paper: 32).
        clips_per_label: Clips of one label placed together in a batch (K of P×K).
        lr: Adam learning rate (the paper: 1e-2).
        weight_decay: Adam weight decay (the paper: 2e-3).
        margin: Contrastive margin (the paper: 1).
        positives: ``"simulation"`` (renders of one simulation, the paper) or ``"theta"``
            (all simulation seeds of one θ).
        seed: Seed of initialisation, batch order and validation triplets.
        n_val_triplets: Validation triplets (default: one per validation clip).
        frontend_batch_size: Clips per front-end pass when features are computed.
        progress: Show progress bars on stderr.
    """

    epochs: int = 30
    batch_size: int = 32
    clips_per_label: int = 4
    lr: float = 1e-2
    weight_decay: float = 2e-3
    margin: float = 1.0
    positives: PositiveRule = "simulation"
    seed: int = 0
    n_val_triplets: int | None = None
    frontend_batch_size: int = 8
    progress: bool = True

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if self.epochs < 0:
            raise ValueError(f"epochs must be non-negative, got {self.epochs}")
        if self.batch_size < 2:
            raise ValueError(f"batch_size must be at least 2, got {self.batch_size}")
        if not 2 <= self.clips_per_label <= self.batch_size:
            raise ValueError("clips_per_label must be between 2 and batch_size")
        if self.lr <= 0 or self.weight_decay < 0 or self.margin <= 0:
            raise ValueError("lr and margin must be positive, weight_decay non-negative")
        if self.positives not in ("simulation", "theta"):
            raise ValueError(f"positives must be 'simulation' or 'theta', got {self.positives!r}")
        if self.n_val_triplets is not None and self.n_val_triplets < 1:
            raise ValueError("n_val_triplets must be positive")
        if self.frontend_batch_size < 1:
            raise ValueError("frontend_batch_size must be positive")

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainConfig:
        """Rebuild from :meth:`to_dict` output."""
        return settings_from_dict(cls, data)


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train_sdn` produced.

    Attributes:
        out_dir: The output directory.
        weights: The best network's weights file (``sdn.safetensors``).
        checkpoint: The resumable checkpoint.
        epochs_completed: Epochs finished in total (over all resumptions).
        best_epoch: Epoch (1-based) of the best network.
        best: Scores of the best network (``val_triplet_accuracy``, ``val_loss``, ``train_loss``).
        history: One record per epoch.
    """

    out_dir: Path
    weights: Path
    checkpoint: Path
    epochs_completed: int
    best_epoch: int
    best: dict[str, float | None]
    history: list[dict[str, Any]]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (what ``physinfer train --json`` prints)."""
        return to_jsonable(dataclasses.asdict(self))


# -- batches ---------------------------------------------------------------------------


def label_batches(
    labels: np.ndarray, *, batch_size: int, clips_per_label: int, rng: np.random.Generator
) -> list[np.ndarray]:
    """P×K batches covering every clip once.

    Each label's clips are shuffled and cut into groups of ``clips_per_label``; the
    groups are shuffled and packed into batches of at most ``batch_size`` clips.

    Args:
        labels: ``(N,)`` labels.
        batch_size: Maximum clips per batch.
        clips_per_label: Group size ``K``.
        rng: Source of the shuffles.

    Returns:
        Index arrays, one per batch.
    """
    groups: list[np.ndarray] = []
    for label in np.unique(labels):
        members = rng.permutation(np.flatnonzero(labels == label))
        groups.extend(
            members[i : i + clips_per_label] for i in range(0, len(members), clips_per_label)
        )
    batches: list[np.ndarray] = []
    current: list[np.ndarray] = []
    size = 0
    for g in rng.permutation(len(groups)):
        group = groups[g]
        if size + len(group) > batch_size and current:
            batches.append(np.concatenate(current))
            current, size = [], 0
        current.append(group)
        size += len(group)
    if current:
        batches.append(np.concatenate(current))
    return batches


def dataset_fingerprint(dataset: SDNDataset, labels: np.ndarray) -> str:
    """A short hash of a split's size and labels, to refuse resuming on other data."""
    h = hashlib.sha256()
    h.update(str(len(dataset)).encode())
    h.update(np.ascontiguousarray(labels, dtype=np.int64).tobytes())
    h.update(np.ascontiguousarray(dataset.sim_ids, dtype=np.int64).tobytes())
    return h.hexdigest()[:16]


# -- checkpoints -----------------------------------------------------------------------


def save_checkpoint(
    path: Path, model: SDN, optimizer: torch.optim.Optimizer, state: Mapping[str, Any]
) -> None:
    """Write network, optimizer and run state to one safetensors file (atomically)."""
    tensors = {f"model.{k}": v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    opt = optimizer.state_dict()
    for pid, entries in opt["state"].items():
        for name, value in entries.items():
            tensors[f"optim.{pid}.{name}"] = torch.as_tensor(value).detach().cpu().contiguous()
    metadata = {
        "format": CHECKPOINT_FORMAT,
        "state": json.dumps(to_jsonable(dict(state)), allow_nan=False),
        "param_groups": json.dumps(to_jsonable(opt["param_groups"])),
    }
    with atomic_path(path, suffix=".safetensors") as tmp:
        save_file(tensors, str(tmp), metadata=metadata)


def read_checkpoint(
    path: Path,
) -> tuple[dict[str, torch.Tensor], dict[str, Any], list[dict[str, Any]]]:
    """Tensors, run state and optimizer parameter groups of a checkpoint.

    Raises:
        UserInputError: unreadable or foreign file.
    """
    try:
        with safe_open(str(path), framework="pt", device="cpu") as f:
            meta = f.metadata() or {}
            tensors = {name: f.get_tensor(name) for name in f.keys()}  # noqa: SIM118
        if meta.get("format") != CHECKPOINT_FORMAT:
            raise ValueError(f"format {meta.get('format')!r}, expected {CHECKPOINT_FORMAT!r}")
        return tensors, json.loads(meta["state"]), json.loads(meta["param_groups"])
    except Exception as exc:  # safetensors and json raise many types on damage
        raise UserInputError(
            f"cannot resume from {path} ({type(exc).__name__}: {exc}); delete it or pass --no-resume"
        ) from None


def restore(
    model: SDN,
    optimizer: torch.optim.Optimizer,
    tensors: Mapping[str, torch.Tensor],
    param_groups: list[dict[str, Any]],
) -> None:
    """Load network and optimizer state read by :func:`read_checkpoint`."""
    model.load_state_dict(
        {k[6:]: v for k, v in tensors.items() if k.startswith("model.")}, strict=True
    )
    state: dict[int, dict[str, torch.Tensor]] = {}
    for key, value in tensors.items():
        if key.startswith("optim."):
            _, pid, name = key.split(".", 2)
            state.setdefault(int(pid), {})[name] = value
    optimizer.load_state_dict({"state": state, "param_groups": param_groups})


#: ``TrainConfig`` fields as ``physinfer train`` spells them (the others have no option).
_OPTION = {"batch_size": "--batch-size", "clips_per_label": "--batch-size", "seed": "--seed", "positives": "--positives"}
#: What a resumed run's stored entries are set by, in ``physinfer train``'s options.
_SET_BY = {
    "model_config": " (--frames, --size)",
    "train_fingerprint": " (the train split of --data)",
    "val_fingerprint": " (the val split of --data)",
}


def _check_resumable(stored: Mapping[str, Any], current: Mapping[str, Any], path: Path) -> None:
    for key in ("model_config", "train_fingerprint", "val_fingerprint"):
        if stored.get(key) != current.get(key):
            raise UserInputError(
                f"{path} belongs to a run with a different {key.replace('_', ' ')}{_SET_BY[key]}; "
                "use another --out, or pass --no-resume to start over"
            )
    old = {k: v for k, v in stored["train_config"].items() if k not in _RESUMABLE_CHANGES}
    new = {k: v for k, v in current["train_config"].items() if k not in _RESUMABLE_CHANGES}
    if old != new:
        changed = sorted({_OPTION.get(k, k) for k in new if old.get(k) != new[k]})
        raise UserInputError(
            f"{path} was trained with other settings ({', '.join(changed)}); only --epochs may "
            "change on resume. Use another --out, or pass --no-resume to start over"
        )


# -- training --------------------------------------------------------------------------


def _run_epoch(
    model: SDN,
    optimizer: torch.optim.Optimizer,
    features: SDNDataset,
    labels: np.ndarray,
    config: TrainConfig,
    rng: np.random.Generator,
    device: torch.device,
    on_batch: Any,
) -> dict[str, float]:
    model.head.train()
    totals = {
        "train_loss": 0.0,
        "train_positive_loss": 0.0,
        "train_negative_loss": 0.0,
        "train_active_negatives": 0.0,
    }
    n_batches = 0
    for idx in label_batches(
        labels, batch_size=config.batch_size, clips_per_label=config.clips_per_label, rng=rng
    ):
        if len(idx) < 2:
            continue
        x = torch.from_numpy(features.get_batch(idx)).to(device)
        stats = contrastive_loss(
            model.head(x), torch.from_numpy(labels[idx]).to(device), margin=config.margin
        )
        optimizer.zero_grad(set_to_none=True)
        stats.loss.backward()
        optimizer.step()
        totals["train_loss"] += float(stats.loss.detach())
        totals["train_positive_loss"] += stats.positive_loss
        totals["train_negative_loss"] += stats.negative_loss
        totals["train_active_negatives"] += stats.active_negative_fraction
        n_batches += 1
        on_batch(float(stats.loss.detach()))
    return {k: v / max(1, n_batches) for k, v in totals.items()}


@torch.no_grad()
def _validate(
    model: SDN,
    features: SDNDataset,
    labels: np.ndarray,
    triplets: np.ndarray,
    config: TrainConfig,
    device: torch.device,
) -> dict[str, float]:
    model.eval()
    embeddings = embed_dataset(model, features, device=str(device), batch_size=config.batch_size)
    # A fixed batch order (independent of the epoch) makes validation losses comparable.
    rng = np.random.default_rng([config.seed, 2**31 - 1])
    losses = []
    for idx in label_batches(
        labels, batch_size=config.batch_size, clips_per_label=config.clips_per_label, rng=rng
    ):
        if len(idx) >= 2:
            e = torch.from_numpy(embeddings[idx])
            losses.append(
                float(contrastive_loss(e, torch.from_numpy(labels[idx]), margin=config.margin).loss)
            )
    return {
        "val_loss": float(np.mean(losses)) if losses else float("nan"),
        "val_triplet_accuracy": triplet_accuracy(embeddings, triplets),
    }


def _score(record: Mapping[str, Any]) -> tuple[float, float]:
    acc = record.get("val_triplet_accuracy")
    if acc is None:
        return (0.0, -float(record["train_loss"]))
    val_loss = record.get("val_loss")
    return (float(acc), -float(val_loss) if val_loss is not None else 0.0)


def train_sdn(
    train: SDNDataset,
    val: SDNDataset | None = None,
    *,
    out_dir: str | Path,
    model_config: SDNConfig | None = None,
    config: TrainConfig | None = None,
    resume: bool = True,
    device: str | None = None,
    info: Mapping[str, Any] | None = None,
) -> TrainResult:
    """Train an SDN with the contrastive loss; checkpoint every epoch; keep the best.

    Args:
        train: Training split (clips or cached features).
        val: Validation split (selects the best network), or ``None``.
        out_dir: Output directory (created); see the module docstring for its files.
        model_config: Architecture (default: the paper's SDN).
        config: Training settings (default: the paper's).
        resume: Continue from ``out_dir``'s checkpoint when there is one.
        device: Torch device (default: cuda if available, else cpu).
        info: Provenance stored with the weights (e.g. the dataset path, the command).

    Returns:
        Paths, scores and history of the run.

    Raises:
        UserInputError: bad settings, a split without positives, or a checkpoint of a
            different run in ``out_dir``.
    """
    model_config = model_config or SDNConfig()
    config = config or TrainConfig()
    for settings in (model_config, config):
        try:
            settings.validate()
        except ValueError as exc:
            raise UserInputError(f"invalid {type(settings).__name__}: {exc}") from None
    target = resolve_device(device)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    checkpoint_path, weights_path = out / CHECKPOINT_FILE, out / WEIGHTS_FILE

    train_labels = positive_labels(train.sim_ids, train.group_ids, config.positives)
    if len(np.unique(train_labels)) == len(train_labels):
        raise UserInputError(
            "the training split has no positive pairs: every clip has its own label"
        )
    val_labels = (
        None if val is None else positive_labels(val.sim_ids, val.group_ids, config.positives)
    )
    val_triplets = (
        None
        if val_labels is None
        else make_triplets(val_labels, n_triplets=config.n_val_triplets, seed=config.seed)
    )
    run = {
        "model_config": model_config.to_dict(),
        "train_config": config.to_dict(),
        "train_fingerprint": dataset_fingerprint(train, train_labels),
        "val_fingerprint": None if val is None else dataset_fingerprint(val, val_labels),  # type: ignore[arg-type]
    }

    torch.manual_seed(config.seed)
    model = SDN(config=model_config).to(target)
    optimizer = torch.optim.Adam(
        model.head.parameters(), lr=config.lr, weight_decay=config.weight_decay
    )
    history: list[dict[str, Any]] = []
    best: dict[str, Any] = {}
    if resume and checkpoint_path.is_file():
        tensors, stored, param_groups = read_checkpoint(checkpoint_path)
        _check_resumable(stored, run, checkpoint_path)
        restore(model, optimizer, tensors, param_groups)
        for group in optimizer.param_groups:
            group["betas"] = tuple(group["betas"])
        history, best = list(stored["history"]), dict(stored["best"])
        model.to(target)

    features = {
        "train": as_features(
            train,
            model_config.frontend,
            device=str(target),
            batch_size=config.frontend_batch_size,
            progress=config.progress,
        )
    }
    if val is not None:
        features["val"] = as_features(
            val,
            model_config.frontend,
            device=str(target),
            batch_size=config.frontend_batch_size,
            progress=config.progress,
        )

    with progress_bar(config.progress) as bar:
        epochs_task = bar.add_task("epochs", total=config.epochs, completed=len(history), info="")
        batch_task = bar.add_task("batches", total=None, info="")
        for epoch in range(len(history), config.epochs):
            started = time.perf_counter()
            bar.reset(batch_task, total=None)

            def on_batch(loss: float) -> None:
                bar.update(batch_task, advance=1, info=f"loss {loss:.4f}")

            rng = np.random.default_rng([config.seed, epoch])
            record: dict[str, Any] = {"epoch": epoch + 1}
            record.update(
                _run_epoch(
                    model, optimizer, features["train"], train_labels, config, rng, target, on_batch
                )
            )
            if val is not None:
                record.update(
                    _validate(model, features["val"], val_labels, val_triplets, config, target)
                )  # type: ignore[arg-type]
            record["seconds"] = time.perf_counter() - started
            history.append(to_jsonable(record))
            if not best or _score(record) > _score(best):
                best = dict(history[-1])
                save_sdn(
                    model,
                    weights_path,
                    info={
                        **dict(info or {}),
                        "epoch": epoch + 1,
                        "scores": best,
                        "train_config": config.to_dict(),
                    },
                )
            save_checkpoint(
                checkpoint_path, model, optimizer, {**run, "history": history, "best": best}
            )
            atomic_write_json(out / HISTORY_FILE, {"history": history, "best": best})
            summary = f"loss {record['train_loss']:.4f}"
            if "val_triplet_accuracy" in record:
                summary += f" · val acc {record['val_triplet_accuracy']:.3f}"
            bar.update(epochs_task, advance=1, info=summary)
    # Again after the loop: a run killed between the checkpoint and history.json resumes with
    # every epoch done, runs none, and would otherwise leave the older history behind.
    atomic_write_json(out / HISTORY_FILE, {"history": history, "best": best})

    if not weights_path.is_file():  # epochs=0: still leave usable (untrained) weights
        save_sdn(
            model,
            weights_path,
            info={**dict(info or {}), "epoch": 0, "train_config": config.to_dict()},
        )
    return TrainResult(
        out_dir=out,
        weights=weights_path,
        checkpoint=checkpoint_path,
        epochs_completed=len(history),
        best_epoch=int(best.get("epoch", 0)),
        best={k: best.get(k) for k in ("val_triplet_accuracy", "val_loss", "train_loss")},
        history=history,
    )
