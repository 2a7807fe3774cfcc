"""Which way round a video shows its subject, and the mirror that turns it the renderer's way.

A renderer draws its subject one way round, and everything that compares with it learnt that
side: the flag flies to the right, its hoist on the left, in every render, every estimator's
training clip and the framing rule (which hangs its square from the moving region's top-left
corner). Filmed flags fly left as often as right, and a flag compared mirrored is read wrong
without a word: a 6 m/s render, mirrored, came back from ``infer`` as 8.6 m/s [90 %: 6.6–9.5]
and "reproduces"; a 0.8 m/s one as "not identified" (2026-11-27, docs/real-videos.md).

So a phenomenon whose subject has a side reads it (``Phenomenon.facing``, the plugin's
knowledge of its subject) and a target read as mirrored is mirrored back before anything
else looks at it — framing, ζ estimate, embedding. ``--mirror``/``--no-mirror`` say it
instead of the reading; a reading that cannot tell leaves the video as it is, and says so.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from physinfer.types import Clip

Box = tuple[float, float, float, float]
_log = logging.getLogger(__name__)

#: Seconds of a video the subject's side is read on (the start of a long phone clip suffices).
READ_SECONDS = 10.0


@dataclass(frozen=True)
class Facing:
    """What was decided about a target's side.

    Attributes:
        mirrored: The target was mirrored (left and right swapped) before it was compared.
        evidence: The phenomenon's reading (``> 0``: the renderer's way round; ``|e| < 1``:
            cannot tell), or ``None`` when the user said it (``--mirror``/``--no-mirror``).
        note: What the user is told (mirrored, or could not tell), or ``None``.
    """

    mirrored: bool
    evidence: float | None
    note: str | None = None

    @property
    def unclear(self) -> bool:
        """The reading could not tell which way round the video shows the subject."""
        return self.evidence is not None and abs(self.evidence) < 1.0

    def to_dict(self) -> dict[str, Any]:
        """``target_conditions``' ``facing`` entry."""
        by = "read from the video" if self.evidence is not None else ("--mirror" if self.mirrored else "--no-mirror")
        record: dict[str, Any] = {"mirrored": self.mirrored, "by": by}
        if self.evidence is not None:
            record["evidence"] = round(float(self.evidence), 3)
        if self.note:
            record["note"] = self.note
        return record


def mirror(clip: Clip) -> Clip:
    """``clip`` with left and right swapped."""
    return Clip(np.ascontiguousarray(clip.frames[:, :, ::-1]), clip.fps)


def mirror_roi(roi: Box, width: int) -> Box:
    """The region ``(x, y, w, h)`` of a ``width``-pixel frame as it lies in the mirrored frame."""
    x, y, w, h = roi
    return (width - x - w, y, w, h)


def read_facing(phenomenon: Any, clip: Clip, roi: Box | None) -> float:
    """The phenomenon's reading of ``clip``'s side, in ``roi`` when given, on its first
    :data:`READ_SECONDS`."""
    first = Clip(clip.frames[: max(2, int(round(READ_SECONDS * float(clip.fps))))], clip.fps)
    return float(phenomenon.facing(first if roi is None else first.cropped(roi)))


def face(phenomenon: Any, clip: Clip, roi: Box | None, asked: bool | None) -> tuple[Clip, Box | None, Facing | None]:
    """``clip`` turned the renderer's way round, ``roi`` turned with it, and what was decided
    (``None``: the subject has no side and nothing was asked).

    ``asked`` (the user's ``--mirror``/``--no-mirror``) decides when given; otherwise
    ``Phenomenon.facing`` reads the video, and a video read as mirrored (evidence at most -1)
    is mirrored. A reading that cannot tell leaves the video as it is.
    """
    if asked is None and phenomenon.facing is None:
        return clip, roi, None
    if asked is not None:
        decision = Facing(mirrored=asked, evidence=None)
    else:
        evidence = read_facing(phenomenon, clip, roi)
        decision = Facing(mirrored=evidence <= -1.0, evidence=evidence, note=_note(phenomenon.name, evidence))
        if decision.note:
            _log.warning("note: %s", decision.note)
    if not decision.mirrored:
        return clip, roi, decision
    return mirror(clip), None if roi is None else mirror_roi(roi, clip.size[1]), decision


def _note(name: str, evidence: float) -> str | None:
    if evidence <= -1.0:
        return (
            f"the video shows the {name} the other way round from its renderer (reading {evidence:+.2f}): "
            "mirrored before comparing; --no-mirror uses it as it is"
        )
    if evidence < 1.0:
        return (
            f"cannot tell which way round the video shows the {name} (reading {evidence:+.2f}): used as it "
            "is; give --mirror if it faces the other way from the renderer's"
        )
    return None
