"""The self-consistency stage of a diagnosis: refine the runs the decisions need, on workers
when there are any (the method is :mod:`physinfer.discrepancy.needed_calibration`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from physinfer.discrepancy.decide import null_scale
from physinfer.discrepancy.needed_calibration import CalibrationRun, next_to_refine, scale_bounds
from physinfer.discrepancy.parallel import WorkerPool, run_on_workers, stage_jobs
from physinfer.discrepancy.progress import StageClock
from physinfer.discrepancy.records import Candidate, Verdict
from physinfer.discrepancy.stages import calibration_run
from physinfer.evaluation import Pipeline
from physinfer.progress import StageProgress
from physinfer.roles import Target

if TYPE_CHECKING:
    from physinfer.discrepancy.settings import DiagnoseSettings

Log = Callable[[str], None]
#: Every decision at a null scale: the candidates' records, the verdict, the named effect.
Judge = Callable[[float], tuple[list[Candidate], Verdict, str | None]]


def _signature(judged: Judge) -> Callable[[float], Any]:
    """Every decision at a null scale as one comparable value."""

    def signature(scale: float) -> Any:
        candidates, verdict, named = judged(scale)
        return (verdict.gap_test, tuple(c.significant for c in candidates), verdict.misspecified, named)

    return signature


def first_calibration_jobs(
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


def one_round_of_controls(todo: list[int], runs: list[CalibrationRun], workers: int) -> list[int]:
    """The controls of ``todo`` to refine in one round: no more than there are workers, those
    of the largest first-stage gaps first (a control can only lower its run's gap, and the
    largest bound the null scale's range from above), so that what one round finds can
    settle the rest before another round is spent on them."""
    ranked = sorted(todo, key=lambda r: (-(runs[r].gap_run if runs[r].gap_run is not None else math.inf), r))
    return sorted(ranked[: max(1, workers)])


def calibrate(
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
    runs = [CalibrationRun(r) for r in range(settings.calibration_runs)]

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
