"""The flows behind an amortized posterior: the coordinates they are trained in, an untrained
network of a stored shape, and an ensemble of seeded flows sampled as one.

:mod:`physinfer.posterior.estimator` saves, loads and checks an estimator; this module holds
the torch networks it carries.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import torch

# nflows' LU transform (inside sbi's spline flows) calls torch.triangular_solve, which torch
# reports as deprecated on every first use: six lines of torch's internals printed above a
# user's `physinfer infer` answer, about code neither they nor we can change.
warnings.filterwarnings(
    "ignore", message="torch.triangular_solve is deprecated", category=UserWarning
)

#: Normalised coordinates are kept this far inside ``±1`` before ``atanh``.
EDGE = 1e-6


def to_unbounded(theta_unit: np.ndarray) -> np.ndarray:
    """``[-1, 1]`` → the real line (``atanh``), where the flow is trained.

    A flow on the bounded cube leaks mass outside it (three quarters of the flag's first
    estimator's samples fell outside, and rejecting them made sampling ~4× slower); on the
    real line every sample maps back inside.
    """
    return np.arctanh(np.clip(theta_unit, -1.0 + EDGE, 1.0 - EDGE))


def to_unit(phi: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_unbounded` (``tanh``)."""
    return np.tanh(phi)


def build_network(config: Any) -> torch.nn.Module:
    """An untrained network of ``config``'s shape (an :class:`~physinfer.posterior.estimator.EstimatorConfig`;
    typed loosely, as the estimator imports this module) (its z-scoring is replaced on loading)."""
    gen = torch.Generator().manual_seed(0)
    dim = len(config.parameters)
    theta = torch.randn(16, dim, generator=gen)
    x = torch.randn(16, config.x_dim, generator=gen)
    members = [config.network.builder()(theta, x) for _ in range(config.network.ensemble)]
    return members[0] if len(members) == 1 else FlowEnsemble(members)


class FlowEnsemble(torch.nn.Module):
    """An equal-weight mixture of sbi density estimators trained with different seeds.

    Sampling draws ``n // K`` samples from each member (the first ``n % K`` members one
    more): a stratified draw from the mixture, with less spread between calls than picking
    each sample's member at random. A single-member estimator is stored as the bare sbi
    network (files written before ensembles existed load unchanged).

    Args:
        members: The trained estimators (each with ``sample(shape, condition=...)``).
    """

    def __init__(self, members: list[torch.nn.Module]) -> None:
        super().__init__()
        self.members = torch.nn.ModuleList(members)

    def sample(self, sample_shape: tuple[int, ...], condition: torch.Tensor) -> torch.Tensor:
        """``(n, B, D)`` samples for conditions ``(B, E)``, ``sample_shape = (n,)``."""
        (n,) = sample_shape
        k = len(self.members)
        counts = [n // k + (1 if i < n % k else 0) for i in range(k)]
        draws = [
            m.sample((c,), condition=condition)
            for m, c in zip(self.members, counts, strict=True)
            if c
        ]
        return torch.cat(draws, dim=0)
