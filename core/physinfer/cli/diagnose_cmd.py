"""``physinfer diagnose``: name the effect a refined model is missing, or say none is.

Registered as a command by physinfer's built-in plugin; a thin shell over :func:`physinfer.api.diagnose`, which runs
:func:`physinfer.discrepancy.workflow.run_diagnosis`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from physinfer.cli.app import (
    DiagnoseBatchSizeOpt,
    DurationOpt,
    EmbedderFramesOpt,
    FixOpt,
    JsonOpt,
    NoPrepareOpt,
    PluginOpt,
    RoiOpt,
    SceneSetOpt,
    SeedOpt,
    SelectSeedsOpt,
    SelectTopOpt,
    emit_json,
    err_console,
    handle_errors,
)


@handle_errors()
def diagnose_cmd(
    plugin: PluginOpt,
    target: Annotated[
        Path | None, typer.Option("--target", help="Video to diagnose; default: the plugin's embedded target.")
    ] = None,
    fps: Annotated[float | None, typer.Option("--fps", help="Frame rate of --target if it cannot be read.")] = None,
    truth: Annotated[
        list[str], typer.Option("--truth", help="Known true value NAME=VALUE (reported only).")
    ] = [],  # noqa: B006
    steps: Annotated[int | None, typer.Option("--steps", help="Baseline trials (default: the plugin's).")] = None,
    effect_steps: Annotated[
        int | None, typer.Option("--effect-steps", help="Trials per augmented model and for the control (default: --steps).")
    ] = None,
    effect: Annotated[
        list[str], typer.Option("--effect", help="Only try these effects (repeatable; default: all of the plugin's).")
    ] = [],  # noqa: B006
    optimizer: Annotated[str, typer.Option("--optimizer", help="ax, random, cma, or a plugin's.")] = "ax",
    embedder: Annotated[str | None, typer.Option("--embedder", help="Embedder (default: the plugin's).")] = None,
    embedder_frames: EmbedderFramesOpt = None,
    duration: DurationOpt = None,
    fix: FixOpt = [],  # noqa: B006
    weights: Annotated[Path | None, typer.Option("--weights", help="Embedder weights file.")] = None,
    device: Annotated[str | None, typer.Option("--device", help="torch device (default: cuda if present).")] = None,
    render_set: Annotated[
        list[str], typer.Option("--render-set", help="Render setting NAME=VALUE for simulations.")
    ] = [],  # noqa: B006
    floor_samples: Annotated[
        int, typer.Option("--floor-samples", help="Re-simulations per gap measurement (>= 4).")
    ] = 6,
    select_top: SelectTopOpt = 0,
    select_seeds: SelectSeedsOpt = 3,
    batch_size: DiagnoseBatchSizeOpt = None,
    calibrate: Annotated[
        bool,
        typer.Option("--calibrate/--no-calibrate", help="Self-consistency refinements to calibrate the null scale."),
    ] = True,
    calibration_runs: Annotated[
        int,
        typer.Option(
            "--calibration-runs",
            help="Self-consistency refinements (>= 1, each --steps trials); --calibration-summary makes their "
            "gaps one (default: the largest).",
        ),
    ] = 3,
    calibrate_all: Annotated[
        bool,
        typer.Option(
            "--calibrate-all",
            help="Refine every self-consistency run and control. By default only those that could change a "
            "decision are refined (the same decisions; the null scale may then be known only as a range).",
        ),
    ] = False,
    calibration_control: Annotated[
        bool,
        typer.Option(
            "--calibration-control/--no-calibration-control",
            help="Give each self-consistency run its own control (--effect-steps more trials), as the baseline has.",
        ),
    ] = True,
    calibration_summary: Annotated[
        str,
        typer.Option(
            "--calibration-summary",
            help="max or median of the self-consistency runs' gaps: the null scale's optimizer part.",
        ),
    ] = "max",
    threshold: Annotated[
        float,
        typer.Option("--threshold", help="The gap test finds the model misspecified above this many null scales."),
    ] = 2.0,
    require_gap_test: Annotated[
        bool,
        typer.Option(
            "--require-gap-test",
            help="Name an effect only when the gap test alone finds the model misspecified (by default an "
            "effect's significant improvement is evidence enough).",
        ),
    ] = False,
    seed: SeedOpt = 0,
    out: Annotated[Path | None, typer.Option("--out", help="Diagnosis directory (re-run to continue it).")] = None,
    no_video: Annotated[bool, typer.Option("--no-video", help="Skip the side-by-side video.")] = False,
    limits: Annotated[
        bool,
        typer.Option(
            "--limits/--no-limits",
            help="Estimate each effect's detection limit (the weakest strength this clip could name) from a "
            "ladder of simulations at the best baseline fit.",
        ),
    ] = True,
    reveal: Annotated[
        bool,
        typer.Option(
            "--reveal",
            help="Also measure whether another camera view or a twice longer clip would lower the limits "
            "(chaotic phenomena; re-renders and re-simulates the ladder).",
        ),
    ] = False,
    check_limits: Annotated[
        bool,
        typer.Option(
            "--check-limits",
            help="Check each effect not named: run this diagnosis' own stages on a target made with it at its "
            "stated limit (doubled until named, to the end of its range), so the limit is what this search names. Costly.",
        ),
    ] = False,
    screen: Annotated[
        bool,
        typer.Option(
            "--screen/--no-screen",
            help="Before refining the effects, leave out those whose signature at the baseline's fit no fit "
            "could name (a ladder of simulations; chaotic phenomena only). --no-screen refines every effect.",
        ),
    ] = True,
    ridge_starts: Annotated[
        bool,
        typer.Option(
            "--ridge-starts/--no-ridge-starts",
            help="Start each effect's search also where the video points along the ridge it shares with the "
            "base parameters (drag vs restitution), not only at the baseline's fit.",
        ),
    ] = True,
    scene_set: SceneSetOpt = [],  # noqa: B006
    no_prepare: NoPrepareOpt = False,
    roi: RoiOpt = None,
    workers: Annotated[
        int | None,
        typer.Option(
            "--workers",
            help="Run the stages after the baseline side by side in K local worker processes (default: one "
            "per CPU; 0 or 1: in this process). The decisions do not depend on it.",
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            "--scheduler",
            help="Run those stages on a Dask cluster (tcp://host:8786); its workers need physinfer and the "
            "plugins installed and must see --out.",
        ),
    ] = None,
    as_json: JsonOpt = False,
) -> None:
    """Find where the refined model disagrees with the video and name the missing effect."""
    given = dict(locals())
    from physinfer import api
    from physinfer.cli.app import options_from_cli
    from physinfer.discrepancy.limit_text import screened_line
    from physinfer.discrepancy.limits import limit_line
    from physinfer.discrepancy.needed_calibration import limits_scale_note, null_scale_words

    options = options_from_cli(api.DiagnoseOptions, given)
    diagnosis = api.diagnose(
        plugin, options, log=lambda msg: err_console.print(msg, markup=False, highlight=False), progress=True
    )
    report, out = diagnosis.to_dict(), diagnosis.out
    if as_json:
        emit_json(report)
        return
    by = {"gap": "the gap test", "effect": "an effect's significant improvement"}
    because = " and ".join(by[e] for e in report["misspecified_by"])
    err_console.print(
        f"[bold]misspecified[/] {report['misspecified']}{f' (by {because})' if because else ''}"
        f"   gap {report['gap_before']:.4g} → {report['gap_after']:.4g}"
        f"   (noise floor {report['noise_floor']:.4g}, {null_scale_words(report)},"
        f" gap-test threshold {report['threshold']:.4g})",
        highlight=False,
    )
    for c in report["candidates"]:
        mark = "[green]significant[/]" if c["significant"] else "not significant"
        bounds = "".join(f", {name} at its {side} bound" for name, side in c.get("at_bounds", {}).items())
        err_console.print(
            f"  {c['effect']}: gap {c['gap']:.4g} (x{c['ratio']:.2f}, p={c['p_value']:.3g}) {mark}{bounds}",
            highlight=False,
        )
    if report.get("limits"):
        for c in report["candidates"]:
            err_console.print(
                "  " + limit_line(c, report["named_effect"], report["limits"]["clip_seconds"]), highlight=False
            )
        if note := limits_scale_note(report):
            err_console.print(f"  ({note})", highlight=False)
    for c in report.get("screened") or []:
        err_console.print(f"  {screened_line(c)}", highlight=False)
    named = escape(f"{report['named_effect'] or 'none'}; results in {out}")
    err_console.print(f"[bold]named effect[/] {named}", highlight=False)
    if leaves := report.get("named_leaves"):
        err_console.print(f"  [yellow]but[/] {escape(leaves['message'])}", highlight=False)
    if unnamed := report.get("unnamed"):
        err_console.print(f"  {escape(unnamed['message'])}", highlight=False)
    err_console.print(timing_line(report), highlight=False)


def timing_line(report: dict) -> str:
    """``took 2.1 min: baseline 17 s, calibration-0 34 s, ...`` from the report's timing."""
    timing = report.get("timing") or {}
    stages = ", ".join(f"{name} {seconds:.0f} s" for name, seconds in (timing.get("stages_s") or {}).items())
    workers = timing.get("workers") or 1
    where = f" ({workers} workers side by side)" if workers > 1 else ""
    return f"took {report.get('wall_time_s', 0) / 60:.1f} min{where}: {stages}"
