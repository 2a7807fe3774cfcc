"""Where each effect's search starts: read from the ridge probe's ``ridge.json``.

:mod:`physinfer.discrepancy.ridge` writes the file in the main process before the effects
are refined; :func:`search_starts` reads it wherever an effect's stage runs
(:func:`physinfer.discrepancy.stages.effect_stage`), so a worker, the main process and a
resumed diagnosis start each search from the same points. Kept apart from the probe so that
the stages need none of its machinery.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np

RIDGE_FILE = "ridge.json"
#: Starts handed to a search besides its first trial, at most.
MAX_EXTRA = 4


def search_starts(
    out: Path, name: str, baseline_best: Mapping[str, float], off_start: Mapping[str, float], steps: int
) -> tuple[dict[str, float], list[dict[str, float]]] | None:
    """The warm start and the extra first trials of effect ``name``'s search from ``ridge.json``
    (``None`` when there is none for this θ̂: the search starts at ``off_start`` alone).

    The search starts at the closest of θ̂ with the effect off and the ridge points; the
    others follow as its first trials (at most :data:`MAX_EXTRA`, and a quarter of the
    budget), the closest first, θ̂ among them when a ridge point led."""
    path = out / RIDGE_FILE
    if not path.is_file():
        return None
    stored = json.loads(path.read_text())
    theta = stored.get("key", {}).get("theta", {})
    if not theta or any(abs(float(baseline_best.get(k, np.nan)) - v) > 1e-12 for k, v in theta.items()):
        return None
    record = stored.get("effects", {}).get(name)
    if not record:
        return None
    candidates = [(float(p["distance"]), dict(p["params"])) for p in record["starts"]]
    candidates.append((float(record["baseline_distance"]), dict(off_start)))
    candidates.sort(key=lambda c: c[0])  # stable: a ridge point equal to θ̂ stays first
    n_extra = min(MAX_EXTRA, max(0, steps // 4), len(candidates) - 1)
    return candidates[0][1], [p for _, p in candidates[1 : 1 + n_extra]]
