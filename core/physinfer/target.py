"""The target a run is compared with: the phenomenon's own clip, or a user's video read (in
bounded memory, the part ``--start``/``--end`` chose: :func:`read_target_video`),
conditioned (framed, its ζ estimated; :mod:`physinfer.conditioning`) and given its truth.

Reading and conditioning a user's video is the footage floor's work, so it sits here, above
the engine (:mod:`physinfer.evaluation` builds the roles; the loop takes the
:class:`~physinfer.roles.Target` this returns). ``refine``, ``diagnose`` and ``infer`` load
their targets here, and :func:`start_from_video` reads where the target video itself points
(``refine`` and ``diagnose`` start their searches there).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.conditioning import Conditioning, condition_target
from physinfer.errors import UserInputError
from physinfer.evaluation import Pipeline, full_parameter_space
from physinfer.parameters import parse_float_assignments
from physinfer.roles import Target
from physinfer.types import Clip
from physinfer.video import read_video

_log = logging.getLogger(__name__)

#: A target video's frames are decoded at most this large (longer side, pixels): a 4K video
#: is downscaled while it is decoded, so its memory stays bounded (the embedders read 64-224 px).
TARGET_MAX_SIDE = 1920
#: At most this many bytes of decoded target frames: a longer video is decoded smaller or cut,
#: with a note or a warning.
TARGET_MAX_BYTES = 2 * 2**30
#: Smallest shorter side of a target (pixels): a 1 x 128 "video" is no picture of anything.
TARGET_MIN_SIDE = 32
#: A target longer than the budget holds at its size is decoded smaller, so that up to this
#: many seconds of it are read whole (the motion embedder compares up to 40 s) ...
TARGET_FIT_SECONDS = 60.0
#: ... but its longer side not below this (pixels; 640 × 360 at 60 fps: 52 s in 2 GiB).
TARGET_MIN_READ_SIDE = 640
#: A target whose frame-to-frame change stays below this (gray levels, 99.9th percentile over
#: pixels and frame pairs) shows nothing moving: codec noise reaches 1-2 levels.
STATIC_LEVELS = 3.0


def read_target_video(
    path: str | Path,
    fps: float | None = None,
    *,
    start_s: float = 0.0,
    end_s: float | None = None,
    max_side: int = TARGET_MAX_SIDE,
    max_bytes: int = TARGET_MAX_BYTES,
) -> Clip:
    """A user's target video, in bounded memory and checked to show something moving.

    Frames are downscaled to ``max_side`` while decoding; ``start_s`` and ``end_s`` (seconds
    of the video, ``--start``/``--end``) choose the part read, and reading stops after
    ``max_bytes`` of frames (a warning says how much was kept): the part of a long video is
    read without holding what comes before it (a 1080p phone video fills the budget in about
    11 s).

    Raises:
        UserInputError: as :func:`read_video`; a frame smaller than ``TARGET_MIN_SIDE`` on a
            side; a part past the video's end or of fewer than two frames; a video in which
            nothing moves.
    """
    probe = read_video(path, fps, max_frames=1, max_side=max_side)
    height, width = probe.frames.shape[1:3]
    if min(height, width) < TARGET_MIN_SIDE:
        raise UserInputError(
            f"{path}: its frames are {width}×{height} pixels; a target needs at least {TARGET_MIN_SIDE} on "
            "each side to show the phenomenon"
        )
    side, seconds = _side_to_fit(path, (height, width), probe.fps, (start_s, end_s), max_side, max_bytes)
    if side < max(height, width):
        probe = read_video(path, fps, max_frames=1, max_side=side)
        (old_h, old_w), (height, width), max_side = (height, width), probe.frames.shape[1:3], side
        _log.warning(
            "note: %s is read at %d×%d (not %d×%d) so that its %.1f s fit in memory",
            path, width, height, old_w, old_h, seconds,
        )  # fmt: skip
    budget = max(2, max_bytes // (height * width * 3))
    first = int(round(start_s * probe.fps))
    wanted = budget if end_s is None else min(budget, int(round(end_s * probe.fps)) - first)
    try:
        clip = read_video(path, fps, max_frames=max(wanted, 1), max_side=max_side, skip_frames=first)
    except UserInputError:
        if not first:
            raise
        raise UserInputError(f"--start {start_s:g} s is past the end of {path}{_length_words(path)}") from None
    if len(clip.frames) >= budget:
        kept = f"{budget / clip.fps:.1f} s from {start_s:g} s" if start_s else f"its first {budget / clip.fps:.1f} s"
        _log.warning(
            "warning: %s is longer than %d frames at %d×%d; only %s are used (--start and --end choose the part)",
            path, budget, width, height, kept,
        )  # fmt: skip
    elif end_s is not None and len(clip.frames) < wanted - 1:  # the video ended before --end
        raise UserInputError(
            f"--end {end_s:g} s is past the end of {path} ({(first + len(clip.frames)) / clip.fps:.2f} s long)"
        )
    if len(clip.frames) < 2:
        asked = f"--start {start_s:g}" + ("" if end_s is None else f" --end {end_s:g}")
        raise UserInputError(f"{asked} keeps one frame of {path}; keep at least two")
    check_motion(clip, path)
    return clip


def _side_to_fit(
    path: str | Path, size: tuple[int, int], rate: float, window: tuple[float, float | None], max_side: int,
    max_bytes: int,
) -> tuple[int, float | None]:  # fmt: skip
    """The longer side to decode a target at, and the seconds to be read: ``max_side`` when
    the part wanted (up to :data:`TARGET_FIT_SECONDS`) fits ``max_bytes`` at ``size``, else
    smaller, down to :data:`TARGET_MIN_READ_SIDE`. At 1920 px a 1080p phone video filled the
    budget in about 11 s and its pendulum was measured on that much of a 25-s swing; the
    embedders read 64-224 px."""
    seconds = _container_seconds(path)
    if seconds is None:
        return max_side, None
    start_s, end_s = window
    part = min(max(0.0, (seconds if end_s is None else min(seconds, end_s)) - start_s), TARGET_FIT_SECONDS)
    need = part * rate * size[0] * size[1] * 3
    longer = max(size)
    if need <= max_bytes:
        return max_side, part
    side = int(longer * math.sqrt(max_bytes / need)) // 2 * 2
    return max(min(TARGET_MIN_READ_SIDE, longer), side), part


def _container_seconds(path: str | Path) -> float | None:
    """How long the video lasts, as its container says (``None`` for a gif, a folder of
    images or a container that does not say)."""
    try:
        import av

        with av.open(str(path)) as container:
            return container.duration / 1e6 if container.duration else None
    except Exception:  # not a container PyAV opens
        return None


def _length_words(path: str | Path) -> str:
    """`` (N s long)`` as the container says, or nothing."""
    seconds = _container_seconds(path)
    return "" if seconds is None else f" ({seconds:.2f} s long)"


def check_motion(clip: Clip, path: str | Path) -> None:
    """Refuse a clip in which nothing changes beyond codec noise between frames."""
    if len(clip.frames) < 2:
        raise UserInputError(f"{path}: one frame is a picture, not a video; a target needs motion")
    pairs = np.linspace(0, len(clip.frames) - 2, min(len(clip.frames) - 1, 50)).astype(int)
    gray = lambda i: clip.frames[i, ::2, ::2].astype(np.float32).mean(axis=-1)  # noqa: E731
    change = max(float(np.quantile(np.abs(gray(i + 1) - gray(i)), 0.999)) for i in pairs)
    if change < STATIC_LEVELS:
        raise UserInputError(
            f"{path}: nothing moves in this video (frame-to-frame change at most {change:.1f} gray levels); "
            "a target must show the phenomenon in motion"
        )


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
    window = {"start_s": start_s, "end_s": round(start_s + clip.duration, 3), "frames": clip.n_frames}
    estimated: dict[str, Any] = {}
    conditions = None
    if conditioning is not None:
        clip, estimated, conditions = condition_target(
            pipeline.phenomenon, pipeline.embedder, clip, conditioning, render_set
        )
        if start_s or end_s is not None:  # the part of the video compared
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
