"""``physinfer diagnose``: name the effect a refined model is missing, or say none is.

Registered as a command by physinfer's built-in plugin; a thin shell over :func:`physinfer.api.diagnose`, which runs
:func:`physinfer.discrepancy.workflow.run_diagnosis`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

import physinfer
from physinfer.cli.app import (
    DiagnoseBatchSizeOpt,
    DurationOpt,
    EmbedderFramesOpt,
    EndOpt,
    FixOpt,
    JsonOpt,
    MirrorOpt,
    NoPrepareOpt,
    PluginOpt,
    RoiOpt,
    SceneSetOpt,
    SeedOpt,
    SelectSeedsOpt,
    SelectTopOpt,
    StartOpt,
    emit_json,
    err_console,
    handle_errors,
    options_from_cli,
)
from physinfer.cli.options import (
    EmbedderOpt,
    FpsOpt,
    OptimizerOpt,
    RenderSetOpt,
    TorchDeviceOpt,
    WeightsOpt,
)
from physinfer.discrepancy.limit_text import screened_line
from physinfer.discrepancy.self_consistency import limits_scale_note, null_scale_words

# The options only ``diagnose`` has, declared here so its signature reads as a list of settings.
_TargetOpt = Annotated[
    Path | None, typer.Option("--target", help="Video to diagnose; default: the plugin's embedded target.")
]
_TruthOpt = Annotated[list[str], typer.Option("--truth", help="Known true value NAME=VALUE (reported only).")]
_StepsOpt = Annotated[int | None, typer.Option("--steps", help="Baseline trials (default: the plugin's).")]
_EffectStepsOpt = Annotated[
    int | None, typer.Option("--effect-steps", help="Trials per augmented model and for the control (default: --steps).")
]
_EffectOpt = Annotated[
    list[str], typer.Option("--effect", help="Only try these effects (repeatable; default: all of the plugin's).")
]
_FloorSamplesOpt = Annotated[
    int, typer.Option("--floor-samples", help="Re-simulations per gap measurement (>= 4).")
]
_CalibrateOpt = Annotated[
    bool,
    typer.Option("--calibrate/--no-calibrate", help="Self-consistency refinements to calibrate the null scale."),
]
_CalibrationRunsOpt = Annotated[
    int,
    typer.Option(
        "--calibration-runs",
        help="Self-consistency refinements (>= 1, each --steps trials); --calibration-summary makes their "
        "gaps one (default: the largest).",
    ),
]
_CalibrateAllOpt = Annotated[
    bool,
    typer.Option(
        "--calibrate-all",
        help="Refine every self-consistency run and control. By default only those that could change a "
        "decision are refined (the same decisions; the null scale may then be known only as a range).",
    ),
]
_CalibrationControlOpt = Annotated[
    bool,
    typer.Option(
        "--calibration-control/--no-calibration-control",
        help="Give each self-consistency run its own control (--effect-steps more trials), as the baseline has.",
    ),
]
_CalibrationSummaryOpt = Annotated[
    str,
    typer.Option(
        "--calibration-summary",
        help="max or median of the self-consistency runs' gaps: the null scale's optimizer part.",
    ),
]
_ThresholdOpt = Annotated[
    float,
    typer.Option("--threshold", help="The gap test finds the model misspecified above this many null scales."),
]
_RequireGapTestOpt = Annotated[
    bool,
    typer.Option(
        "--require-gap-test",
        help="Name an effect only when the gap test alone finds the model misspecified (by default an "
        "effect's significant improvement is evidence enough).",
    ),
]
_OutOpt = Annotated[Path | None, typer.Option("--out", help="Diagnosis directory (re-run to continue it).")]
_NoVideoOpt = Annotated[bool, typer.Option("--no-video", help="Skip the side-by-side video.")]
_LimitsOpt = Annotated[
    bool,
    typer.Option(
        "--limits/--no-limits",
        help="Estimate each effect's detection limit (the weakest strength this clip could name) from a "
        "ladder of simulations at the best baseline fit.",
    ),
]
_RevealOpt = Annotated[
    bool,
    typer.Option(
        "--reveal",
        help="Also measure whether another camera view or a twice longer clip would lower the limits "
        "(chaotic phenomena; re-renders and re-simulates the ladder).",
    ),
]
_CheckLimitsOpt = Annotated[
    bool,
    typer.Option(
        "--check-limits",
        help="Check each effect not named: run this diagnosis' own stages on a target made with it at its "
        "stated limit (doubled until named, to the end of its range, then the last bracket halved), so the limit is "
        "what this search names. Costly.",
    ),
]
_ScreenOpt = Annotated[
    bool,
    typer.Option(
        "--screen/--no-screen",
        help="Before refining the effects, leave out those whose signature at the baseline's fit no fit "
        "could name (a ladder of simulations; chaotic phenomena only). --no-screen refines every effect.",
    ),
]
_RidgeStartsOpt = Annotated[
    bool,
    typer.Option(
        "--ridge-starts/--no-ridge-starts",
        help="Start each effect's search also where the video points along the ridge it shares with the "
        "base parameters (drag vs restitution), not only at the baseline's fit; for a deterministic "
        "phenomenon also polish every search's start (controls and effects) towards its target.",
    ),
]
_WorkersOpt = Annotated[
    int | None,
    typer.Option(
        "--workers",
        help="Run the stages after the baseline side by side in K local worker processes (default: one "
        "per CPU; 0 or 1: in this process). The decisions do not depend on it.",
    ),
]
_SchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="Run those stages on a Dask cluster (tcp://host:8786); its workers need physinfer and the "
        "plugins installed and must see --out.",
    ),
]


@handle_errors(kept="finished stages are saved: run the same command again to continue")
def diagnose_cmd(
    plugin: PluginOpt,
    target: _TargetOpt = None,
    fps: FpsOpt = None,
    truth: _TruthOpt = [],  # noqa: B006
    steps: _StepsOpt = None,
    effect_steps: _EffectStepsOpt = None,
    effect: _EffectOpt = [],  # noqa: B006
    optimizer: OptimizerOpt = "ax",
    embedder: EmbedderOpt = None,
    embedder_frames: EmbedderFramesOpt = None,
    duration: DurationOpt = None,
    fix: FixOpt = [],  # noqa: B006
    weights: WeightsOpt = None,
    device: TorchDeviceOpt = None,
    render_set: RenderSetOpt = [],  # noqa: B006
    floor_samples: _FloorSamplesOpt = 6,
    select_top: SelectTopOpt = 0,
    select_seeds: SelectSeedsOpt = 3,
    batch_size: DiagnoseBatchSizeOpt = None,
    calibrate: _CalibrateOpt = True,
    calibration_runs: _CalibrationRunsOpt = 3,
    calibrate_all: _CalibrateAllOpt = False,
    calibration_control: _CalibrationControlOpt = True,
    calibration_summary: _CalibrationSummaryOpt = "max",
    threshold: _ThresholdOpt = 2.0,
    require_gap_test: _RequireGapTestOpt = False,
    seed: SeedOpt = 0,
    out: _OutOpt = None,
    no_video: _NoVideoOpt = False,
    limits: _LimitsOpt = True,
    reveal: _RevealOpt = False,
    check_limits: _CheckLimitsOpt = False,
    screen: _ScreenOpt = True,
    ridge_starts: _RidgeStartsOpt = True,
    scene_set: SceneSetOpt = [],  # noqa: B006
    no_prepare: NoPrepareOpt = False,
    roi: RoiOpt = None,
    mirror: MirrorOpt = None,
    start: StartOpt = 0.0,
    end: EndOpt = None,
    workers: _WorkersOpt = None,
    scheduler: _SchedulerOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Find where the refined model disagrees with the video and name the missing effect."""
    given = dict(locals())
    options = options_from_cli(physinfer.DiagnoseOptions, given)
    diagnosis = physinfer.diagnose(
        plugin, options, log=lambda msg: err_console.print(msg, markup=False, highlight=False), progress=True
    )
    report = diagnosis.to_dict()
    if as_json:
        emit_json(report)
        return
    for line in diagnosis_lines(report, diagnosis.out):
        err_console.print(line, highlight=False)


def diagnosis_lines(report: dict, out: Path) -> list[str]:
    """What ``diagnose`` prints (without ``--json``), as rich markup: the verdict, a line per
    effect tried (and its detection limit), the effects screened out, the effect named and
    where the results are, the time taken."""
    adequacy = report.get("adequacy") or {}
    said = adequacy.get("message")
    refused = said if said and adequacy.get("reproduces") is False else None
    agrees = said if said and adequacy.get("reproduces") else None
    return [
        *([f"[bold red]{escape(refused)}[/]"] if refused else []),
        _misspecified_line(report),
        *_candidate_lines(report),
        *[f"  {screened_line(c)}" for c in report.get("screened") or []],
        *_named_lines(report, out),
        *([f"  {escape(agrees)}"] if agrees else []),
        timing_line(report),
    ]


def _misspecified_line(report: dict) -> str:
    """``misspecified True (by the gap test)   gap 1.2 → 0.4   (noise floor ..., null scale ...)``."""
    by = {"gap": "the gap test", "effect": "an effect's significant improvement"}
    because = " and ".join(by[e] for e in report["misspecified_by"])
    return (
        f"[bold]misspecified[/] {report['misspecified']}{f' (by {because})' if because else ''}"
        f"   gap {report['gap_before']:.4g} → {report['gap_after']:.4g}"
        f"   (noise floor {report['noise_floor']:.4g}, {null_scale_words(report)},"
        f" gap-test threshold {report['threshold']:.4g})"
    )


def _candidate_lines(report: dict) -> list[str]:
    """A line per effect tried (gap, ratio, p-value, significance, parameters on a bound), then
    with ``--limits`` a line per effect with its detection limit and the null scale's note."""
    # Imported here: the detection limits load most of the diagnosis (~45 % more start-up
    # for --help, which imports every command module).
    from physinfer.discrepancy.limit_text import limit_line

    lines = []
    for c in report["candidates"]:
        mark = "[green]significant[/]" if c["significant"] else "not significant"
        bounds = "".join(f", {name} at its {side} bound" for name, side in c.get("at_bounds", {}).items())
        lines.append(f"  {c['effect']}: gap {c['gap']:.4g} (x{c['ratio']:.2f}, p={c['p_value']:.3g}) {mark}{bounds}")
    if report.get("limits"):
        for c in report["candidates"]:
            lines.append("  " + limit_line(c, report["named_effect"], report["limits"]["clip_seconds"]))
        if note := limits_scale_note(report):
            lines.append(f"  ({note})")
    return lines


def _named_lines(report: dict, out: Path) -> list[str]:
    """The effect named (or none) and where the results are; what naming it leaves open."""
    named = escape(f"{report['named_effect'] or 'none'}; results in {out}")
    lines = [f"[bold]named effect[/] {named}"]
    if leaves := report.get("named_leaves"):
        lines.append(f"  [yellow]but[/] {escape(leaves['message'])}")
    for note in (report.get("unnamed"), report.get("lead")):
        if note:
            lines.append(f"  {escape(note['message'])}")
    return lines


def timing_line(report: dict) -> str:
    """``took 2.1 min: baseline 17 s, calibration-0 34 s, ...`` from the report's timing."""
    timing = report.get("timing") or {}
    stages = ", ".join(f"{name} {seconds:.0f} s" for name, seconds in (timing.get("stages_s") or {}).items())
    workers = timing.get("workers") or 1
    where = f" ({workers} workers side by side)" if workers > 1 else ""
    return f"took {report.get('wall_time_s', 0) / 60:.1f} min{where}: {stages}"
