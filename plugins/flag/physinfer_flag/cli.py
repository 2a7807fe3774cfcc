"""The flag plugin's commands: ``physinfer train`` and ``physinfer evaluate triplets|wind``.

Registered by :mod:`physinfer_flag.plugin` through ``physinfer_register_commands`` and
mounted by the host CLI. They follow the host's conventions (``physinfer.cli.app``):
``--json`` prints exactly one JSON object on stdout, progress goes to stderr, a user
mistake ends with one line on stderr (and ``{"error": ...}`` with ``--json``) and exit
status 2. This module is imported when the CLI is built, so only typer is imported at
module level; torch and the SDN package are imported inside the commands.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any

import typer

from physinfer.cli.app import emit_json, err_console, handle_errors, registry_and_infos
from physinfer.errors import UserInputError

#: The plugin whose phenomenon these commands train and evaluate.
PLUGIN = "flag"
#: Embedders ``physinfer evaluate triplets`` accepts (learned baselines have no triplet use).
TRIPLET_EMBEDDERS = ("sdn", "spectral")
#: Models ``physinfer evaluate wind`` accepts; all but ``sdn`` need no weights file.
WIND_EMBEDDERS = ("sdn", "spectral", "resnet18", "cnn_lstm")

PluginOpt = Annotated[str, typer.Option("--plugin", "-p", help="Phenomenon (only 'flag' trains an SDN).")]
DataOpt = Annotated[
    Path, typer.Option("--data", help="Dataset directory written by `physinfer dataset generate`.")
]
DeviceOpt = Annotated[
    str | None, typer.Option("--device", help="torch device (default: cuda if present, else cpu).")
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print exactly one JSON object on stdout.")]
ThreadsOpt = Annotated[
    int | None,
    typer.Option("--threads", help="torch CPU threads (default: $PHYSINFER_TORCH_THREADS, else 1)."),
]
ModelOpt = Annotated[
    Path | None,
    typer.Option(
        "--model",
        help="SDN weights file or `physinfer train` output directory (default: the shipped weights).",
    ),
]
FramesOpt = Annotated[
    int | None,
    typer.Option("--frames", help="Input frames at 25 fps of a baseline (an SDN's are in its weights)."),
]


def require_plugin(plugin: str, command: str) -> None:
    """Refuse a ``--plugin`` that does not provide ``command``.

    Args:
        plugin: The ``--plugin`` value.
        command: The command's registered name, e.g. ``"train"`` or ``"evaluate wind"``.

    Raises:
        UserInputError: naming the plugins that provide ``command``.
    """
    if plugin == PLUGIN:
        return
    registry, _ = registry_and_infos()
    entry = registry.entries["commands"].get(command)
    providers = sorted({entry.plugin}) if entry is not None else [PLUGIN]
    raise UserInputError(
        f"--plugin {plugin!r}: `physinfer {command}` is provided by the plugins "
        f"{', '.join(providers)}; use --plugin {providers[0]}"
    )


def require_dataset_dir(data: Path) -> None:
    """Refuse a ``--data`` that is not a directory (the loader explains the rest)."""
    if not data.is_dir():
        raise UserInputError(
            f"--data {data}: no such directory; create a dataset with "
            "`physinfer dataset generate --plugin flag --out DIR`"
        )


def resolve_model(model: Path | None, embedder: str, *, allowed: tuple[str, ...]) -> str | Path:
    """What the workflows take as ``model``: a weights path, or a baseline's name.

    Args:
        model: ``--model`` (weights file or training directory), or ``None``.
        embedder: ``--embedder``.
        allowed: The embedders this command accepts.

    Returns:
        ``model`` (or the shipped weights) for ``sdn``; the embedder's name otherwise.

    Raises:
        UserInputError: unknown embedder, ``--model`` given with a baseline, or no
            ``--model`` while the shipped weights are missing.
    """
    if embedder not in allowed:
        raise UserInputError(f"--embedder {embedder!r}: choose one of {', '.join(allowed)}")
    if embedder != "sdn":
        if model is not None:
            raise UserInputError(
                f"--model is for --embedder sdn; the {embedder} baseline has no weights file"
            )
        return embedder
    if model is not None:
        if not model.exists():
            raise UserInputError(
                f"--model {model}: no such file or directory; pass weights written by "
                "`physinfer train` (the .safetensors file or its --out directory)"
            )
        return model
    from physinfer_flag.sdn.weights import DEFAULT_WEIGHTS

    if not DEFAULT_WEIGHTS.is_file():
        raise UserInputError(
            f"no --model given and the shipped weights {DEFAULT_WEIGHTS} are missing; run "
            "`make pretrained`, pass --model, or use --embedder spectral"
        )
    return DEFAULT_WEIGHTS


def baseline_frontend(frames: int | None) -> Any:
    """The front-end settings of a baseline: the SDN's, with ``frames`` input frames."""
    import dataclasses

    from physinfer_flag.sdn.frontend import FrontEndConfig

    config = FrontEndConfig()
    return config if frames is None else dataclasses.replace(config, n_frames=frames)


def cpu_threads(threads: int | None) -> Any:
    """A context limiting torch to ``threads`` CPU threads (default: the refinement's rule).

    On a shared machine torch's spinning OpenMP threads wait on descheduled peers: on the
    2-core reference machine under load the front end ran 4–8× faster on 1 thread than on 2
    (see :mod:`physinfer.threads`).
    """
    from physinfer.threads import refinement_torch_threads, torch_threads

    check_positive("--threads", threads)
    return torch_threads(threads or refinement_torch_threads())


def check_positive(name: str, value: int | None) -> None:
    """Refuse a non-positive count option."""
    if value is not None and value < 1:
        raise UserInputError(f"{name} must be a positive integer, got {value}")


# ----------------------------------------------------------------------------- train


def _train_folder(out: Path) -> Any:
    """``train --out`` as an output folder of ``train`` (:mod:`physinfer.outputs`)."""
    from physinfer.outputs import OutputFolder

    # The names of physinfer_flag.sdn.training and .weights, without importing torch here.
    outputs = ("sdn.safetensors", "checkpoint.safetensors", "history.json")
    return OutputFolder(out, "train", outputs, resumes=True, example="sdn")


@handle_errors(kept="finished epochs are saved: run the same command again to continue")
def train_cmd(
    plugin: PluginOpt,
    data: DataOpt,
    out: Annotated[Path, typer.Option("--out", help="Output directory of the run (weights, checkpoint).")],
    epochs: Annotated[int | None, typer.Option("--epochs", help="Epochs in all (default 30).")] = None,
    positives: Annotated[
        str,
        typer.Option(
            "--positives",
            help="Positive pairs: 'simulation' (renders of one simulation, the paper) or "
            "'parameters' (all simulation seeds of one θ).",
        ),
    ] = "simulation",
    frames: Annotated[
        int | None, typer.Option("--frames", help="Input frames at 25 fps (default 30, the paper's).")
    ] = None,
    size: Annotated[
        int | None, typer.Option("--size", help="Input side in pixels (default 224, the paper's).")
    ] = None,
    batch_size: Annotated[int | None, typer.Option("--batch-size", help="Clips per batch (default 32).")] = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of initialisation and batch order.")] = 0,
    device: DeviceOpt = None,
    threads: ThreadsOpt = None,
    resume: Annotated[
        bool, typer.Option("--resume/--no-resume", help="Continue the run found in --out (default).")
    ] = True,
    progress: Annotated[bool, typer.Option("--progress/--no-progress", help="Progress bars on stderr.")] = True,
    as_json: JsonOpt = False,
) -> None:
    """Train the SDN on a dataset's train split; checkpoint each epoch, keep the best on val."""
    require_plugin(plugin, "train")
    folder = _train_folder(out)
    folder.check()  # the user's weights and history stay theirs; a run of train's own resumes
    require_dataset_dir(data)
    rule = {"simulation": "simulation", "parameters": "theta", "theta": "theta"}.get(positives)
    if rule is None:
        raise UserInputError(f"--positives {positives!r}: choose 'simulation' or 'parameters'")
    for name, value in (("--epochs", epochs), ("--frames", frames), ("--size", size)):
        check_positive(name, value)
    if batch_size is not None and batch_size < 2:
        raise UserInputError(f"--batch-size must be at least 2, got {batch_size}")

    import dataclasses

    from physinfer_flag.sdn.frontend import FrontEndConfig
    from physinfer_flag.sdn.network import SDNConfig
    from physinfer_flag.sdn.training import TrainConfig
    from physinfer_flag.sdn.workflows import train_from_directory

    frontend = FrontEndConfig()
    if frames is not None:
        frontend = dataclasses.replace(frontend, n_frames=frames)
    if size is not None:
        frontend = dataclasses.replace(frontend, size=size)
    train_config = TrainConfig(seed=seed)
    if batch_size is not None:
        train_config = dataclasses.replace(
            train_config, batch_size=batch_size, clips_per_label=min(4, batch_size)
        )
    from physinfer.locking import exclusive_directory

    started = time.perf_counter()
    with cpu_threads(threads), exclusive_directory(out):  # one writer of --out's checkpoint
        folder.claim()
        summary = train_from_directory(
            data,
            out,
            epochs=epochs,
            positives=rule,  # type: ignore[arg-type]
            model_config=SDNConfig(frontend=frontend),
            train_config=train_config,
            resume=resume,
            device=device,
            progress=progress,
        )
    summary.update(data=str(data), positives=rule, seconds=round(time.perf_counter() - started, 2))
    if as_json:
        emit_json(summary)
        return
    best = summary["best"]
    acc = best.get("val_triplet_accuracy")
    score = f"val triplet accuracy {acc:.3f}" if acc is not None else f"train loss {best['train_loss']:.4f}"
    err_console.print(
        f"{summary['epochs_completed']} epochs; best epoch {summary['best_epoch']} ({score})",
        highlight=False,
    )
    err_console.print(f"weights in {summary['weights']}", markup=False, highlight=False)


# -------------------------------------------------------------------------- evaluate


@handle_errors()
def evaluate_triplets_cmd(
    plugin: PluginOpt,
    data: DataOpt,
    model: ModelOpt = None,
    embedder: Annotated[
        str, typer.Option("--embedder", help="sdn (weights from --model) or spectral (no weights).")
    ] = "sdn",
    split: Annotated[str, typer.Option("--split", help="Split the triplets come from.")] = "test",
    n_triplets: Annotated[
        int | None, typer.Option("--n-triplets", help="Triplets (default: one per clip with a positive).")
    ] = None,
    positives: Annotated[
        str, typer.Option("--positives", help="What makes a positive: 'simulation' or 'parameters'.")
    ] = "simulation",
    frames: FramesOpt = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the triplet draw.")] = 0,
    device: DeviceOpt = None,
    threads: ThreadsOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Triplet accuracy of an embedding on a dataset split (the test split by default)."""
    require_plugin(plugin, "evaluate triplets")
    require_dataset_dir(data)
    check_positive("--n-triplets", n_triplets)
    check_positive("--frames", frames)
    rule = {"simulation": "simulation", "parameters": "theta", "theta": "theta"}.get(positives)
    if rule is None:
        raise UserInputError(f"--positives {positives!r}: choose 'simulation' or 'parameters'")
    name = resolve_model(model, embedder, allowed=TRIPLET_EMBEDDERS)
    if frames is not None and embedder == "sdn":
        raise UserInputError("--frames is for --embedder spectral; an SDN's input length is in its weights")

    from physinfer_flag.sdn.workflows import evaluate_triplets_in_directory

    started = time.perf_counter()
    with cpu_threads(threads):
        scores = evaluate_triplets_in_directory(
            data,
            name,
            split=split,
            n_triplets=n_triplets,
            positives=rule,  # type: ignore[arg-type]
            seed=seed,
            spectral_frontend=baseline_frontend(frames),
            device=device,
            progress=not as_json,
        )
    scores.update(embedder=embedder, data=str(data), seconds=round(time.perf_counter() - started, 2))
    if as_json:
        emit_json(scores)
        return
    err_console.print(
        f"triplet accuracy {scores['triplet_accuracy']:.3f} on {scores['n_triplets']} "
        f"{split} triplets ({embedder})",
        highlight=False,
    )


@handle_errors()
def evaluate_wind_cmd(
    plugin: PluginOpt,
    data: DataOpt,
    model: ModelOpt = None,
    embedder: Annotated[
        str,
        typer.Option(
            "--embedder",
            help="sdn (weights from --model), spectral, or a learned baseline trained here: "
            "resnet18, cnn_lstm.",
        ),
    ] = "sdn",
    target: Annotated[str, typer.Option("--target", help="The regressed parameter.")] = "wind_speed",
    head_epochs: Annotated[
        int, typer.Option("--head-epochs", help="Epochs of the regression head (and of a learned baseline).")
    ] = 30,
    frames: FramesOpt = None,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the head's initialisation and batches.")] = 0,
    device: DeviceOpt = None,
    threads: ThreadsOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Wind-speed regression: a head fitted on the train split, MSE and Acc@0.5 on test."""
    require_plugin(plugin, "evaluate wind")
    require_dataset_dir(data)
    check_positive("--head-epochs", head_epochs)
    check_positive("--frames", frames)
    name = resolve_model(model, embedder, allowed=WIND_EMBEDDERS)
    if frames is not None and embedder == "sdn":
        raise UserInputError("--frames is for the baselines; an SDN's input length is in its weights")

    from physinfer_flag.sdn.evaluation import RegressionConfig
    from physinfer_flag.sdn.workflows import evaluate_wind_in_directory

    started = time.perf_counter()
    with cpu_threads(threads):
        scores = evaluate_wind_in_directory(
            data,
            name,
            config=RegressionConfig(target=target, epochs=head_epochs, seed=seed, progress=not as_json),
            n_frames=frames,
            spectral_frontend=baseline_frontend(frames if embedder == "spectral" else None),
            device=device,
        )
    scores.update(
        embedder=embedder, target=target, data=str(data), seconds=round(time.perf_counter() - started, 2)
    )
    if as_json:
        emit_json(scores)
        return
    err_console.print(
        f"{target}: MSE {scores['mse']:.4g}, Acc@0.5 {scores['acc_at_0_5']:.3f} on {scores['n']} "
        f"test clips ({embedder})",
        highlight=False,
    )
