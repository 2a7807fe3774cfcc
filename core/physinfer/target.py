"""The target a run is compared with: the phenomenon's own clip, or a user's video read,
conditioned (framed, its ζ estimated; :mod:`physinfer.conditioning`) and given its truth.

Reading and conditioning a user's video is the footage floor's work, so it sits here, above
the engine (:mod:`physinfer.pipeline` builds the roles; the loop takes the
:class:`~physinfer.roles.Target` this returns). ``refine``, ``diagnose`` and ``infer`` load
their targets here, and :func:`start_from_video` reads where the target video itself points
(``refine`` and ``diagnose`` start their searches there).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.conditioning import Conditioning, condition_target
from physinfer.errors import UserInputError
from physinfer.evaluation import Pipeline
from physinfer.parameters import parse_float_assignments
from physinfer.pipeline import full_parameter_space
from physinfer.roles import Target
from physinfer.video import read_target_video


def load_target(
    pipeline: Pipeline,
    target_path: Path | None,
    *,
    fps: float | None,
    truth: Sequence[str],
    render_set: Mapping[str, Any],
    fixed: Sequence[str] = (),
    conditioning: Conditioning | None = None,
) -> Target:
    """The user's video (with ``--truth`` and ζ) or the phenomenon's embedded target.

    ``fixed``: ``--fix``'s items (their parameters may have a ``--truth`` too).
    ``conditioning``: how a user's video is framed and its ζ estimated
    (:mod:`physinfer.conditioning`); ``None``: used as it is, at the default ζ.
    """
    truth_values = parse_float_assignments(truth, "--truth")
    space = full_parameter_space(pipeline, fixed)
    for name in truth_values:
        space[name]  # unknown names fail with the list of known ones
    if target_path is None:
        if conditioning is not None and (conditioning.start_s or conditioning.end_s is not None):
            raise UserInputError("--start and --end choose a part of --target: give --target too")
        target = pipeline.phenomenon.default_target()
        zeta = pipeline.renderer.check_render_params({**target.render_params, **render_set})
        merged_truth = {**(target.truth or {}), **truth_values}
        return Target(target.clip, merged_truth or None, zeta, target.description)
    defaults = pipeline.renderer.default_render_params
    pipeline.renderer.check_render_params({**defaults, **render_set})  # a typo costs no framing
    start_s, end_s = (conditioning.start_s, conditioning.end_s) if conditioning is not None else (0.0, None)
    clip = read_target_video(target_path, fps=fps, start_s=start_s, end_s=end_s)
    estimated: dict[str, Any] = {}
    conditions = None
    if conditioning is not None:
        clip_read = clip
        clip, estimated, conditions = condition_target(
            pipeline.phenomenon, pipeline.embedder, clip, conditioning, render_set
        )
        if start_s or end_s is not None:  # the part of the video compared
            seconds = clip_read.n_frames / clip_read.fps
            window = {"start_s": start_s, "end_s": round(start_s + seconds, 3), "frames": clip_read.n_frames}
            conditions = {"window": window, **conditions}
    zeta = pipeline.renderer.check_render_params({**defaults, **estimated, **render_set})
    return Target(clip, truth_values or None, zeta, str(target_path), conditions)


#: Narrowest search box per parameter, normalised (a tenth of the range).
MIN_BOX = 0.2
#: ``(start_x, (lo, hi), record)``: a search's normalised start and box read from the video, and
#: the estimate (:func:`start_from_video`).
VideoStart = tuple[Any, Any, dict[str, Any]]


def start_from_video(pipeline: Pipeline, target: Target) -> VideoStart | None:
    """The search's start and box from what the target video tells directly
    (``Phenomenon.video_estimate``), or ``None`` when the phenomenon reads nothing.

    Returns:
        ``(start_x, (lo, hi), record)``: normalised start and box, and the estimate for
        ``run.json`` (``start``).
    """
    estimate_of = pipeline.phenomenon.video_estimate
    if estimate_of is None:
        return None
    space = pipeline.simulator.parameter_space
    estimate = {k: v for k, v in estimate_of(target.clip).items() if k in space.names}
    if not estimate:
        return None
    lo, hi = -np.ones(len(space.names)), np.ones(len(space.names))
    for i, spec in enumerate(space):
        if spec.name in estimate:
            low, high = sorted(np.clip(spec.to_unit(np.array(estimate[spec.name][1:])), -1.0, 1.0))
            # An estimate beyond the range leaves no box: search the edge it points to.
            lo[i], hi[i] = min(low, 1.0 - MIN_BOX), max(high, -1.0 + MIN_BOX)
    values = {spec.name: float(np.clip(estimate[spec.name][0], *spec.bounds)) for spec in space if spec.name in estimate}
    centre = np.clip(space.to_unit(space.complete(values)), lo, hi)  # the others start at their defaults
    record: dict[str, Any] = {"video_estimate": {k: [float(x) for x in v] for k, v in estimate.items()}}
    outside = {
        spec.name: ("below" if estimate[spec.name][0] < spec.bounds[0] else "above")
        for spec in space
        if spec.name in estimate and not spec.bounds[0] <= estimate[spec.name][0] <= spec.bounds[1]
    }
    if outside:  # the search stays in range; the answer must say the video points beyond it
        record["outside_range"] = {
            name: f"the video suggests {name} {side} {space[name].bounds[0 if side == 'below' else 1]:g} "
            f"{space[name].unit} ({estimate[name][0]:.3g} from the video alone)"
            for name, side in outside.items()
        }
    return centre, (lo, hi), record


def start_identity(video_start: VideoStart) -> dict[str, Any]:
    """``run.json``'s entries for a start from the video that a resume must match: the box and
    the start, normalised (the estimate itself is recorded beside them by the caller)."""
    start_x, (lo, hi), _ = video_start
    return {"search_box": [[float(v) for v in lo], [float(v) for v in hi]], "start_x": [float(v) for v in start_x]}
