"""Training an amortized posterior with sbi's NPE on cached (θ, embedding) pairs.

sbi trains the density estimator; physinfer only feeds it the pairs, seeds it, and steps
it a few epochs at a time (``resume_training``) so a progress callback can report the
validation loss. Retraining from the cached embeddings takes minutes on 2 CPU cores, so a
killed training is redone rather than resumed.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from collections.abc import Callable, Iterator, Mapping
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from physinfer.errors import UserInputError
from physinfer.posterior.estimator import EstimatorConfig, NetworkConfig, PosteriorEstimator
from physinfer.posterior.features import EmbeddedSet
from physinfer.posterior.flows import FlowEnsemble, to_unbounded
from physinfer.posterior.inputs import input_statistics

#: Epochs between two progress reports.
EPOCHS_PER_REPORT = 5
#: Fewer pairs than this cannot train a flow that says anything.
MIN_PAIRS = 50


def train_estimator(
    pairs: EmbeddedSet,
    identity: Mapping[str, Any],
    *,
    network: NetworkConfig | None = None,
    seed: int = 0,
    device: str = "cpu",
    on_epoch: Callable[[int, int, float], None] | None = None,
) -> PosteriorEstimator:
    """Train q(θ | s(x)) on ``pairs`` with sbi's NPE.

    Args:
        pairs: θ (normalised) and embeddings of the training clips (with the render
            settings the estimator is told, :meth:`EmbeddedSet.with_render_inputs`).
        identity: The :class:`EstimatorConfig` fields naming plugin, embedder (name, frames,
            fps, probe) and clip length.
        network: Density estimator and training settings.
        seed: Seeds torch (initialisation, batches, the validation split); member k of an
            ensemble (``network.ensemble``) uses ``seed + k``.
        device: Torch device to train on.
        on_epoch: Called as ``(epochs_done, max_epochs, best_validation_loss)``.

    Raises:
        UserInputError: too few pairs, or settings sbi cannot use.
    """
    network = network or NetworkConfig()
    network.validate()
    if len(pairs) < MIN_PAIRS:
        raise UserInputError(
            f"{len(pairs)} training clips are too few for a posterior estimator (at least {MIN_PAIRS}); "
            "generate more with `physinfer dataset generate --sims N`"
        )
    theta = torch.from_numpy(
        to_unbounded(np.asarray(pairs.theta_unit, dtype=np.float64)).astype(np.float32)
    )
    x = torch.from_numpy(np.asarray(pairs.conditions, dtype=np.float32))
    members, runs = [], []
    for k in range(network.ensemble):
        # Member k sees the epochs of those before it: one progress bar over the ensemble.
        def report(done: int, total: int, best: float, k: int = k) -> None:
            if on_epoch is not None:
                on_epoch(k * total + done, network.ensemble * total, best)

        with _private_rngs():
            member, run = _train_one(theta, x, network, seed=seed + k, device=device, on_epoch=report)
        members.append(member)
        runs.append(run)
    training = {
        "pairs": len(pairs),
        "epochs": runs[0]["epochs"] if len(runs) == 1 else [r["epochs"] for r in runs],
        "best_validation_loss": runs[0]["best_validation_loss"]
        if len(runs) == 1
        else [r["best_validation_loss"] for r in runs],
        "seed": seed,
        "device": device,
    }
    estimator = members[0] if len(members) == 1 else FlowEnsemble(members)
    config = EstimatorConfig(
        **dict(identity),
        parameters=pairs.parameter_space.to_dict(),
        x_dim=int(x.shape[1]),
        network=network,
        scene_ranges={k: list(v) for k, v in pairs.scene_ranges.items()} or None,
        targets={"as_given": dict(pairs.as_given)} if pairs.as_given else None,
        inputs=input_statistics(pairs.conditions),
        render_inputs={k: list(v) for k, v in pairs.render_inputs.items()} or None,
    )
    config = replace(config, training={**config.training, **training})
    trained = PosteriorEstimator(config, estimator.cpu(), "cpu")
    trained.validation_curves = [r["validation_curve"] for r in runs]
    return trained


def _train_one(
    theta: torch.Tensor,
    x: torch.Tensor,
    network: NetworkConfig,
    *,
    seed: int,
    device: str,
    on_epoch: Callable[[int, int, float], None],
) -> tuple[torch.nn.Module, dict[str, Any]]:
    """One flow trained with sbi's NPE on ``(atanh θ, x)``; returns it and its epochs and loss."""
    from sbi.inference import NPE

    torch.manual_seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - sbi draws its validation split from torch and numpy
    # No prior: the flow is trained on atanh(θ) (unbounded), and the dataset's θ already
    # follow the prior, which is all single-round NPE needs.
    inference = NPE(
        prior=None, density_estimator=network.builder(), device=device, show_progress_bars=False,
        tracker=_NoTracker(),
    )  # fmt: skip
    _quiet(inference.append_simulations, theta=theta, x=x)  # its z-scoring warnings: ours are in the file
    settings = {
        "training_batch_size": network.batch_size,
        "learning_rate": network.learning_rate,
        "validation_fraction": network.validation_fraction,
        "stop_after_epochs": network.stop_after_epochs,
        "show_train_summary": False,
    }
    estimator = _quiet(
        inference.train, max_num_epochs=min(EPOCHS_PER_REPORT, network.max_epochs), **settings
    )
    while True:
        best = float(inference._summary["best_validation_loss"][-1])
        on_epoch(min(inference.epoch, network.max_epochs), network.max_epochs, best)
        # sbi keeps the best weights at the end of every call; it has converged once the
        # validation loss has not improved for the patience.
        stalled = inference._epochs_since_last_improvement >= network.stop_after_epochs
        if stalled or inference.epoch >= network.max_epochs:
            break
        target = min(inference.epoch + EPOCHS_PER_REPORT, network.max_epochs)
        estimator = _quiet(inference.train, max_num_epochs=target, resume_training=True, **settings)
    run = {
        "epochs": int(inference.epoch),
        "best_validation_loss": float(inference._summary["best_validation_loss"][-1]),
        "validation_curve": [float(v) for v in inference._summary["validation_loss"]],
    }
    return estimator, run


@contextlib.contextmanager
def _private_rngs() -> Iterator[None]:
    """Seed torch's and numpy's global generators for one flow (sbi draws from both), then
    give the caller's state back: training in a notebook must not reset its random streams."""
    state = np.random.get_state()  # noqa: NPY002 - the global state sbi uses
    with torch.random.fork_rng():
        try:
            yield
        finally:
            np.random.set_state(state)  # noqa: NPY002


def _quiet(train: Callable[..., Any], **kwargs: Any) -> Any:
    """Call sbi's ``train`` without its prints on stdout (``--json`` owns stdout) and without
    its "maximum epochs reached" warning, which every chunk of epochs but the last raises, nor its
    warning on constant embedding dimensions (a spectral embedder's empty bands; sbi's z-scoring
    maps them to zero, as they should be)."""
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*Maximum number of epochs.*")
        warnings.filterwarnings("ignore", message=".*constant values in dimension.*")
        warnings.filterwarnings("ignore", message=".*extreme outliers in dimension.*")
        warnings.filterwarnings("ignore", message=".*prior.*")
        return train(**kwargs)


class _NoTracker:
    """sbi's tracker protocol, keeping nothing: its default writes TensorBoard logs into
    ``./sbi-logs``, outside the run's ``--out``."""

    log_dir = None

    def log_metric(self, name: str, value: float, step: int | None = None) -> None:
        pass

    def log_metrics(self, metrics: Mapping[str, float], step: int | None = None) -> None:
        pass

    def log_params(self, params: Mapping[str, Any]) -> None:
        pass

    def add_figure(self, name: str, figure: Any, step: int | None = None) -> None:
        pass

    def flush(self) -> None:
        pass
