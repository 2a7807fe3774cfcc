"""Posterior workflows over the roles: train an estimator on a dataset, infer the
posterior of one video, and check calibration on held-out simulations.

Each returns a result object with the numbers, the files it wrote and ``to_dict()`` (the
JSON the CLI prints). Progress goes to an injected ``progress(stage, done, total)``
callback; nothing here prints.

One module per workflow: :mod:`~physinfer.posterior.train_workflow` (``posterior train``),
:mod:`~physinfer.posterior.infer_workflow` (``infer``, and the posterior a refinement starts
from), :mod:`~physinfer.posterior.calibrate_workflow` (``evaluate calibration``); what they
load and check (estimator, embedder, target embedding, dataset) is in
:mod:`~physinfer.posterior.loading`. Their names are re-exported here.
"""

from __future__ import annotations

from physinfer.posterior.calibrate_workflow import CalibrationReport, evaluate_calibration
from physinfer.posterior.infer_workflow import (
    PosteriorReport,
    infer,
    posterior_for_refinement,
    posterior_of_clip,
    summary_lines,
    trust_lines,
    write_report,
)
from physinfer.posterior.loading import (
    ProgressFn,
    build_embedder,
    check_dataset,
    embed_target,
    estimator_embedder,
    load_estimator,
)
from physinfer.posterior.train_workflow import TrainResult, train_posterior

__all__ = [
    "CalibrationReport",
    "PosteriorReport",
    "ProgressFn",
    "TrainResult",
    "build_embedder",
    "check_dataset",
    "embed_target",
    "estimator_embedder",
    "evaluate_calibration",
    "infer",
    "load_estimator",
    "posterior_for_refinement",
    "posterior_of_clip",
    "summary_lines",
    "train_posterior",
    "trust_lines",
    "write_report",
]
