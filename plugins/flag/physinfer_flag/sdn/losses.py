"""The contrastive loss (Hadsell, Chopra & LeCun 2006) with Batch All pair mining.

Every pair of a batch is used (Batch All, Hermans et al. 2017; Ding et al. 2015): pairs
with the same label are positives, pulled together by ``½ D²``; pairs with different
labels are negatives, pushed apart by ``½ max(0, m − D)²``, with ``D`` the Euclidean
distance of the two embeddings. Positive and negative terms are averaged separately and
added, so that the many negatives of a batch do not drown the few positives.

Labels are simulation ids (the paper: renders of one simulation are positives) or, as an
option, θ-group ids (all simulation seeds of one θ are positives, since the flag is
chaotic and a real target is never the same realisation as any simulation).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch

from physinfer.errors import UserInputError

PositiveRule = Literal["simulation", "theta"]

# Gradients of sqrt at 0 are infinite; identical embeddings are common early in training.
_DISTANCE_EPS = 1e-12


@dataclass(frozen=True)
class ContrastiveStats:
    """What one loss evaluation saw.

    Attributes:
        loss: The loss (a scalar tensor carrying gradients).
        positive_loss: Mean ``½ D²`` over positive pairs (0 when there are none).
        negative_loss: Mean ``½ max(0, m − D)²`` over negative pairs.
        n_positive: Number of positive pairs (unordered).
        n_negative: Number of negative pairs (unordered).
        active_negative_fraction: Fraction of negative pairs closer than the margin.
    """

    loss: torch.Tensor
    positive_loss: float
    negative_loss: float
    n_positive: int
    n_negative: int
    active_negative_fraction: float


def pairwise_distances(embeddings: torch.Tensor) -> torch.Tensor:
    """Euclidean distances between all rows, ``(B, D)`` → ``(B, B)`` (differentiable)."""
    squared = (embeddings[:, None, :] - embeddings[None, :, :]).square().sum(-1)
    return torch.sqrt(squared.clamp_min(_DISTANCE_EPS))


def pair_masks(labels: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Boolean masks of positive and negative pairs, upper triangle only.

    Args:
        labels: ``(B,)`` integer labels.

    Returns:
        ``(positive, negative)``, each ``(B, B)`` bool, ``i < j``.
    """
    same = labels[:, None] == labels[None, :]
    upper = torch.ones_like(same).triu(diagonal=1)
    return same & upper, ~same & upper


def contrastive_loss(
    embeddings: torch.Tensor, labels: torch.Tensor, *, margin: float = 1.0
) -> ContrastiveStats:
    """Batch All contrastive loss.

    Args:
        embeddings: ``(B, D_e)`` embeddings.
        labels: ``(B,)`` integer labels (equal labels make a positive pair).
        margin: ``m``: negatives farther apart than this cost nothing.

    Returns:
        The loss and the pair statistics.

    Raises:
        UserInputError: when the batch holds no pair at all (fewer than 2 rows).
    """
    if embeddings.ndim != 2 or labels.shape != embeddings.shape[:1]:
        raise UserInputError(
            f"embeddings must be (B, D) and labels (B,), got {tuple(embeddings.shape)} and {tuple(labels.shape)}"
        )
    if embeddings.shape[0] < 2:
        raise UserInputError("the contrastive loss needs at least two embeddings per batch")
    distances = pairwise_distances(embeddings)
    positive, negative = pair_masks(labels.to(embeddings.device))
    zero = embeddings.sum() * 0.0  # keeps the graph when a batch lacks one kind of pair
    pos_terms = 0.5 * distances[positive].square()
    neg_gap = (margin - distances[negative]).clamp_min(0.0)
    neg_terms = 0.5 * neg_gap.square()
    pos_loss = pos_terms.mean() if pos_terms.numel() else zero
    neg_loss = neg_terms.mean() if neg_terms.numel() else zero
    n_neg = int(neg_terms.numel())
    return ContrastiveStats(
        loss=pos_loss + neg_loss,
        positive_loss=float(pos_loss.detach()),
        negative_loss=float(neg_loss.detach()),
        n_positive=int(pos_terms.numel()),
        n_negative=n_neg,
        active_negative_fraction=float((neg_gap > 0).sum()) / n_neg if n_neg else 0.0,
    )


def positive_labels(
    sim_ids: np.ndarray, group_ids: np.ndarray | None, rule: PositiveRule
) -> np.ndarray:
    """The labels that define positives under ``rule``.

    Args:
        sim_ids: ``(N,)`` simulation id of each clip.
        group_ids: ``(N,)`` θ-group id of each clip (clips of simulations that share θ
            and differ only in seed share a group), or ``None``.
        rule: ``"simulation"`` (the paper) or ``"theta"`` (across seeds).

    Returns:
        ``(N,)`` int64 labels.

    Raises:
        UserInputError: ``"theta"`` without group ids, or an unknown rule.
    """
    if rule == "simulation":
        return np.asarray(sim_ids, dtype=np.int64)
    if rule == "theta":
        if group_ids is None:
            raise UserInputError(
                "positives='theta' needs θ-group ids in the dataset (clips of one θ rendered from several "
                "simulation seeds); use positives='simulation' or add group ids"
            )
        return np.asarray(group_ids, dtype=np.int64)
    raise UserInputError(f"unknown positive rule {rule!r}; use 'simulation' or 'theta'")
