"""What an estimator's training inputs looked like, and how a target's input compares: the
guard against a video the estimator was never trained for; and the render settings ζ an
estimator may be told (the camera and light), scaled as its inputs and checked against the
training clips' ranges.

An estimator records, per input dimension, the training inputs' 0.1 and 99.9 % quantiles,
mean and spread (:func:`input_statistics`, in its file). At inference :func:`check_inputs`
holds the dimensions the training never varied at their training value and reports how
far the input lies outside the training range.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from physinfer.errors import UserInputError

#: A target whose input lies outside the training inputs in more than this share of its
#: dimensions is reported as extrapolated (its interval is not calibrated for it).
MAX_OUTSIDE_SHARE = 0.2
#: ... or when one input lies farther than this from the training mean, in training standard
#: deviations. In-model targets as given stay below 45 (2026-11-27: the largest over 200
#: held-out flag clips 38, flag targets after a photo background, noise and CRF 35 45, the
#: pendulum's 20, the hanging cloth's 12); videos of another phenomenon reach 192-1396 (a
#: pendulum filmed, fed to the flag's and the hanging cloth's estimators; a flag fed to the
#: hanging cloth's) in a few dimensions, under the share above, while the posterior median's
#: predictive check passed them.
MAX_WORST_SD = 100.0


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
    :data:`MAX_OUTSIDE_SHARE` of the dimensions outside, or one beyond :data:`MAX_WORST_SD`).
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
        "extrapolating": share > MAX_OUTSIDE_SHARE or worst > MAX_WORST_SD,
    }
    return x, record


def checked_rows(stats: dict[str, Any] | None, xs: np.ndarray) -> np.ndarray:
    """``(B, D)`` the inputs ``xs`` after :func:`check_inputs`, row by row (held-out sets)."""
    return np.stack([check_inputs(stats, row)[0] for row in np.asarray(xs)])


# ------------------------------------------------------------------ told render settings ζ
#
# An estimator may take some of the render settings ζ (camera, light) as inputs after the
# embedding: the user who knows the camera tells it (``infer --render-set``), and the posterior
# no longer has to average over the cameras the training clips were rendered with. Each told
# setting is mapped linearly from the training clips' range to [-1, 1].

#: A told value beyond the training clips' range by more than this share of it is outside.
RENDER_MARGIN = 0.02


def _number(value: Any) -> float | None:
    """``value`` as a finite float, or ``None`` when it is no number (a texture, a vector)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
        return None
    number = float(value)
    return number if np.isfinite(number) else None


def varied_render_settings(render_params: Sequence[Mapping[str, Any]]) -> list[str]:
    """The numeric render settings (one number each) that vary across ``render_params``,
    sorted: the camera and light a dataset randomised (``posterior train --told-camera``)."""
    names = set().union(*(zeta.keys() for zeta in render_params)) if render_params else set()
    varied = []
    for name in sorted(names):
        values = [_number(zeta.get(name)) for zeta in render_params]
        if all(v is not None for v in values) and max(values) > min(values):  # type: ignore[type-var]
            varied.append(name)
    return varied


def render_ranges(names: Sequence[str], render_params: Sequence[Mapping[str, Any]]) -> dict[str, list[float]]:
    """``{name: [low, high]}`` (sorted by name): the range of each render setting ``names``
    over the training clips' ζ ``render_params``.

    Raises:
        UserInputError: a name the clips' ζ lacks or holds as no number (the numeric ones
            that vary are listed), or one that never varied (telling it adds nothing).
    """
    usable = varied_render_settings(render_params)
    ranges: dict[str, list[float]] = {}
    for name in sorted(set(names)):
        values = [_number(zeta.get(name)) for zeta in render_params]
        if any(v is None for v in values) or name not in usable:
            why = "never varies in" if all(v is not None for v in values) else "is not a number in every ζ of"
            raise UserInputError(
                f"--render-input {name}: the setting {why} the training clips, so the estimator cannot "
                "learn from it",
                remedy=f"take one the dataset varies: {', '.join(usable) or 'none'} (or --told-camera for all)",
            )
        ranges[name] = [float(min(values)), float(max(values))]  # type: ignore[type-var]
    return ranges


def render_context(ranges: Mapping[str, Sequence[float]], told: Mapping[str, Any]) -> list[float]:
    """The told render settings as an estimator's extra inputs: each mapped linearly from its
    training range to ``[-1, 1]`` (sorted by name)."""
    context = []
    for name in sorted(ranges):
        low, high = (float(v) for v in ranges[name])
        value = _number(told[name])
        if value is None:
            raise UserInputError(f"--render-set {name}={told[name]!r}: give a finite number")
        context.append(2.0 * (value - low) / (high - low) - 1.0)
    return context


def render_outside(ranges: Mapping[str, Sequence[float]] | None, told: Mapping[str, Any]) -> list[str]:
    """The told render settings beyond the training range (by more than :data:`RENDER_MARGIN`
    of it): ``["fov_deg=60 (trained on 30.1..49.9)", ...]``, empty when all lie within."""
    outside = []
    for name in sorted(ranges or {}):
        low, high = (float(v) for v in ranges[name])  # type: ignore[index]
        value = _number(told.get(name))
        margin = RENDER_MARGIN * (high - low)
        if value is not None and not low - margin <= value <= high + margin:
            outside.append(f"{name}={value:g} (trained on {low:.3g}..{high:.3g})")
    return outside
