"""The target a run is compared with: the phenomenon's own clip, or a user's video read,
conditioned (framed, its ζ estimated; :mod:`physinfer.conditioning`) and given its truth.

Reading and conditioning a user's video is the footage floor's work, so it sits here, above
the engine (:mod:`physinfer.pipeline` builds the roles; the loop takes the
:class:`~physinfer.roles.Target` this returns). ``refine``, ``diagnose`` and ``infer`` load
their targets here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from physinfer.conditioning import Conditioning, condition_target
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
        target = pipeline.phenomenon.default_target()
        zeta = pipeline.renderer.check_render_params({**target.render_params, **render_set})
        merged_truth = {**(target.truth or {}), **truth_values}
        return Target(target.clip, merged_truth or None, zeta, target.description)
    defaults = pipeline.renderer.default_render_params
    pipeline.renderer.check_render_params({**defaults, **render_set})  # a typo costs no framing
    clip = read_target_video(target_path, fps=fps)
    estimated: dict[str, Any] = {}
    conditions = None
    if conditioning is not None:
        clip, estimated, conditions = condition_target(
            pipeline.phenomenon, pipeline.embedder, clip, conditioning, render_set
        )
    zeta = pipeline.renderer.check_render_params({**defaults, **estimated, **render_set})
    return Target(clip, truth_values or None, zeta, str(target_path), conditions)
