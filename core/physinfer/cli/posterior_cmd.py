"""``physinfer posterior train``, ``physinfer infer`` and ``physinfer evaluate calibration``.

Thin shells over :mod:`physinfer.api`: parse options, call, print (one JSON
object with ``--json``; progress on stderr).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from physinfer.cli.app import (
    JsonOpt,
    NoPrepareOpt,
    PluginOpt,
    RoiOpt,
    SceneSetOpt,
    emit_json,
    err_console,
    handle_errors,
)

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


@posterior_app.callback()
def posterior_group() -> None:
    """Amortized posteriors over θ (neural posterior estimation with sbi; docs/posterior.md)."""


@posterior_app.command("train")
@handle_errors()
def train_cmd(
    plugin: PluginOpt,
    data: Annotated[
        Path, typer.Option("--data", help="Dataset from `physinfer dataset generate`.")
    ],
    out: Annotated[Path, typer.Option("--out", help="Estimator file to write (*.safetensors).")],
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="Replace --out when it exists (by default an existing file is refused before "
            "anything is embedded or trained).",
        ),
    ] = False,
    embedder: Annotated[
        str | None, typer.Option("--embedder", help="Embedder (default: the plugin's).")
    ] = None,
    embedder_frames: Annotated[
        int | None,
        typer.Option("--embedder-frames", help="Frames a parameter-free embedder reads."),
    ] = None,
    weights: Annotated[
        Path | None, typer.Option("--weights", help="Embedder weights file.")
    ] = None,
    split: Annotated[str, typer.Option("--split", help="Dataset split to train on.")] = "train",
    density: Annotated[
        str,
        typer.Option("--density", help="Density estimator: nsf (neural spline flow), maf or mdn."),
    ] = "nsf",
    max_epochs: Annotated[
        int, typer.Option("--max-epochs", help="Upper bound on training epochs.")
    ] = 400,
    patience: Annotated[
        int,
        typer.Option(
            "--patience", help="Stop after this many epochs without a better validation loss."
        ),
    ] = 60,
    seed: Annotated[
        int, typer.Option("--seed", help="Seed of the network's initialisation and batches.")
    ] = 0,
    ensemble: Annotated[
        int,
        typer.Option(
            "--ensemble",
            help="Flows trained with seeds SEED.. SEED+N-1; the posterior is their mixture.",
        ),
    ] = 1,
    device: DeviceOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Train q(θ | s(x)) on a dataset's (θ, embedding) pairs; embeddings are cached beside the dataset."""
    given = dict(locals())
    from physinfer import api
    from physinfer.cli.options import options_from_cli

    result = api.train_posterior(
        plugin, options_from_cli(api.PosteriorTrainOptions, given), progress=True
    )
    if as_json:
        emit_json(result.to_dict())
        return
    t = result.estimator.config.training
    epochs, losses = t["epochs"], t["best_validation_loss"]
    if isinstance(epochs, list):  # an ensemble: one entry per flow
        how = f"{len(epochs)} flows, {'/'.join(map(str, epochs))} epochs, validation loss "
        how += "/".join(f"{v:.3f}" for v in losses)
    else:
        how = f"{epochs} epochs (validation loss {losses:.3f})"
    err_console.print(
        f"trained on {t['pairs']} clips in {how}; wrote {result.path}", markup=False, highlight=False
    )


@handle_errors()
def infer_cmd(
    plugin: PluginOpt,
    target: Annotated[
        Path | None, typer.Option("--target", help="Video; default: the plugin's embedded target.")
    ] = None,
    posterior: PosteriorOpt = None,
    fps: Annotated[
        float | None, typer.Option("--fps", help="Frame rate of --target if it cannot be read.")
    ] = None,
    truth: Annotated[
        list[str],
        typer.Option("--truth", help="Known true value NAME=VALUE (reported beside the interval)."),
    ] = [],  # noqa: B006
    samples: Annotated[int, typer.Option("--samples", help="Posterior samples to draw.")] = 5000,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the posterior samples.")] = 0,
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Directory for posterior.json, samples.npz, corner.png."),
    ] = None,
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="Replace an earlier infer's results in --out (only those; a folder of other files "
            "is refused).",
        ),
    ] = False,
    device: DeviceOpt = None,
    scene_set: SceneSetOpt = [],  # noqa: B006
    no_prepare: NoPrepareOpt = False,
    roi: RoiOpt = None,
    check: Annotated[
        bool,
        typer.Option(
            "--check/--no-check",
            help="Simulate the posterior's median and say whether the model reproduces the video "
            "(two simulations: seconds on the flag).",
        ),
    ] = True,
    as_json: JsonOpt = False,
) -> None:
    """The posterior of one video in seconds: median, 50 % and 90 % intervals, identifiability."""
    given = dict(locals())
    from physinfer import api
    from physinfer.cli.app import options_from_cli
    from physinfer.posterior.workflow import summary_lines

    report = api.infer(plugin, options_from_cli(api.InferOptions, given))
    if as_json:
        emit_json(report.to_dict())
        return
    err_console.print(
        f"[bold]posterior[/] ({escape(report.estimator.name)}, {len(report.samples_unit)} samples)"
    )
    from physinfer.adequacy import verdict_line

    if (verdict := verdict_line(report.adequacy)) is not None:
        err_console.print(verdict, markup=False, highlight=False)
    for line in summary_lines(report.marginals):
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
    seed: Annotated[int, typer.Option("--seed", help="Seed of the posterior samples.")] = 0,
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
    from physinfer import api
    from physinfer.cli.options import options_from_cli

    report = api.evaluate_calibration(
        plugin, options_from_cli(api.CalibrationOptions, given), progress=True
    )
    summary = report.to_dict()
    if as_json:
        emit_json(summary)
        return
    tol = summary["tolerance"]
    err_console.print(
        f"[bold]coverage[/] on {summary['n_pairs']} held-out simulations "
        f"(calibrated within ±{tol['coverage50']:.2f} / ±{tol['coverage90']:.2f})",
        highlight=False,
    )
    for name, row in summary["parameters"].items():
        err_console.print(
            f"  {name}: 50 % → {row['coverage50']:.2f}, 90 % → {row['coverage90']:.2f} ({row['verdict90']}); "
            f"median error {row['median_abs_error']:.3g}, contraction {row['mean_contraction']:.2f}",
            highlight=False,
        )
    err_console.print(f"results in {Path(report.paths['report']).parent}", markup=False)
