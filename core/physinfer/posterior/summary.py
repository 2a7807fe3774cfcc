"""What posterior samples say about each parameter: median, credible intervals,
contraction against the prior, an identifiability label, and the strongest correlations.

Contraction is measured in the normalised coordinates, where the prior is uniform on
``[-1, 1]`` (variance 1/3): ``contraction = 1 - var_posterior / var_prior``. 0 means the
video taught nothing about the parameter, 1 that it pinned it down. Labels:

- ``identified``: contraction ≥ 0.75 (the posterior's spread is at most half the prior's);
- ``weakly identified``: 0.3 ≤ contraction < 0.75;
- ``not identified``: contraction < 0.3 (the spread is ≥ 84 % of the prior's).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from physinfer.parameters import ParameterSpace

IDENTIFIED = 0.75
WEAKLY_IDENTIFIED = 0.3
PRIOR_VARIANCE = 1.0 / 3.0  # uniform on [-1, 1]
#: Correlations weaker than this are not reported.
MIN_CORRELATION = 0.3


def identifiability_label(contraction: float) -> str:
    """``identified``, ``weakly identified`` or ``not identified`` (thresholds above)."""
    if contraction >= IDENTIFIED:
        return "identified"
    if contraction >= WEAKLY_IDENTIFIED:
        return "weakly identified"
    return "not identified"


def marginals(samples_unit: np.ndarray, space: ParameterSpace) -> dict[str, dict[str, Any]]:
    """Per parameter: median, 50 % and 90 % central intervals (physical units), contraction
    and label.

    Args:
        samples_unit: ``(S, D)`` posterior samples in normalised coordinates.
        space: The parameter space (column order).

    Returns:
        ``{name: {"median", "ci50", "ci90", "contraction", "label", "unit"}}``.
    """
    out: dict[str, dict[str, Any]] = {}
    for i, spec in enumerate(space):
        u = samples_unit[:, i]
        q = np.quantile(u, [0.5, 0.25, 0.75, 0.05, 0.95])
        phys = [float(v) for v in spec.from_unit(np.clip(q, -1.0, 1.0))]
        variance = float(np.var(u))
        contraction = float(1.0 - variance / PRIOR_VARIANCE)
        out[spec.name] = {
            "median": phys[0],
            "ci50": [phys[1], phys[2]],
            "ci90": [phys[3], phys[4]],
            "contraction": contraction,
            "label": identifiability_label(contraction),
            "unit": spec.unit,
        }
    return out


def correlations(
    samples_unit: np.ndarray, names: Sequence[str], *, top: int = 5
) -> list[dict[str, Any]]:
    """The strongest pairwise posterior correlations (|r| ≥ :data:`MIN_CORRELATION`).

    A strong negative correlation between two parameters is a ridge: the video fixes a
    combination of them (the flag's wind speed and area weight), not each alone.

    Returns:
        Up to ``top`` dicts ``{"a", "b", "r"}``, strongest first.
    """
    d = samples_unit.shape[1]
    if d < 2:
        return []
    r = np.corrcoef(samples_unit, rowvar=False)
    pairs = [
        {"a": names[i], "b": names[j], "r": float(r[i, j])}
        for i in range(d)
        for j in range(i + 1, d)
        if abs(r[i, j]) >= MIN_CORRELATION
    ]
    return sorted(pairs, key=lambda p: -abs(p["r"]))[:top]


def format_marginal(name: str, m: dict[str, Any]) -> str:
    """One printed line: ``wind_speed = 5.9 m/s  [90 %: 5.4 – 6.4]  identified``."""
    unit = f" {m['unit']}" if m.get("unit") else ""
    lo, hi = m["ci90"]
    if m["label"] == "not identified":
        return f"  {name}: not identified (90 %: {lo:.4g} – {hi:.4g}{unit}, the video barely narrows its range)"
    return f"  {name} = {m['median']:.4g}{unit}   [90 %: {lo:.4g} – {hi:.4g}]   {m['label']}"
