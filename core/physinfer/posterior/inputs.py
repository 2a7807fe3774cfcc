"""What an estimator's training inputs looked like, and how a target's input compares: the
guard against a video the estimator was never trained for.

An estimator records, per input dimension, the training inputs' 0.1 and 99.9 % quantiles,
mean and spread (:func:`input_statistics`, in its file). At inference :func:`check_inputs`
holds the dimensions the training never varied at their training value and reports how
far the input lies outside the training range.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: A target whose input lies outside the training inputs in more than this share of its
#: dimensions is reported as extrapolated (its interval is not calibrated for it).
MAX_OUTSIDE_SHARE = 0.2


def input_statistics(x: np.ndarray) -> dict[str, Any]:
    """The training inputs' range per dimension (:attr:`~physinfer.posterior.estimator.EstimatorConfig.inputs`).

    ``scale`` is the inputs' typical spread (root mean square of the per-dimension standard
    deviations): a dimension varying by less than a millionth of it is ``constant`` (cells of
    a still wall, frozen by the conditioning, give exact zeros in training and 1e-8 of
    floating-point residue in a target — nothing, but a flow standardising that dimension
    reads it as a million standard deviations).
    """
    x = np.asarray(x, dtype=np.float64)
    sd = x.std(axis=0)
    scale = float(max(np.sqrt(np.mean(sd**2)), 1e-12)) if x.size else 1.0
    constant = np.flatnonzero(sd <= 1e-6 * scale)

    def six(values: np.ndarray) -> list[float]:  # six significant digits: small and exact enough
        return [float(f"{v:.6g}") for v in values]

    return {
        "low": six(np.quantile(x, 0.001, axis=0)),
        "high": six(np.quantile(x, 0.999, axis=0)),
        "mean": six(x.mean(axis=0)),
        "std": six(sd),
        "scale": scale,
        "constant": constant.tolist(),
        # exact, not to six digits: the flow standardises a constant input by a spread of ~0,
        # so a value held a rounding away from its training value reads as thousands of SDs
        "constant_values": [float(np.float32(v)) for v in x[0, constant]] if len(x) else [],
    }


def check_inputs(stats: dict[str, Any] | None, x: np.ndarray) -> tuple[np.ndarray, dict[str, Any] | None]:
    """``(x, record)``: the estimator's input with the dimensions its training never
    varied held at their training value (a constant input standardised by sbi turns any
    codec noise there into a huge value, and the posterior onto a bound), and how far the
    input lies outside the training inputs (``None`` for an estimator without
    :attr:`~physinfer.posterior.estimator.EstimatorConfig.inputs`).

    ``record``: ``outside`` (dimensions beyond the training range by more than a tenth
    of it), ``dimensions``, ``worst_sd`` (the farthest, in training standard
    deviations), ``held`` (constant dimensions reset) and ``extrapolating`` (more than
    :data:`MAX_OUTSIDE_SHARE` of the dimensions outside).
    """
    x = np.asarray(x, dtype=np.float32).reshape(-1).copy()
    if not stats or len(stats.get("low", ())) != x.shape[0]:
        return x, None
    low, high = np.asarray(stats["low"]), np.asarray(stats["high"])
    mean, sd = np.asarray(stats["mean"]), np.asarray(stats["std"])
    tiny = 1e-3 * float(stats.get("scale", 1.0))  # below this, a difference is numerical residue
    constant = np.asarray(stats.get("constant", []), dtype=int)
    values = np.asarray(stats.get("constant_values", mean[constant]), dtype=np.float32)
    held = int(np.sum(np.abs(x[constant] - values) > tiny)) if constant.size else 0
    if constant.size:
        x[constant] = values
    margin = 0.1 * (high - low) + tiny
    outside = (x < low - margin) | (x > high + margin)
    worst = float(np.max(np.abs(x - mean) / np.maximum(sd, tiny))) if x.size else 0.0
    share = float(outside.mean()) if x.size else 0.0
    record = {
        "outside": int(outside.sum()),
        "dimensions": int(x.size),
        "worst_sd": round(worst, 2),
        "held": held,
        "extrapolating": share > MAX_OUTSIDE_SHARE,
    }
    return x, record


def checked_rows(stats: dict[str, Any] | None, xs: np.ndarray) -> np.ndarray:
    """``(B, D)`` the inputs ``xs`` after :func:`check_inputs`, row by row (held-out sets)."""
    return np.stack([check_inputs(stats, row)[0] for row in np.asarray(xs)])
