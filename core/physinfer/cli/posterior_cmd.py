"""``physinfer posterior train``, ``physinfer infer`` and ``physinfer evaluate calibration``.

Thin shells over :mod:`physinfer.api`: parse options, call, print (one JSON
object with ``--json``; progress on stderr).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

import physinfer
from physinfer.cli.app import (
    EndOpt,
    JsonOpt,
    MirrorOpt,
    NoPrepareOpt,
    PluginOpt,
    RoiOpt,
    SceneSetOpt,
    StartOpt,
    emit_json,
    err_console,
    handle_errors,
)
from physinfer.cli.options import EmbedderOpt, FpsOpt, WeightsOpt, options_from_cli

posterior_app = typer.Typer(
    no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False
)

DeviceOpt = Annotated[
    str | None,
    typer.Option("--device", help="torch device: cpu, cuda, cuda:N (default: cuda if present)."),
]
PosteriorOpt = Annotated[
    Path | None,
    typer.Option(
        "--posterior",
        help="Estimator file from `physinfer posterior train` (default: the plugin's shipped one).",
    ),
]
SampleSeedOpt = Annotated[int, typer.Option("--seed", help="Seed of the posterior samples.")]


@posterior_app.callback()
def posterior_group() -> None:
    """Amortized posteriors over θ (neural posterior estimation with sbi; docs/posterior.md)."""


# The options only ``posterior train`` has, declared here so its signature reads as a list of settings.
_DataOpt = Annotated[
    list[Path],
    typer.Option(
        "--data",
        help="Dataset from `physinfer dataset generate` (repeatable: datasets generated alike, "
        "trained on together).",
    ),
]
_EstimatorOutOpt = Annotated[
    Path, typer.Option("--out", help="Estimator file to write (*.safetensors).")
]
_OverwriteEstimatorOpt = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Replace --out when it exists (by default an existing file is refused before "
        "anything is embedded or trained).",
    ),
]
_TrainFramesOpt = Annotated[
    int | None,
    typer.Option("--embedder-frames", help="Frames a parameter-free embedder reads."),
]
_TrainSplitOpt = Annotated[str, typer.Option("--split", help="Dataset split to train on.")]
_DensityOpt = Annotated[
    str,
    typer.Option("--density", help="Density estimator: nsf (neural spline flow), maf or mdn."),
]
_MaxEpochsOpt = Annotated[int, typer.Option("--max-epochs", help="Upper bound on training epochs.")]
_PatienceOpt = Annotated[
    int,
    typer.Option("--patience", help="Stop after this many epochs without a better validation loss."),
]
_TrainSeedOpt = Annotated[
    int, typer.Option("--seed", help="Seed of the network's initialisation and batches.")
]
_EnsembleOpt = Annotated[
    int,
    typer.Option(
        "--ensemble",
        help="Flows trained with seeds SEED.. SEED+N-1; the posterior is their mixture.",
    ),
]
_StoredOpt = Annotated[
    bool,
    typer.Option(
        "--stored",
        help="Train on the stored renders as they are (default: on the clips as users give videos: "
        "camera effects, H.264 and infer's conditioning).",
    ),
]
_RenderInputOpt = Annotated[
    list[str],
    typer.Option(
        "--render-input",
        help="A render setting (camera, light) the estimator is told, from each clip's recorded ζ "
        "(repeatable); infer then needs it with --render-set.",
    ),
]
_ToldCameraOpt = Annotated[
    bool,
    typer.Option(
        "--told-camera",
        help="Tell the estimator every numeric render setting the dataset varies (the flag: camera "
        "angles, field of view, framing, light): sharper when the camera is known; infer then needs them "
        "all with --render-set.",
    ),
]
_AcceptMiscalibratedOpt = Annotated[
    bool,
    typer.Option(
        "--accept-miscalibrated",
        help="Write the estimator even when it fails its check on the held-out clips.",
    ),
]


@posterior_app.command("train")
@handle_errors(kept="embedded clips are cached in the dataset: run the same command again to continue")
def train_cmd(
    plugin: PluginOpt,
    data: _DataOpt,
    out: _EstimatorOutOpt,
    overwrite: _OverwriteEstimatorOpt = False,
    embedder: EmbedderOpt = None,
    embedder_frames: _TrainFramesOpt = None,
    weights: WeightsOpt = None,
    split: _TrainSplitOpt = "train",
    density: _DensityOpt = "nsf",
    max_epochs: _MaxEpochsOpt = 400,
    patience: _PatienceOpt = 60,
    seed: _TrainSeedOpt = 0,
    ensemble: _EnsembleOpt = 1,
    device: DeviceOpt = None,
    stored: _StoredOpt = False,
    render_inputs: _RenderInputOpt = [],  # noqa: B006
    told_camera: _ToldCameraOpt = False,
    accept_miscalibrated: _AcceptMiscalibratedOpt = False,
    as_json: JsonOpt = False,
) -> None:
    """Train q(θ | s(x)) on a dataset's (θ, embedding) pairs, the clips sent down the path a user's
    video takes, and check it on the held-out clips before writing; embeddings are cached beside
    the dataset."""
    given = dict(locals())
    result = physinfer.train_posterior(
        plugin, options_from_cli(physinfer.PosteriorTrainOptions, given), progress=True
    )
    if as_json:
        emit_json(result.to_dict())
        return
    for line in trained_lines(result):
        err_console.print(line, markup=False, highlight=False)


def trained_lines(result: Any) -> list[str]:
    """What ``posterior train`` prints (without ``--json``): how it trained and where it wrote,
    the inputs that never varied, the held-out check."""
    t = result.estimator.config.training
    epochs, losses = t["epochs"], t["best_validation_loss"]
    if isinstance(epochs, list):  # an ensemble: one entry per flow
        how = f"{len(epochs)} flows, {'/'.join(map(str, epochs))} epochs, validation loss "
        how += "/".join(f"{v:.3f}" for v in losses)
    else:
        how = f"{epochs} epochs (validation loss {losses:.3f})"
    lines = [f"trained on {t['pairs']} clips in {how}; wrote {result.path}"]
    told = result.estimator.config.render_inputs
    if told:
        lines.append(
            f"told the render settings {', '.join(told)}: infer needs them with --render-set NAME=VALUE"
        )
    constant = result.to_dict()["constant_inputs"]
    if constant:
        lines.append(
            f"{constant} of {result.estimator.config.x_dim} inputs never varied in training (a still "
            "background, say); at inference they are held at their training value"
        )
    return lines + held_out_lines(result.estimator.config.held_out)


def held_out_lines(held_out: dict | None) -> list[str]:
    """What the held-out check found, a line per parameter (or why there was none)."""
    if not held_out:
        return ["not checked on held-out clips: the dataset has no test or val split (--sims TRAIN,VAL,TEST)"]
    how = "as users give them" if held_out["as_given"] else "as stored"
    lines = [f"held-out check on {held_out['clips']} {held_out['split']} clips {how}:"]
    for name, row in held_out["parameters"].items():
        lines.append(
            f"  {name}: 90 % interval holds the truth on {row['coverage90']:.0%}, "
            f"median width {row['median_width90']:.0%} of the range"
        )
    lines += [f"  FAILED: {p}" for p in held_out["problems"]]
    lines += [f"  nuisance (not refused): {p}" for p in held_out.get("nuisance_problems", [])]
    return lines


# The options only ``infer`` has.
_InferTargetOpt = Annotated[
    Path | None, typer.Option("--target", help="Video; default: the plugin's embedded target.")
]
_InferTruthOpt = Annotated[
    list[str],
    typer.Option("--truth", help="Known true value NAME=VALUE (reported beside the interval)."),
]
_InferSamplesOpt = Annotated[int, typer.Option("--samples", help="Posterior samples to draw.")]
_InferOutOpt = Annotated[
    Path | None,
    typer.Option("--out", help="Directory for posterior.json, samples.npz, corner.png."),
]
_InferOverwriteOpt = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Replace an earlier infer's results in --out (only those; a folder of other files "
        "is refused).",
    ),
]
_InferRenderSetOpt = Annotated[
    list[str],
    typer.Option(
        "--render-set",
        help="The camera and light the video was taken with, NAME=VALUE (repeatable): an estimator told "
        "them (posterior train --told-camera) needs them; the plugin's shipped one for them is then used.",
    ),
]
_CheckOpt = Annotated[
    bool,
    typer.Option(
        "--check/--no-check",
        help="Simulate the posterior's median and say whether the model reproduces the video "
        "(two simulations: seconds on the flag).",
    ),
]


@handle_errors()
def infer_cmd(
    plugin: PluginOpt,
    target: _InferTargetOpt = None,
    posterior: PosteriorOpt = None,
    fps: FpsOpt = None,
    truth: _InferTruthOpt = [],  # noqa: B006
    samples: _InferSamplesOpt = 5000,
    seed: SampleSeedOpt = 0,
    out: _InferOutOpt = None,
    overwrite: _InferOverwriteOpt = False,
    device: DeviceOpt = None,
    scene_set: SceneSetOpt = [],  # noqa: B006
    render_set: _InferRenderSetOpt = [],  # noqa: B006
    no_prepare: NoPrepareOpt = False,
    roi: RoiOpt = None,
    mirror: MirrorOpt = None,
    start: StartOpt = 0.0,
    end: EndOpt = None,
    check: _CheckOpt = True,
    as_json: JsonOpt = False,
) -> None:
    """The posterior of one video in seconds: median, 50 % and 90 % intervals, identifiability."""
    given = dict(locals())
    # Imported here: the posterior workflows load torch, and adequacy the footage modules;
    # --help imports every command module.
    from physinfer.posterior.workflow import summary_lines, trust_lines

    report = physinfer.infer(plugin, options_from_cli(physinfer.InferOptions, given))
    if as_json:
        emit_json(report.to_dict())
        return
    err_console.print(
        f"[bold]posterior[/] ({escape(report.estimator.name)}, {len(report.samples_unit)} samples)"
    )
    from physinfer.adequacy import agreement_line, verdict_line

    # An extrapolated estimator's median says nothing for the model: no agreement claimed then
    # (the ball on a string through the flag's estimator passed at 6.6 while 192 SDs outside).
    agreement = None if (report.inputs or {}).get("extrapolating") else agreement_line(report.adequacy)
    if (verdict := verdict_line(report.adequacy) or agreement) is not None:
        err_console.print(verdict, markup=False, highlight=False)
    for line in trust_lines(report):
        err_console.print(line, markup=False, highlight=False)
    for line in summary_lines(report.marginals, report.nuisance):
        err_console.print(line, highlight=False)
    for pair in report.correlations[:3]:
        err_console.print(
            f"  correlated: {pair['a']} ~ {pair['b']}  r = {pair['r']:+.2f}", highlight=False
        )
    err_console.print(f"results in {Path(report.paths['posterior']).parent}", markup=False)


@handle_errors()
def calibration_cmd(
    plugin: PluginOpt,
    data: Annotated[Path, typer.Option("--data", help="Dataset of held-out simulations.")],
    posterior: PosteriorOpt = None,
    split: Annotated[str, typer.Option("--split", help="Dataset split to check on.")] = "test",
    samples: Annotated[
        int, typer.Option("--samples", help="Posterior samples per simulation.")
    ] = 1000,
    seed: SampleSeedOpt = 0,
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Directory for calibration.json and calibration.png."),
    ] = None,
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="Replace an earlier calibration's results in --out (only those; a folder of other "
            "files is refused).",
        ),
    ] = False,
    device: DeviceOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Simulation-based calibration: rank histograms and coverage of the 50 % and 90 % intervals."""
    given = dict(locals())
    report = physinfer.evaluate_calibration(
        plugin, options_from_cli(physinfer.CalibrationOptions, given), progress=True
    )
    summary = report.to_dict()
    if as_json:
        emit_json(summary)
        return
    tol = summary["tolerance"]
    err_console.print(
        f"[bold]coverage[/] on {summary['n_pairs']} held-out simulations as users give videos "
        f"(camera, H.264, infer's conditioning; calibrated within ±{tol['coverage50']:.2f} / "
        f"±{tol['coverage90']:.2f}); as stored in brackets",
        highlight=False,
    )
    stored = summary.get("in_memory", {}).get("parameters", {})
    for name, row in summary["parameters"].items():
        raw = stored.get(name)
        beside = f" [{raw['coverage90']:.2f}]" if raw else ""
        err_console.print(
            f"  {name}: 50 % → {row['coverage50']:.2f}, 90 % → {row['coverage90']:.2f}{beside} "
            f"({row['verdict90']}); median error {row['median_abs_error']:.3g}, "
            f"contraction {row['mean_contraction']:.2f}",
            highlight=False,
        )
    err_console.print(f"results in {Path(report.paths['report']).parent}", markup=False)
