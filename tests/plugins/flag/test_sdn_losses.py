"""The contrastive loss with Batch All mining, and the choice of positives."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physinfer.errors import UserInputError
from physinfer_flag.sdn.losses import contrastive_loss, pair_masks, positive_labels


def test_loss_matches_a_hand_computation():
    e = torch.tensor([[0.0, 0.0], [0.3, 0.4], [0.6, 0.0], [3.0, 0.0]])
    labels = torch.tensor([0, 0, 1, 1])
    stats = contrastive_loss(e, labels, margin=1.0)
    # Positives: (0,1) D=0.5, (2,3) D=2.4. Negatives: (0,2) D=0.6, (0,3) D=3, (1,2) D=0.5, (1,3) D=2.7...
    pos = (0.5 * 0.5**2 + 0.5 * 2.4**2) / 2
    d12 = float(np.hypot(0.3, 0.4))
    neg = (0.5 * (1 - 0.6) ** 2 + 0.0 + 0.5 * (1 - d12) ** 2 + 0.0) / 4
    assert float(stats.loss) == pytest.approx(pos + neg, rel=1e-6)
    assert (stats.n_positive, stats.n_negative) == (2, 4)
    assert stats.active_negative_fraction == pytest.approx(0.5)


def test_no_loss_when_positives_coincide_and_negatives_are_beyond_the_margin():
    e = torch.tensor([[0.0, 0.0], [0.0, 0.0], [2.0, 0.0], [2.0, 0.0]], requires_grad=True)
    stats = contrastive_loss(e, torch.tensor([5, 5, 7, 7]), margin=1.0)
    assert float(stats.loss.detach()) == pytest.approx(0.0, abs=1e-10)
    stats.loss.backward()
    assert torch.isfinite(e.grad).all()  # no NaN from sqrt at zero distance


def test_a_gradient_step_separates_negatives_relative_to_positives():
    torch.manual_seed(0)
    e = torch.randn(6, 4) * 0.2
    e.requires_grad_(True)
    labels = torch.tensor([0, 0, 1, 1, 2, 2])
    positive, negative = pair_masks(labels)

    def mean_distances(x):
        d = torch.cdist(x, x)
        return float(d[positive].mean()), float(d[negative].mean())

    before = mean_distances(e.detach())
    loss_before = contrastive_loss(e, labels).loss
    loss_before.backward()
    stepped = (e - 0.05 * e.grad).detach()
    after = mean_distances(stepped)
    assert float(contrastive_loss(stepped, labels).loss) < float(loss_before.detach())
    assert after[0] < before[0]
    assert after[1] / after[0] > before[1] / before[0]


def test_batch_all_uses_every_pair_once():
    positive, negative = pair_masks(torch.tensor([0, 0, 0, 1, 1]))
    assert int(positive.sum()) == 3 + 1 and int(negative.sum()) == 3 * 2
    assert not (positive & negative).any() and not positive.diagonal().any()


def test_positive_rules():
    sims, groups = np.array([0, 0, 1, 1, 2]), np.array([0, 0, 0, 0, 1])
    np.testing.assert_array_equal(positive_labels(sims, groups, "simulation"), sims)
    np.testing.assert_array_equal(positive_labels(sims, groups, "theta"), groups)
    with pytest.raises(UserInputError, match="group ids"):
        positive_labels(sims, None, "theta")
    with pytest.raises(UserInputError, match="unknown"):
        positive_labels(sims, groups, "render")  # type: ignore[arg-type]


def test_a_batch_of_one_is_refused():
    with pytest.raises(UserInputError, match="at least two"):
        contrastive_loss(torch.zeros(1, 3), torch.zeros(1, dtype=torch.long))
