"""The check ``posterior train`` makes before it writes an estimator: on held-out clips, sent
down the path a user's video takes, do the 90 % intervals hold the truth, and are the
posteriors more than a point?

Pure numpy over samples. An estimator that fails is not written (``posterior train`` says
what to change), because its intervals would be confident and wrong on every video: the
spring estimator trained on stored renders and asked about mp4 targets put all its mass on a
bound, while the calibration on its own training format said "calibrated".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: Held-out clips checked at most (each gets :data:`SAMPLES` posterior samples).
MAX_CLIPS = 200
SAMPLES = 500
#: The 90 % interval must hold the truth at least this often, less three binomial standard
#: errors (at 50 clips: 0.77; at 200: 0.84).
LEVEL = 0.9
#: A posterior whose 90 % interval is narrower than this share of the prior's range is a point.
MIN_WIDTH = 0.005


def held_out_check(
    theta_unit: np.ndarray, samples_unit: np.ndarray, names: Sequence[str], nuisance: Sequence[str] = ()
) -> dict[str, Any]:
    """Coverage and widths of the 90 % intervals on held-out clips.

    Args:
        theta_unit: ``(N, D)`` the clips' true θ, normalised to ``[-1, 1]``.
        samples_unit: ``(S, N, D)`` posterior samples for each clip.
        names: ``(D,)`` parameter names.
        nuisance: Names of nuisance parameters (a pendulum's phase): reported, never
            measured, so their failures are ``nuisance_problems``, not ``problems``.

    Returns:
        ``{clips, parameters: {name: {coverage90, median_width90 (share of the range),
        points (share of posteriors narrower than MIN_WIDTH)}}, problems: [str],
        nuisance_problems: [str]}``.
    """
    lo = np.quantile(samples_unit, 0.05, axis=0)
    hi = np.quantile(samples_unit, 0.95, axis=0)
    covered = (theta_unit >= lo) & (theta_unit <= hi)
    width = (hi - lo) / 2.0  # share of the normalised range [-1, 1]
    n = int(theta_unit.shape[0])
    need = LEVEL - 3.0 * np.sqrt(LEVEL * (1 - LEVEL) / max(n, 1))
    parameters: dict[str, Any] = {}
    problems: list[str] = []
    nuisance_problems: list[str] = []
    for i, name in enumerate(names):
        found = nuisance_problems if name in nuisance else problems
        row = {
            "coverage90": round(float(covered[:, i].mean()), 3),
            "median_width90": round(float(np.median(width[:, i])), 4),
            "points": round(float(np.mean(width[:, i] < MIN_WIDTH)), 3),
        }
        parameters[name] = row
        if row["points"] > 0.5:
            found.append(
                f"{name}: the posterior collapsed to a point on {row['points']:.0%} of the held-out clips"
            )
        elif row["coverage90"] < need:
            found.append(
                f"{name}: its 90 % interval held the truth on {row['coverage90']:.0%} of {n} held-out clips "
                f"(at least {need:.0%} expected)"
            )
    return {
        "clips": n,
        "required_coverage90": round(float(need), 3),
        "parameters": parameters,
        "problems": problems,
        "nuisance_problems": nuisance_problems,
    }
