"""Where each search of a diagnosis starts: the baseline's (and its self-consistency runs')
where the video points (:func:`baseline_video_start`), each effect's from the ridge probe's
``ridge.json`` (:func:`search_starts`).

A baseline searched from the centre missed on real footage: the ball on a string's ended at
0.217 m with its amplitude on the 60° bound (``refine``, which starts where the video points:
0.259 m; truth 0.2585), and the diagnosis named air drag for it.

:mod:`physinfer.discrepancy.ridge` writes the file in the main process before the effects
are refined; :func:`search_starts` reads it wherever an effect's stage runs
(:func:`physinfer.discrepancy.stages.effect_stage`), so a worker, the main process and a
resumed diagnosis start each search from the same points. Kept apart from the probe so that
the stages need none of its machinery.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.discrepancy.warmstart import warm_start_factory
from physinfer.errors import UserInputError
from physinfer.evaluation import Pipeline
from physinfer.registry import Registry
from physinfer.rundir import RUN_FILE
from physinfer.target import VideoStart, start_identity

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


def stage_optimizer(
    registry: Registry, optimizer: str, pipeline: Pipeline, start: Mapping[str, float] | None,
    extra_starts: Sequence[Mapping[str, float]], video_start: VideoStart | None,
) -> Callable[..., Any]:  # fmt: skip
    """The stage's optimizer factory: warm-started at ``start`` (then ``extra_starts``), else at
    the video's start in its box, else the registered optimizer as it is."""
    factory = registry.get("optimizers", optimizer).load()
    space = pipeline.simulator.parameter_space
    if start is not None:
        extra = [space.to_unit(space.complete(p)) for p in extra_starts]
        return warm_start_factory(factory, space.to_unit(space.complete(start)), extra=extra)
    if video_start is not None:
        return warm_start_factory(factory, video_start[0], video_start[1])
    return factory


def baseline_video_start(out: Path) -> VideoStart | None:
    """The baseline stage's start and box from the video (its ``run.json``), or ``None``.

    The self-consistency runs search as the baseline did: from its start, in its box (which
    holds the baseline's fit, where their targets are made). Their targets' own estimates
    would be another search: the pendulum's rendered 64-px self-target with the pivot out of
    view read a 11.5° swing as 2.4° (the visible string lifts the centroid as the bob sinks), a
    box without the truth, and a null scale a hundred times the real ball's gap.
    """
    path = out / "baseline" / RUN_FILE
    info = json.loads(path.read_text()) if path.is_file() else {}
    if "video_start" not in info:
        return None
    lo, hi = info["search_box"]
    return np.asarray(info["start_x"], float), (np.asarray(lo, float), np.asarray(hi, float)), info["video_start"]


def video_start_identity(video_start: VideoStart | None) -> dict[str, Any]:
    """``run.json``'s record of a start from the video (``refine``'s keys), or nothing."""
    return {} if video_start is None else {"video_start": video_start[2], **start_identity(video_start)}


def check_resumed_start(run_file: Path, video_start: VideoStart | None) -> None:
    """Refuse to continue a stage begun before searches started where the video points: its
    trials came from the centre, and continuing them would give that search's answer again (a
    pendulum diagnosis of the ball on a string made before 2026-11-27: 0.2165 m, air drag named).

    Raises:
        UserInputError: naming the folder and what to do.
    """
    if video_start is None or not run_file.is_file():
        return
    if "video_start" not in json.loads(run_file.read_text()):
        raise UserInputError(
            f"{run_file.parent} was refined from the centre by an earlier physinfer; diagnose now starts "
            f"where the video points, and every later stage starts from that fit. Give a new --out, or "
            f"delete {run_file.parent.parent} to diagnose again"
        )
