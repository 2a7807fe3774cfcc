"""Posteriors over θ: what a video determines, with calibrated credible intervals.

An amortized estimator q(θ | s(x)) is trained with sbi's neural posterior estimation on
the (θ, embedding) pairs of a generated dataset (:mod:`~physinfer.posterior.training`,
:mod:`~physinfer.posterior.features`), saved without pickles
(:mod:`~physinfer.posterior.estimator`), summarised per parameter with an identifiability
label (:mod:`~physinfer.posterior.summary`) and checked by simulation-based calibration on
held-out simulations (:mod:`~physinfer.posterior.calibration`). The workflows the CLI
calls are in :mod:`~physinfer.posterior.workflow`. See docs/posterior.md.

Importing this package is cheap; torch and sbi load with the submodules that need them.
"""

from physinfer.posterior.summary import (
    IDENTIFIED,
    WEAKLY_IDENTIFIED,
    correlations,
    identifiability_label,
    marginals,
)

__all__ = ["IDENTIFIED", "WEAKLY_IDENTIFIED", "correlations", "identifiability_label", "marginals"]
