"""Diagnose's self-consistency runs: the baseline refit to clips simulated from its own fit,
whose gaps give the null scale (the gap a correct model leaves); only the runs that can
change a decision are refined, on workers when there are any.

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
all the runs would give, and the runs (or controls) still unknown are skipped; where
they differ, the runs are refined — first stages first, then only the controls whose
``a_r`` could move ``S`` across a decision — until they agree.

On the flag's clean targets the decisions at the noise floor and at an infinite scale are
both "nothing": a self-consistency run could only confirm it, and the six self-consistency
stages (half of a default diagnosis' work) are skipped. ``diagnose --calibrate-all`` runs
every run as earlier versions did.

Until 2026-11-30 the method was ``discrepancy.needed_calibration`` and the stage
``discrepancy.calibration_stage`` (their old names are found there with a warning): the code
no longer calls these runs "calibration", the word of the posterior's simulation-based
calibration; diagnose's options (``--calibration-runs``, ...), its stage folders
(``calibration-<r>``) and the report's ``calibration`` key still do.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.discrepancy.decide import null_scale, self_consistency_gap
from physinfer.discrepancy.parallel import WorkerPool, run_on_workers, stage_jobs
from physinfer.discrepancy.progress import StageClock
from physinfer.discrepancy.records import Candidate, Verdict
from physinfer.discrepancy.stages import calibration_run
from physinfer.evaluation import Pipeline
from physinfer.progress import StageProgress
from physinfer.roles import Target

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings

#: Decisions at a null scale, as a comparable value (the gap test, each candidate's
#: significance, misspecified, the named effect).
Signature = Callable[[float], Hashable]


@dataclass
class SelfConsistencyRun:
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
    runs: Sequence[SelfConsistencyRun], floor: float, floor_q95: float, summary: str
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


def settled(runs: Sequence[SelfConsistencyRun], floor: float, floor_q95: float, summary: str, signature: Signature) -> bool:
    """Whether the runs still unknown can no longer change any decision."""
    lo, hi = scale_bounds(runs, floor, floor_q95, summary)
    return signature(lo) == signature(hi)


def next_to_refine(
    runs: Sequence[SelfConsistencyRun], floor: float, floor_q95: float, summary: str, signature: Signature
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


# The stage: refine the runs the decisions need.


Log = Callable[[str], None]
#: Every decision at a null scale: the candidates' records, the verdict, the named effect.
Judge = Callable[[float], tuple[list[Candidate], Verdict, str | None]]


def _signature(judged: Judge) -> Callable[[float], Any]:
    """Every decision at a null scale as one comparable value."""

    def signature(scale: float) -> Any:
        candidates, verdict, named = judged(scale)
        return (verdict.gap_test, tuple(c.significant for c in candidates), verdict.misspecified, named)

    return signature


def first_self_consistency_jobs(
    settings: DiagnoseSettings, effects: list[str], workers: int, floor: float
) -> list[tuple[int, bool]]:
    """The self-consistency jobs sent with the control and the effects: every run with its
    control under ``calibrate_all``; every run's first stage where the noise ``floor`` is 0;
    otherwise first stages only where one of ``workers`` would idle (the control and effect
    jobs not filling the last round), which costs no wall time.

    With a floor of 0 (a deterministic phenomenon) the null scale may be anything from 0 up
    before the runs are refined, and at 0 the gap test fires on any gap above 0 while at an
    unbounded scale nothing does: the decisions differ, and :func:`next_to_refine` asks for
    every run's first stage whatever the control and the effects find. Sent with them, the
    first stages fill the round's idle slots instead of making rounds of their own.
    """
    if not settings.calibrate:
        return []
    runs = range(settings.calibration_runs)
    if settings.calibrate_all:
        return [(r, True) for r in runs]
    if floor == 0:
        return [(r, False) for r in runs]
    idle = (-(1 + len(effects))) % workers if workers > 1 else 0
    return [(r, False) for r in runs[:idle]]


def with_idle_controls(todo: list[int], with_control: bool, workers: int) -> list[tuple[int, bool]]:
    """``(run, with_control)`` for a round of ``todo`` runs: where first stages alone would
    leave workers idle in their last round and take two rounds or more anyway, the idle
    slots go to some runs' controls (a run and its control take two rounds in one job), which
    the decisions may ask for next and which cost no wall time now."""
    rounds = -(-len(todo) // workers) if workers > 1 else 0
    spare = rounds * workers - len(todo) if not with_control and rounds >= 2 else 0
    return [(r, with_control or i < spare) for i, r in enumerate(todo)]


def one_round_of_controls(todo: list[int], runs: list[SelfConsistencyRun], workers: int) -> list[int]:
    """The controls of ``todo`` to refine in one round: no more than there are workers, those
    of the largest first-stage gaps first (a control can only lower its run's gap, and the
    largest bound the null scale's range from above), so that what one round finds can
    settle the rest before another round is spent on them."""
    ranked = sorted(todo, key=lambda r: (-(runs[r].gap_run if runs[r].gap_run is not None else math.inf), r))
    return sorted(ranked[: max(1, workers)])


def run_self_consistency(
    settings: DiagnoseSettings,
    base: Pipeline,
    baseline_best: Mapping[str, float],
    target: Target,
    gap0: Any,
    judged: Judge,
    job_args: Mapping[str, Any],
    effects: list[str],
    common: Mapping[str, Any],
    bars: StageProgress,
    clock: StageClock,
    say: Log,
    pool: WorkerPool,
) -> tuple[list[dict[str, Any]], float, tuple[float, float]]:
    """Refine the self-consistency runs the decisions need (all with ``calibrate_all``).

    Returns:
        Each run's record (``skipped`` says why a run or its control did not run), the null
        scale the decisions are made at (the lower end of its range: every decision is the
        same over the range), and the range.
    """
    if not settings.calibrate:
        scale = null_scale(gap0.floor, gap0.floor_q95, None)
        return [], scale, (scale, scale)
    summary = settings.rule.calibration_summary
    runs = [SelfConsistencyRun(r) for r in range(settings.calibration_runs)]

    def refine(indices: list[int], with_control: bool, on_workers: bool = True) -> None:
        plan = [(r, with_control) for r in indices]
        if on_workers and settings.calibration_control:
            plan = with_idle_controls(indices, with_control, pool.size)
        elsewhere = on_workers and pool.size > 1  # then the loop below reads the stages back
        if elsewhere:
            jobs = stage_jobs(settings, effects, **job_args, calibration=plan, control_and_effects=False)
            run_on_workers(pool, jobs, bars, clock, say, label="calibration_side_by_side")
        for r, control in plan:
            with clock.stage(f"calibration-{r}", add=on_workers and not elsewhere):  # else a read-back
                record = calibration_run(
                    r, base, baseline_best, target, steps=job_args["steps"], effect_steps=job_args["effect_steps"],
                    seeds=job_args["seeds"], with_control=control, **common,
                )  # fmt: skip
            runs[r].update(record, final=control or not settings.calibration_control)

    # Stages already on disk (a worker's idle round, an earlier invocation) are read back.
    if firsts := [r.run for r in runs if _finished(settings, f"calibration-{r.run}")]:
        refine(firsts, with_control=False, on_workers=False)
    if settings.calibration_control and (
        controls := [r for r in firsts if _finished(settings, f"calibration-{r}-control")]
    ):
        refine(controls, with_control=True, on_workers=False)
    if settings.calibrate_all and (todo := [r.run for r in runs if not r.done]):
        say(f"[4/6] self-consistency: refining the baseline against its own fit ({len(todo)} runs)")
        refine(todo, with_control=True)
    signature = _signature(judged)
    while True:
        todo, with_control = next_to_refine(runs, gap0.floor, gap0.floor_q95, summary, signature)
        if not todo:
            break
        if with_control:
            todo = one_round_of_controls(todo, runs, pool.size)
        lo, hi = scale_bounds(runs, gap0.floor, gap0.floor_q95, summary)
        what = "their controls" if with_control else f"the baseline against its own fit, {job_args['steps']} trials each"
        say(f"[4/6] self-consistency: the decisions differ between null scales {lo:.4g} and "
            f"{scale_text((hi, hi))}: refining run(s) {', '.join(map(str, todo))} ({what})")  # fmt: skip
        refine(todo, with_control=with_control)
    lo, hi = scale_bounds(runs, gap0.floor, gap0.floor_q95, summary)
    skipped = f"not needed: every decision is the same at any null scale from {lo:.4g} to {scale_text((hi, hi))}"
    if not all(r.done for r in runs):
        say(f"[4/6] self-consistency: {skipped}")
    return [r.to_dict(skipped) for r in runs], lo, (lo, hi)


def _finished(settings: DiagnoseSettings, stage: str) -> bool:
    """Whether a stage's refinement and gap are on disk (its gap is measured last)."""
    return (settings.out / stage / "gap.json").is_file()


def scale_text(scale_range: tuple[float, float]) -> str:
    lo, hi = scale_range
    if lo == hi:
        return f"{lo:.4g}"
    return f"{lo:.4g}–{hi:.4g}" if math.isfinite(hi) else f"≥ {lo:.4g}"


def limit_scale(scale_range: tuple[float, float], floor_q95: float) -> float:
    """The null scale the detection limits assume: the diagnosis' own where it is known;
    where the self-consistency runs were skipped, the upper end of its range, or (no upper
    end) the noise floor's 95th percentile, the stand-in without calibration."""
    lo, hi = scale_range
    if math.isfinite(hi):
        return hi
    return max(lo, floor_q95) if math.isfinite(floor_q95) else lo
