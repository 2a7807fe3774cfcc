"""``physinfer refine``: refine a simulation until it matches a target video, and what it prints
without ``--json`` (the parameters, their intervals and labels, the noise-floor hint)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

import physinfer
from physinfer.cli.common import emit_json, handle_errors
from physinfer.cli.options import (
    BatchSizeOpt,
    DurationOpt,
    EmbedderFramesOpt,
    EmbedderOpt,
    EndOpt,
    FixOpt,
    FpsOpt,
    JsonOpt,
    MirrorOpt,
    NoPrepareOpt,
    OptimizerOpt,
    PluginOpt,
    RenderSetOpt,
    RoiOpt,
    SceneSetOpt,
    SeedOpt,
    SelectSeedsOpt,
    SelectTopOpt,
    StartOpt,
    TorchDeviceOpt,
    WeightsOpt,
    options_from_cli,
)
from physinfer.console import err_console
from physinfer.scene import scene_text

if TYPE_CHECKING:
    from physinfer.refinement import RefineResult

#: Above this gap / noise-floor ratio the human-readable refine output suggests more search.
NOISE_RATIO_HINT = 1.5


# The options only ``refine`` has, declared here so its signature reads as a list of settings.
_TargetOpt = Annotated[
    Path | None,
    typer.Option("--target", help="Video to match; default: the plugin's embedded target."),
]
_TruthOpt = Annotated[
    list[str], typer.Option("--truth", help="Known true value NAME=VALUE, for error reporting.")
]
_StepsOpt = Annotated[
    int | None,
    typer.Option(
        "--steps",
        help="Trials in all (default: the plugin's; fewer when the search starts from a posterior estimator).",
    ),
]
_EffectOpt = Annotated[list[str], typer.Option("--effect", help="Switch an effect in (repeatable).")]
_ModelOpt = Annotated[
    Path | None,
    typer.Option(
        "--model",
        help="Model file from `physinfer diagnose`: its effects, warm-started from its fit.",
    ),
]
_OutOpt = Annotated[
    Path | None, typer.Option("--out", help="Run directory (default: runs/<plugin>-<time>).")
]
_ResumeOpt = Annotated[bool, typer.Option("--resume", help="Continue the run in --out.")]
_OverwriteOpt = Annotated[bool, typer.Option("--overwrite", help="Replace a finished run in --out.")]
_NoiseSamplesOpt = Annotated[
    int,
    typer.Option(
        "--noise-samples",
        help="Re-simulate the centre under this many seeds first and tell the optimizer the "
        "spread of the distance as its noise (0: let the optimizer infer it).",
    ),
]
_SeedsPerTrialOpt = Annotated[
    int, typer.Option("--seeds-per-trial", help="Average each trial's distance over this many seeds.")
]
_FloorSamplesOpt = Annotated[
    int,
    typer.Option(
        "--floor-samples",
        help="Re-simulate the best fit under this many seeds to report the noise floor (0: skip).",
    ),
]
_WorkersOpt = Annotated[
    int | None,
    typer.Option(
        "--workers",
        help="Simulate and render each step's trials in K local worker processes (with --batch-size "
        "or --seeds-per-trial; 0: the same path in this process). Default: in this process.",
    ),
]
_SchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="Simulate and render the trials on a Dask cluster (tcp://host:8786); its workers need "
        "physinfer and the plugin installed.",
    ),
]
_PosteriorOpt = Annotated[
    Path | None,
    typer.Option(
        "--posterior",
        help="Posterior estimator (`physinfer posterior train`): start the search at the target's "
        "posterior median, search the region it covers, and report the posterior refined by the "
        "trials. Default: the plugin's shipped one, where it applies.",
    ),
]
_NoPosteriorOpt = Annotated[
    bool, typer.Option("--no-posterior", help="Use no posterior estimator (a best fit only).")
]
_NoRenderEstimateOpt = Annotated[
    bool,
    typer.Option(
        "--no-render-estimate",
        help="Render simulations at the default camera instead of the one estimated from --target "
        "(--render-set overrides either way).",
    ),
]


@handle_errors(kept="completed trials are saved: continue with --resume")
def refine_cmd(
    plugin: PluginOpt,
    target: _TargetOpt = None,
    fps: FpsOpt = None,
    truth: _TruthOpt = [],  # noqa: B006
    steps: _StepsOpt = None,
    optimizer: OptimizerOpt = "ax",
    embedder: EmbedderOpt = None,
    weights: WeightsOpt = None,
    device: TorchDeviceOpt = None,
    effect: _EffectOpt = [],  # noqa: B006
    model: _ModelOpt = None,
    render_set: RenderSetOpt = [],  # noqa: B006
    fix: FixOpt = [],  # noqa: B006
    seed: SeedOpt = 0,
    out: _OutOpt = None,
    resume: _ResumeOpt = False,
    overwrite: _OverwriteOpt = False,
    noise_samples: _NoiseSamplesOpt = 3,
    seeds_per_trial: _SeedsPerTrialOpt = 1,
    floor_samples: _FloorSamplesOpt = 4,
    select_top: SelectTopOpt = 0,
    select_seeds: SelectSeedsOpt = 3,
    batch_size: BatchSizeOpt = 1,
    workers: _WorkersOpt = None,
    scheduler: _SchedulerOpt = None,
    duration: DurationOpt = None,
    embedder_frames: EmbedderFramesOpt = None,
    scene_set: SceneSetOpt = [],  # noqa: B006
    posterior: _PosteriorOpt = None,
    no_posterior: _NoPosteriorOpt = False,
    no_prepare: NoPrepareOpt = False,
    roi: RoiOpt = None,
    mirror: MirrorOpt = None,
    start: StartOpt = 0.0,
    end: EndOpt = None,
    no_render_estimate: _NoRenderEstimateOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Refine a simulation until it matches a target video; report the parameters found."""
    given = dict(locals())
    options = options_from_cli(physinfer.RefineOptions, given)
    result = physinfer.refine(plugin, options, progress=True)
    summary = result.summary()
    if as_json:
        emit_json(summary)
        return
    for line in refine_result_lines(result):
        err_console.print(line, highlight=False)


def refine_result_lines(result: RefineResult) -> list[str]:
    """What ``refine`` prints (without ``--json``): the parameters the video determines with
    best fit, posterior median, 90 % interval and label; the others named on one line (their
    best fit is where the search stopped, and a bound it stopped on says nothing either);
    correlations, where the posterior came from, fixed values, bounds, the noise-floor hint."""
    marginals = result.posterior
    hidden = [
        n for n in result.best_params if marginals.get(n, {}).get("label") == "not identified"
    ]
    place = result.place.at_bounds if result.place is not None else {}
    at_bounds = {n: b for n, b in place.items() if n not in hidden}
    return [
        *_fit_lines(result),
        *_parameter_lines(result, marginals, hidden, at_bounds),
        *_note_lines(result, at_bounds),
        f"results in {result.run_dir}",
    ]


def _fit_lines(result: RefineResult) -> list[str]:
    """The best distance, whether the best fit reproduces the video, the scene."""
    # Imported here: adequacy loads the footage modules (~15 % more start-up for --help).
    from physinfer.adequacy import agreement_line, verdict_line

    lines = [f"best distance {result.best_distance:.4g} at step {result.best_step}"]
    if (verdict := verdict_line(result.adequacy) or agreement_line(result.adequacy)) is not None:
        lines.append(verdict)
    if result.target is not None and result.target.scene:
        lines.append(f"  scene: {scene_text(result.target.scene)}")
    return lines


def _parameter_lines(
    result: RefineResult, marginals: dict, hidden: list[str], at_bounds: dict[str, str]
) -> list[str]:
    """A line per parameter the video determines, then the nuisance values on one line and the
    parameters not identified on another."""
    nuisance = result.place.nuisance if result.place is not None else {}
    lines = [
        best_fit_line(name, value, result, marginals.get(name), at_bounds.get(name))
        for name, value in result.best_params.items()
        if name not in hidden and name not in nuisance
    ]
    if nuisance:
        lines.append(
            "  nuisance (what the video leaves open, not a measurement): "
            + ", ".join(f"{name} = {value:.3g}" for name, value in nuisance.items())
        )
    hidden = [name for name in hidden if name not in nuisance]
    if hidden:
        names = (
            ", ".join(hidden)
            if len(hidden) <= 6
            else f"{', '.join(hidden[:4])}, … ({len(hidden)} in all)"
        )
        lines.append(
            f"  not identified (the video barely narrows their ranges; best fits and intervals in "
            f"result.json): {names}"
        )
    return lines


def _note_lines(result: RefineResult, at_bounds: dict[str, str]) -> list[str]:
    """Correlations, where the posterior came from, fixed values, bounds, the noise-floor hint."""
    lines: list[str] = []
    if (posterior := result.target_posterior) is not None:
        lines += [
            f"  correlated: {pair['a']} ~ {pair['b']}  r = {pair['r']:+.2f}"
            for pair in (posterior.correlations or [])[:2]
        ]
        if posterior.note:
            lines.append(posterior.note)
        if posterior.source:
            lines.append(posterior_source_line(posterior.source))
    for name, value in (result.fixed or {}).items():
        lines.append(f"  {name} = {value:.4g}   (fixed)")
    video_estimate = result.target.video_estimate if result.target is not None else None
    for note in ((video_estimate or {}).get("outside_range") or {}).values():
        lines.append(f"at the bound: {note}")
    if at_bounds:
        lines.append(
            f"{', '.join(at_bounds)} ended on a bound of the search range: the truth may lie beyond it, "
            "or another parameter is compensating for something the model lacks (`physinfer diagnose`)."
        )
    floor = result.noise.floor if result.noise is not None else None
    hint = noise_ratio_hint((floor or {}).get("ratio"))
    if hint:
        lines.append(hint)
    return lines


def best_fit_line(
    name: str, value: float, result: RefineResult, marginal: dict | None, bound: str | None
) -> str:
    """One printed parameter: the best fit and, with a posterior, its 90 % interval and label.

    A parameter the video does not determine gets no error against the truth: its best fit
    is wherever the search stopped, not a measurement.
    """
    line = f"  {name} = {value:.4g}"
    if marginal is not None:
        lo, hi = marginal["ci90"]
        line += f"   posterior {marginal['median']:.4g} [90 %: {lo:.4g} – {hi:.4g}]   {marginal['label']}"
    truth, errors = result.ground_truth or {}, result.abs_errors or {}
    if name in errors and (marginal is None or marginal["label"] != "not identified"):
        line += f"   (truth {truth[name]:.4g}, error {errors[name]:.3g})"
    elif name in truth:
        line += f"   (truth {truth[name]:.4g})"
    if bound:
        line += f"   (at its {bound} bound)"
    return line


def posterior_source_line(source: dict) -> str:
    """Where the printed intervals come from: the refinement's trials or the estimator alone."""
    estimator = Path(source["estimator"]).name
    if source["kind"] == "refined":
        return (
            f"posterior: refined by this run's trials (a likelihood of the distance over "
            f"{', '.join(source['modelled'])}; the noise floor sets its scale), from {estimator}"
        )
    return (
        f"posterior: {estimator} alone (not refined: {source.get('not_refined', 'no trials used')})"
    )


def noise_ratio_hint(ratio: float | None) -> str | None:
    """Advice when the best fit's gap is well above the noise floor, else ``None``.

    On held-out flag targets, fits that ended within the flag's chaos had ratios of 0.4–1.2;
    the searches that stopped short ended at 1.4–2.8 (docs/benchmarks.md, Refinement).
    """
    if ratio is None or ratio <= NOISE_RATIO_HINT:
        return None
    return (
        f"noise ratio {ratio:.2f}: the best fit is further from the target than re-simulations of itself are "
        "from each other. Refine longer (--resume --steps N) or again with another --seed; if it stays, "
        "`physinfer diagnose` looks for what the model lacks."
    )
