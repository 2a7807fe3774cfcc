"""CLI commands of the hanging-cloth plugin: ``evaluate bouman`` and ``dataset bouman``.

``physinfer evaluate bouman`` runs the paper's Bouman et al. evaluation on a directory
in the Bouman format; ``physinfer dataset bouman`` writes a synthetic dataset in that
format. Both follow the host's conventions: ``--json`` prints exactly one JSON object,
progress goes to stderr, user mistakes exit with status 2. This module is imported when
the CLI is built, so heavy libraries are imported inside the commands.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from physinfer.cli.app import JsonOpt, emit_json, err_console, handle_errors, registry_and_infos
from physinfer.errors import UserInputError

#: What ``evaluate bouman`` writes into its ``--out``.
BOUMAN_OUTPUTS = ("bouman.png", "result.json", "predictions.csv")


@handle_errors()
def evaluate_bouman_cmd(
    data: Annotated[Path, typer.Option("--data", help="Bouman-format directory (ground_truth.csv|xlsx + videos/).")],
    model: Annotated[
        Path | None, typer.Option("--model", help="Embedder weights (default: the embedder's shipped ones).")
    ] = None,
    embedder: Annotated[str, typer.Option("--embedder", help="Registered embedder: sdn, spectral, ...")] = "sdn",
    device: Annotated[str | None, typer.Option("--device", help="torch device (default: cuda if present).")] = None,
    out: Annotated[
        Path | None, typer.Option("--out", help="Directory for the chart and predictions (default: runs/bouman-*).")
    ] = None,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace an earlier evaluation's results in --out (only those).")
    ] = False,
    pca_dims: Annotated[int, typer.Option("--pca-dims", help="PCA components (the paper: 50).")] = 50,
    as_json: JsonOpt = False,
) -> None:
    """Bouman et al. evaluation: embeddings → PCA → linear regression, leave one fabric out → Pearson R."""
    from physinfer.devices import check_device
    from physinfer.io import atomic_write_json, atomic_write_text
    from physinfer.outputs import OutputFolder
    from physinfer_hanging_cloth.data import load_dataset
    from physinfer_hanging_cloth.evaluation import embed_videos, evaluate_embeddings, plot_bars

    if pca_dims < 1:
        raise UserInputError(f"--pca-dims must be at least 1, got {pca_dims}")
    device = check_device(device)  # also for embedders that take none: never silently ignored
    if out is None:
        out = Path("runs") / f"bouman-{embedder}-{time.strftime('%Y%m%d-%H%M%S')}"
    folder = OutputFolder(out, "evaluate bouman", BOUMAN_OUTPUTS, example="bouman")
    folder.check(overwrite=overwrite)  # before the data is read or a network loaded
    dataset = load_dataset(data)  # check the data before loading any network
    registry, _ = registry_and_infos()
    embedder_obj = registry.embedder(embedder, model=str(model) if model else None, device=device)
    folder.claim(overwrite=overwrite)
    started = time.perf_counter()

    def progress(done: int, total: int) -> None:
        err_console.print(f"embedded {done}/{total} videos", highlight=False)

    embeddings = embed_videos(dataset, embedder_obj, on_video=progress)
    result = evaluate_embeddings(dataset, embeddings, pca_dims=pca_dims)
    chart = plot_bars(result, out / "bouman.png", label=embedder)
    summary = {**result.summary(), "embedder": embedder, "chart": str(chart), "out": str(out)}
    summary["seconds"] = time.perf_counter() - started
    atomic_write_json(out / "result.json", summary)
    lines = ["video,fabric,fan_level,log_stiffness_true,log_stiffness_pred,log_area_weight_true,log_area_weight_pred"]
    for k, video in enumerate(dataset.videos):
        lines.append(
            f"{video.path.name},{video.fabric},{video.fan_level},"
            f"{result.truths['stiffness'][k]:.6g},{result.predictions['stiffness'][k]:.6g},"
            f"{result.truths['area_weight'][k]:.6g},{result.predictions['area_weight'][k]:.6g}"
        )
    atomic_write_text(out / "predictions.csv", "\n".join(lines) + "\n")
    if as_json:
        emit_json(summary)
        return
    err_console.print(
        f"Pearson R  stiffness {result.pearson_stiffness:.3f}   area weight {result.pearson_area_weight:.3f}"
        f"   ({result.n_videos} videos, {result.n_fabrics} fabrics, {embedder}); chart {chart}",
        markup=False,
        highlight=False,
    )


@handle_errors()
def dataset_bouman_cmd(
    out: Annotated[Path, typer.Option("--out", help="Dataset directory; re-running with the same settings resumes.")],
    fabrics: Annotated[int, typer.Option("--fabrics", help="Number of fabrics (3 videos each).")] = 30,
    frames: Annotated[int, typer.Option("--frames", help="Frames per video (25 fps).")] = 60,
    size: Annotated[int, typer.Option("--size", help="Video size in pixels (square).")] = 224,
    seed: Annotated[int, typer.Option("--seed", help="Seed: same seed, same dataset.")] = 0,
    as_json: JsonOpt = False,
) -> None:
    """Write a synthetic hanging-cloth dataset in the Bouman format (fabrics × fan levels W1–W3)."""
    from physinfer.outputs import OutputFolder
    from physinfer_hanging_cloth.data import VIDEO_DIR
    from physinfer_hanging_cloth.generate import (
        SETTINGS_FILE,
        TABLE_FILE,
        SyntheticSettings,
        generate_dataset,
    )

    outputs = (SETTINGS_FILE, TABLE_FILE, VIDEO_DIR)
    folder = OutputFolder(out, "dataset bouman", outputs, resumes=True, example="bouman")
    settings = SyntheticSettings(n_fabrics=fabrics, n_frames=frames, image_size=size, seed=seed)

    def progress(done: int, total: int) -> None:
        err_console.print(f"fabric {done}/{total} done", highlight=False)

    with folder.writing():  # the user's files stay theirs; the generator's own folder resumes
        summary = generate_dataset(out, settings, on_video=progress)
    if as_json:
        emit_json(summary)
        return
    err_console.print(
        f"wrote {summary['written']} videos ({summary['kept']} kept) and ground_truth.csv to {out}", markup=False, highlight=False
    )
