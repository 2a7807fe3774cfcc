"""Condition a user's video for comparison with simulations: frame it as the renderer frames
its subject (:mod:`physinfer.framing`) and read the camera's render parameters ζ from it
(:mod:`physinfer.render_estimate`).

``refine``, ``diagnose`` and ``infer`` run this on every ``--target`` video, so a phone clip
needs no separate ``physinfer prepare`` step. A square video is taken as framed already
(the renderer's output and ``prepare``'s are square; footage rarely is) and left as it is;
``--no-prepare`` leaves any video as it is and ``--roi`` gives the subject's region.

The ζ estimate fills only the render settings the user did not give with ``--render-set``,
and only those the estimator reads well: a component whose held-out error explains less than
:data:`MIN_EXPLAINED` of its spread is reported, not rendered with. For the flag that keeps the
framing (R² 0.89) and leaves the camera angles (R² 0.24-0.25) at the renderer's defaults: on
eight held-out targets the reported wind's median error was 0.32 m/s so conditioned, 0.45 with
the true camera handed over, 0.71 at the default camera, and 1.36 (four targets) with the
estimated angles as well (docs/benchmarks.md, real-video conditions).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.facing import face
from physinfer.framing import PrepareSettings, check_roi, default_framing, prepare_clip
from physinfer.render_estimate import estimate_render_params
from physinfer.static_background import freeze_static
from physinfer.tracking import check_one_mover
from physinfer.types import Clip
from physinfer.video import grid_luminance, resample

Box = tuple[float, float, float, float]

#: Share of a ζ component's spread its estimate must explain (1 − rms² / spread²) to be used.
MIN_EXPLAINED = 0.5
#: A still opening or ending at least this long is pointed out (with the ``--start`` or
#: ``--end`` that leaves it out): a swing's turning points stay still under 0.15 s on 20
#: simulated pendulums, the real ball on a string and the classroom film (2026-11-27).
STILL_NOTE_S = 0.5
#: A frame is still when its most-changed grid cell changes by less than this share of the
#: clip's 90th-percentile change.
STILL_SHARE = 0.2
#: Cells per side of the grid the still check reads.
STILL_GRID = 16

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Conditioning:
    """How a target video is conditioned.

    Attributes:
        prepare: ``None``: frame a video that is not square (the default); ``True``: frame
            it whatever its shape; ``False``: use it as it is.
        roi: ``(x, y, w, h)`` in the video's pixels: the region the subject moves in,
            instead of the one found.
        estimate_render: Estimate ζ from the (framed) clip where the phenomenon has an
            estimator, for the render settings not given.
        mirror: ``True``: mirror the video before anything else (it shows the subject the
            other way round from the renderer); ``False``: never; ``None``: where the
            phenomenon reads a side (``Phenomenon.facing``), as read (:mod:`physinfer.facing`).
        start_s: Seconds of the video left out at its start (``--start``): a phone clip
            often opens on a hand letting go, which no simulation makes.
        end_s: Second of the video at which the part used ends (``--end``; ``None``: its end).
    """

    prepare: bool | None = None
    roi: Box | None = None
    estimate_render: bool = True
    mirror: bool | None = None
    start_s: float = 0.0
    end_s: float | None = None

    def __post_init__(self) -> None:
        check_window(self.start_s, self.end_s)

    def wants_prepare(self, clip: Clip) -> bool:
        """Whether ``clip`` is framed: as asked, else when it is not square (or a roi is given)."""
        if self.prepare is not None:
            return self.prepare
        height, width = clip.size
        return self.roi is not None or height != width


def check_window(start_s: float, end_s: float | None) -> None:
    """Refuse a time window that is no window, before any video is read.

    Raises:
        UserInputError: a negative or non-finite ``--start``, or an ``--end`` not after it.
    """
    if not (math.isfinite(start_s) and start_s >= 0):
        raise UserInputError(f"--start {start_s:g}: give the seconds to leave out at the video's start (>= 0)")
    if end_s is not None and not (math.isfinite(end_s) and end_s > start_s):
        raise UserInputError(f"--end {end_s:g}: give a second of the video after --start ({start_s:g})")


def still_ends(clip: Clip) -> tuple[float, float]:
    """Seconds at the start and at the end of ``clip`` in which nothing moves: a hand holding
    a pendulum's bob before it lets go, a recording left running after the motion died. A
    simulation moves from its first frame to its last, so such seconds are compared with
    motion that never happened (a 0.7-m swing held still for 2 s came back 0.79 m, "does not
    reproduce"; with ``--start 2``, 0.70 m)."""
    cells = grid_luminance(clip.frames, STILL_GRID)
    if len(cells) < 3:
        return 0.0, 0.0
    change = np.abs(np.diff(cells, axis=0)).reshape(len(cells) - 1, -1).max(axis=1)
    still = change < STILL_SHARE * np.percentile(change, 90)
    if still.all():  # nothing moves at all: refused where the subject is looked for
        return 0.0, 0.0
    return int(np.argmin(still)) / clip.fps, int(np.argmin(still[::-1])) / clip.fps


def note_still_ends(clip: Clip, roi: Box | None, start_s: float = 0.0) -> dict[str, Any] | None:
    """Point out a still opening or ending of ``clip`` (in ``roi`` when given; read from
    ``start_s`` of its video) at least :data:`STILL_NOTE_S` long, with the ``--start``/``--end``
    that leaves it out; returns the record (the still seconds at each end and the ``hint``
    said) or ``None``."""
    lead, tail = still_ends(clip if roi is None else clip.cropped(roi))
    if max(lead, tail) < STILL_NOTE_S:
        return None
    end = start_s + clip.n_frames / clip.fps - tail
    parts = []
    if lead >= STILL_NOTE_S:
        parts.append(f"the first {lead:.1f} s of the video (--start {start_s + lead:.1f} leaves them out)")
    if tail >= STILL_NOTE_S:
        parts.append(f"the last {tail:.1f} s (--end {end:.1f} leaves them out)")
    hint = f"nothing moves in {' and in '.join(parts)}"
    _log.warning(
        "note: %s; a simulation moves from its first frame to its last, so still seconds are "
        "compared with motion that never happened",
        hint,
    )
    return {"start_s": round(lead, 3), "end_s": round(tail, 3), "hint": hint}


def parse_roi(text: str | None) -> Box | None:
    """``"x,y,w,h"`` → four floats (checked against the frame when the clip is framed).

    Raises:
        UserInputError: not four numbers.
    """
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 4:
        raise UserInputError(
            f"--roi {text!r}: give x,y,w,h as four numbers in the input's pixels, e.g. 100,50,300,300"
        )
    return values  # type: ignore[return-value]


def frame_clip(phenomenon: Any, embedder: Any, clip: Clip, roi: Box | None) -> tuple[Clip, dict[str, Any]]:
    """``clip`` framed, steadied and resampled as the embedder reads (:func:`physinfer.framing.prepare_clip`).

    Returns:
        The framed clip and what was found (``box``, ``square``, shake, ``warnings``, ...).
    """
    size = int(getattr(embedder, "size", 224)) if embedder is not None else 224
    fps = float(embedder.fps) if embedder is not None else None
    settings = PrepareSettings(size=size, fps=fps, roi=roi)
    prepared = prepare_clip(clip, framing=phenomenon.framing or default_framing, settings=settings)
    record = prepared.to_dict()
    if roi is not None and getattr(embedder, "compares_roi_only", False):
        return outside_frozen(prepared.clip, roi, record["square"]), {**record, "outside_roi": "frozen"}
    return prepared.clip, record


def check_one_subject(clip: Clip, roi: Box | None, fps: float) -> None:
    """Refuse a video in which more than one thing moves (in ``roi`` when given), before the
    framing picks one of them: a film whose animated dials flicker beside its pendulum was
    framed around the dials and measured 27 % short without a word.

    Raises:
        UserInputError: naming the moving regions and asking for ``--roi``.
    """
    if roi is not None:
        check_roi(roi, clip.frames.shape[1:3])  # before cropping: an empty region crashed the tracker
        clip = clip.cropped(roi)
    check_one_mover(resample(clip, min(fps, float(clip.fps))), roi=roi)


def outside_frozen(clip: Clip, roi: Box, square: Box) -> Clip:
    """``clip`` (framed from ``square``) with the pixels outside ``roi`` (both in the input
    video's pixels) held at their temporal median: nothing outside the given region moves.

    The framing's square extends past the region the user gave (a margin, a square shape),
    and whatever moves there (a flickering dial beside a pendulum) would be compared too.
    """
    frames = clip.frames.copy()
    height, width = frames.shape[1:3]
    x0, y0, side = square[0], square[1], square[2]
    left, right = (np.array([roi[0], roi[0] + roi[2]]) - x0) * width / side
    top, bottom = (np.array([roi[1], roi[1] + roi[3]]) - y0) * height / side
    inside = np.zeros((height, width), bool)
    inside[max(0, int(np.floor(top))) : int(np.ceil(bottom)), max(0, int(np.floor(left))) : int(np.ceil(right))] = True
    frames[:, ~inside] = np.median(frames[:, ~inside], axis=0).astype(frames.dtype)
    return Clip(frames, clip.fps)


def freeze_background(clip: Clip) -> tuple[Clip, dict[str, Any]]:
    """``clip`` with its static background frozen, as ``prepare`` does after framing.

    A square video taken as framed still went through a codec: its background flickers
    where a render's is constant, and per-pixel temporal spectra read that as motion. On a
    clean flag render written to mp4 and read back, the shipped posterior said "wind not
    identified" (90 % interval 0-10 m/s) against 2.6-5.0 m/s for the render itself; frozen,
    2.6-5.0 m/s again (docs/real-videos.md).
    """
    frozen, static = freeze_static(clip.frames)  # a Clip's frames are (T, H, W, C) uint8
    return Clip(frozen, clip.fps), static


def condition_target(
    phenomenon: Any,
    embedder: Any,
    clip: Clip,
    conditioning: Conditioning,
    render_set: Mapping[str, Any],
) -> tuple[Clip, dict[str, Any], dict[str, Any]]:
    """Frame ``clip`` if wanted and estimate the render settings ``render_set`` leaves open.

    Args:
        phenomenon: The :class:`~physinfer.roles.Phenomenon` (its framing rule and ζ estimator).
        embedder: The pipeline's embedder (the framing's size and fps; the ζ read-out), or
            ``None`` when the command embeds nothing.
        clip: The video as read (the part ``--start``/``--end`` chose: :func:`physinfer.target.load_target`).
        conditioning: What to do.
        render_set: The user's ``--render-set`` (never overridden).

    Returns:
        ``(clip, zeta, record)``: the clip to compare with, the estimated ζ values to
        render with (only keys not in ``render_set``), and what was done for ``result.json``
        (``still``: a still opening or ending pointed out; ``facing``: whether it was mirrored, :mod:`physinfer.facing`; ``prepared``: the framing found or why not; ``render_estimate``: the estimate with
        its uncertainty, ``used`` and ``not_used_weak`` (read too poorly to render with), or
        why none).
    """
    record: dict[str, Any] = {}
    still = note_still_ends(clip, conditioning.roi, conditioning.start_s)
    if still is not None:
        record["still"] = still
    if getattr(embedder, "compares_roi_only", False):  # a motion embedder tracks one subject
        # Before facing: the regions it names are then in the user's video's pixels, not mirrored.
        check_one_subject(clip, conditioning.roi, float(embedder.fps))
    clip, roi, facing = face(phenomenon, clip, conditioning.roi, conditioning.mirror)  # all below learnt one side
    if facing is not None:
        record["facing"] = facing.to_dict()
        conditioning = replace(conditioning, roi=roi)
    if conditioning.wants_prepare(clip):
        clip, record["prepared"] = frame_clip(phenomenon, embedder, clip, conditioning.roi)
    elif conditioning.prepare is False:
        record["prepared"] = {"skipped": "--no-prepare"}
    else:
        clip, static = freeze_background(clip)
        record["prepared"] = {"skipped": "the video is square: taken as framed already", "static": static}
    zeta: dict[str, Any] = {}
    if conditioning.estimate_render and embedder is not None:
        try:
            estimate = estimate_render_params(phenomenon, clip, embedder=embedder)
        except UserInputError as exc:  # e.g. an estimator of another embedder: ζ is auxiliary here
            estimate = {"values": {}, "note": f"not estimated: {exc}"}
        zeta = {k: v for k, v in estimate.get("values", {}).items() if k not in render_set}
        weak = sorted(k for k in zeta if estimate.get("explained", {}).get(k, 0.0) < MIN_EXPLAINED)
        zeta = {k: v for k, v in zeta.items() if k not in weak}
        record["render_estimate"] = {**estimate, "used": sorted(zeta), "not_used_weak": weak}
    return clip, zeta, record
