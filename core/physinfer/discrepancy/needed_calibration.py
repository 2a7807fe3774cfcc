"""Which self-consistency runs a diagnosis needs: only those that can change a decision.

Every decision of a diagnosis is monotone in the null scale ``S`` (see
:mod:`physinfer.discrepancy.decide`): the gap test fires when the tested gap exceeds
``factor · S``, and a candidate beats the null scale when its improvement exceeds ``S``; the
rank test and the parameter penalty do not depend on ``S``. So a larger ``S`` never turns a
"no" into a "yes", and when the decisions at two scales agree they agree at every scale in
between.

``S = max(noise floor, summary(g_1 … g_R))`` with ``summary`` the maximum (or median) of the
``R`` self-consistency gaps, and each run's gap ``g_r = min(a_r, b_r)`` (its own stage's gap
``a_r`` and its control's ``b_r``). Before run ``r`` is refined ``g_r`` may be anything in
``[0, ∞)``; after its first stage it lies in ``[0, a_r]``. That bounds ``S`` to
``[S_lo, S_hi]``. Where the decisions at ``S_lo`` and ``S_hi`` agree, they are the decisions
the full calibration would give, and the runs (or controls) still unknown are skipped; where
they differ, the runs are refined — first stages first, then only the controls whose
``a_r`` could move ``S`` across a decision — until they agree.

On the flag's clean targets the decisions at the noise floor and at an infinite scale are
both "nothing": a self-consistency run could only confirm it, and the six calibration
stages (half of a default diagnosis' work) are skipped. ``diagnose --calibrate-all`` runs
every run as earlier versions did.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from physinfer.discrepancy.decide import null_scale, self_consistency_gap

#: Decisions at a null scale, as a comparable value (the gap test, each candidate's
#: significance, misspecified, the named effect).
Signature = Callable[[float], Hashable]


@dataclass
class CalibrationRun:
    """What is known of one self-consistency run.

    Attributes:
        run: Its index ``r``.
        gap_run: ``a_r``, its own stage's gap (``None``: not refined yet).
        gap_control: ``b_r``, its control's gap (``None``: not refined, or no control).
        done: Its gap is final (its stage and, with controls, its control have run).
        record: The record :func:`physinfer.discrepancy.stages.calibration_run` returned last.
    """

    run: int
    gap_run: float | None = None
    gap_control: float | None = None
    done: bool = False
    record: dict[str, Any] | None = None

    @property
    def gap(self) -> float | None:
        """``g_r`` once final."""
        if not self.done or self.gap_run is None:
            return None
        return self.gap_run if self.gap_control is None else min(self.gap_run, self.gap_control)

    def bounds(self) -> tuple[float, float]:
        """``g_r``'s known range: exact when done, ``[0, a_r]`` after the first stage."""
        if self.done and self.gap is not None:
            return self.gap, self.gap
        if self.gap_run is not None and math.isfinite(self.gap_run):
            return 0.0, self.gap_run
        return 0.0, math.inf

    def update(self, record: dict[str, Any], *, final: bool) -> None:
        """Take a calibration record (``gap_run``, ``gap_control``)."""
        self.record = dict(record)
        self.gap_run = record.get("gap_run")
        self.gap_control = record.get("gap_control")
        self.done = final

    def to_dict(self, skipped: str | None) -> dict[str, Any]:
        """The report's record of this run (``skipped``: why it or its control did not run)."""
        base = dict(self.record or {"run": self.run})
        base.update({"run": self.run, "gap": self.gap, "gap_run": self.gap_run, "gap_control": self.gap_control})
        if not self.done:
            base["skipped"] = skipped
        return base


def scale_bounds(
    runs: Sequence[CalibrationRun], floor: float, floor_q95: float, summary: str
) -> tuple[float, float]:
    """``[S_lo, S_hi]``: the null scale's range given what is known of the runs."""
    if all(r.done for r in runs):
        scale = null_scale(floor, floor_q95, self_consistency_gap([g for r in runs if (g := r.gap) is not None], summary))
        return scale, scale
    # A run whose gap came out NaN is left out, as self_consistency_gap leaves it out.
    bounds = [r.bounds() for r in runs if not (r.done and r.gap is not None and not math.isfinite(r.gap))]
    if not bounds:
        return null_scale(floor, floor_q95, None), null_scale(floor, floor_q95, None)
    pick = max if summary == "max" else (lambda v: float(np.median(v)))
    return max(floor, pick([lo for lo, _ in bounds])), max(floor, pick([hi for _, hi in bounds]))


def settled(runs: Sequence[CalibrationRun], floor: float, floor_q95: float, summary: str, signature: Signature) -> bool:
    """Whether the runs still unknown can no longer change any decision."""
    lo, hi = scale_bounds(runs, floor, floor_q95, summary)
    return signature(lo) == signature(hi)


def next_to_refine(
    runs: Sequence[CalibrationRun], floor: float, floor_q95: float, summary: str, signature: Signature
) -> tuple[list[int], bool]:
    """The runs to refine next and whether with their controls.

    First the runs not yet refined at all (each may raise ``S`` without bound); then, for the
    maximum, only the controls of runs whose first-stage gap alone could carry ``S`` across
    a decision (for the median: every unfinished run's).

    Returns:
        ``(run indices, with_control)``; no indices when settled.
    """
    if settled(runs, floor, floor_q95, summary, signature):
        return [], False
    fresh = [r.run for r in runs if r.gap_run is None and not r.done]
    if fresh:
        return fresh, False
    lo, _ = scale_bounds(runs, floor, floor_q95, summary)
    unfinished = [r for r in runs if not r.done]
    if summary != "max":
        return [r.run for r in unfinished], True
    decision_at_lo = signature(lo)
    return [r.run for r in unfinished if signature(max(lo, r.bounds()[1])) != decision_at_lo], True


def null_scale_words(report: Mapping[str, Any]) -> str:
    """``null scale 31.2``, or its range where self-consistency runs were skipped:
    ``null scale 20.1 (any of 20.1–∞ gives these decisions)``; where the scale is the noise
    floor at the baseline fit and the report's ``noise_floor`` (the tested fit's) differs, it
    says so, or a reader could not tell where the number came from."""
    scale = report.get("null_scale")
    lo, hi = report.get("null_scale_range") or (scale, scale)
    notes = []
    baseline_floor = (report.get("baseline") or {}).get("floor")
    if _same(scale, baseline_floor) and not _same(baseline_floor, report.get("noise_floor")):
        notes.append("the noise floor at the baseline fit")
    if lo is not None and hi != lo:
        notes.append(f"any of {_g(lo)}–{'∞' if hi is None else _g(hi)} gives these decisions")
    return f"null scale {_g(scale)}" + (f" ({'; '.join(notes)})" if notes else "")


def _same(a: Any, b: Any) -> bool:
    return a is not None and b is not None and math.isclose(float(a), float(b), rel_tol=1e-9)


def limits_scale_note(report: Mapping[str, Any]) -> str | None:
    """What the detection limits assume when the null scale is only known as a range (the
    upper end: a limit never lower than with every run refined), or ``None``."""
    limits = report.get("limits") or {}
    if limits.get("null_scale_exact", True):
        return None
    return (
        f"the detection limits assume a null scale of {_g(limits.get('null_scale'))}, the upper end of what "
        "the decisions allow (self-consistency runs they did not need were skipped), so they may be higher "
        "than with every run refined (in brackets where its lower end reads otherwise; the limits with every "
        "run refined lie between); --calibrate-all gives them at the diagnosis' own null scale"
    )


def _g(value: Any) -> str:
    return "–" if value is None else f"{float(value):.4g}"
