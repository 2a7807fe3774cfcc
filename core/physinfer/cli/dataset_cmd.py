"""``physinfer dataset``: generate a phenomenon's training dataset, locally or on Dask.

Mounted by the main app as ``physinfer dataset``. Heavy work is imported inside the
command, so ``physinfer --help`` stays fast. Progress and the closing summary go to
stderr; with ``--json`` exactly one JSON object goes to stdout. Errors take the CLI's one
path (:func:`physinfer.cli.app.handle_errors`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.markup import escape

from physinfer import plugins
from physinfer.cli.app import JsonOpt, SceneSetOpt, emit_json, handle_errors
from physinfer.errors import UserInputError
from physinfer.scene import (
    bind_scene,
    parse_scene_ranges,
    parse_scene_set,
    resolve_scene,
    scene_text,
)

if TYPE_CHECKING:
    from physinfer.datasets import DatasetPreset, GenerateResult

dataset_app = typer.Typer(
    help="Generate training datasets of simulated, rendered clips.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@dataset_app.callback()
def dataset_group() -> None:
    """Generate training datasets of simulated, rendered clips (see docs/datasets.md)."""


# The options of ``dataset generate``, declared here so its signature reads as a list of settings.
_PluginOpt = Annotated[
    str, typer.Option("--plugin", "-p", help="Phenomenon to simulate (see `physinfer plugins`).")
]
_OutOpt = Annotated[Path, typer.Option("--out", help="Dataset directory; re-running on it resumes.")]
_PresetOpt = Annotated[str, typer.Option("--preset", help="Size preset: cpu, paper, or the plugin's.")]
_SimsOpt = Annotated[
    str | None,
    typer.Option("--sims", help="Simulations: a total N (split like the preset) or TRAIN,VAL,TEST."),
]
_RendersPerSimOpt = Annotated[
    str | None, typer.Option("--renders-per-sim", help="Renders per simulation: M or TRAIN,VAL,TEST.")
]
_FramesOpt = Annotated[int | None, typer.Option("--frames", help="Frames per stored clip.")]
_SizeOpt = Annotated[str | None, typer.Option("--size", help="Stored clip size: N or HxW pixels.")]
_RgbOpt = Annotated[
    bool,
    typer.Option(
        "--rgb/--gray",
        help="Store RGB clips (the default: videos arrive in colour) or grayscale (a third of the disk; "
        "for the SDN's contrastive training, which reads grayscale).",
    ),
]
_SimsPerUnitOpt = Annotated[
    int | None, typer.Option("--sims-per-unit", help="Simulations batched per work unit (one shard).")
]
_SeedsPerThetaOpt = Annotated[
    int | None,
    typer.Option(
        "--seeds-per-theta",
        help="Consecutive simulations sharing one θ with different simulator seeds (default 1: "
        "every simulation its own θ); gives positives across seeds for `train --positives parameters`.",
    ),
]
_WorkersOpt = Annotated[
    int | None, typer.Option("--workers", help="Local worker processes (default: CPU count; 0: this process).")
]
_SchedulerOpt = Annotated[
    str | None, typer.Option("--scheduler", help="Dask scheduler address; its workers must share --out.")
]
_SeedOpt = Annotated[int, typer.Option("--seed", help="Dataset seed: same seed, same data.")]
_SceneRangeOpt = Annotated[
    list[str],
    typer.Option(
        "--scene-range",
        help="Vary a numeric scene setting across the dataset: NAME=LOW:HIGH (repeatable), drawn "
        "per simulation (log-uniform for positive ranges); an estimator trained on it takes the "
        "setting as an input (`--scene-set` at inference), e.g. flag_length=0.9:3.",
    ),
]
_VerifyOpt = Annotated[
    bool, typer.Option("--verify/--no-verify", help="On resume, check every checksum (reads all data).")
]


@dataset_app.command("generate")
@handle_errors(kept="finished units are saved: run the same command again to resume")
def generate_cmd(
    plugin: _PluginOpt,
    out: _OutOpt,
    preset: _PresetOpt = "cpu",
    sims: _SimsOpt = None,
    renders_per_sim: _RendersPerSimOpt = None,
    frames: _FramesOpt = None,
    size: _SizeOpt = None,
    rgb: _RgbOpt = True,
    sims_per_unit: _SimsPerUnitOpt = None,
    seeds_per_theta: _SeedsPerThetaOpt = None,
    workers: _WorkersOpt = None,
    scheduler: _SchedulerOpt = None,
    seed: _SeedOpt = 0,
    scene_set: SceneSetOpt = [],  # noqa: B006
    scene_range: _SceneRangeOpt = [],  # noqa: B006
    verify: _VerifyOpt = True,
    as_json: JsonOpt = False,
) -> None:
    """Simulate, render and store a dataset with train/val/test splits; resumes an interrupted run."""
    result = _generate(
        plugin=plugin,
        out=out,
        preset_name=preset,
        sims=sims,
        renders_per_sim=renders_per_sim,
        frames=frames,
        size=size,
        rgb=rgb,
        sims_per_unit=sims_per_unit,
        seeds_per_theta=seeds_per_theta,
        workers=workers,
        scheduler=scheduler,
        seed=seed,
        verify=verify,
        scene_set=scene_set,
        scene_range=scene_range,
    )
    summary = result.summary()
    _stderr(_summary_line(result))
    if as_json:
        emit_json(summary)


def _generate(
    *,
    plugin: str,
    out: Path,
    preset_name: str,
    sims: str | None,
    renders_per_sim: str | None,
    frames: int | None,
    size: str | None,
    rgb: bool,
    sims_per_unit: int | None,
    seeds_per_theta: int | None,
    workers: int | None,
    scheduler: str | None,
    seed: int,
    verify: bool,
    scene_set: list[str],
    scene_range: Sequence[str] = (),
) -> GenerateResult:
    from physinfer.datasets import generate_dataset, generator_for, parse_split_counts

    registry, _infos = plugins.load_registry()
    phenomenon = registry.phenomenon(plugin)
    scene, ranges = _scene_and_ranges(phenomenon, scene_set, scene_range)
    generator = generator_for(bind_scene(phenomenon, scene), scene_ranges=ranges)
    chosen = _choose_preset(generator.presets(), preset_name, plugin)
    chosen = chosen.with_overrides(
        sims=parse_split_counts(sims, "--sims") if sims is not None else None,
        renders_per_sim=(
            parse_split_counts(renders_per_sim, "--renders-per-sim") if renders_per_sim is not None else None
        ),
        sims_per_unit=sims_per_unit,
        n_frames=frames,
        size=_parse_size(size) if size is not None else None,
        channels=3 if rgb else 1,
        seeds_per_theta=seeds_per_theta,
    )
    _stderr(_plan_line(plugin, chosen, scene, ranges, out, workers, scheduler))
    with _RichProgress() as progress:
        return generate_dataset(
            generator,
            out,
            preset=chosen,
            seed=seed,
            workers=workers,
            scheduler=scheduler,
            verify=verify,
            progress=progress,
        )


def _scene_and_ranges(
    phenomenon: Any, scene_set: list[str], scene_range: Sequence[str]
) -> tuple[Any, dict[str, tuple[float, float]]]:
    """The scene ``--scene-set`` gives and the settings ``--scene-range`` varies; refused when
    a setting is given both ways."""
    given = parse_scene_set(scene_set)
    scene = resolve_scene(phenomenon, given)
    ranges = parse_scene_ranges(phenomenon, scene_range)
    both = sorted(set(ranges) & set(given))
    if both:
        raise UserInputError(f"{', '.join(both)}: given both --scene-set and --scene-range; give one")
    return scene, ranges


def _plan_line(
    plugin: str,
    chosen: DatasetPreset,
    scene: Any,
    ranges: dict[str, tuple[float, float]],
    out: Path,
    workers: int | None,
    scheduler: str | None,
) -> str:
    """What is about to be made, of what, where, and by whom (printed before the work starts)."""
    sharing = f", {chosen.seeds_per_theta} seeds per θ" if chosen.seeds_per_theta > 1 else ""
    where = f"Dask at {scheduler}" if scheduler else f"{workers if workers is not None else 'all CPUs as'} workers"
    return (
        f"{plugin}: {chosen.sims.total} simulations, {chosen.renders.total} renders "
        f"({_splits_text(chosen)}), clips {'×'.join(map(str, chosen.clip.shape))} at {chosen.clip.fps:g} fps{sharing}"
        f"{f', scene {scene_text(scene)}' if scene else ''}"
        f"{''.join(f', {k} {a:g}..{b:g}' for k, (a, b) in ranges.items())} "
        f"→ {out} ({where})"
    )


def _choose_preset(presets: dict[str, DatasetPreset] | Any, name: str, plugin: str) -> DatasetPreset:
    if name not in presets:
        raise UserInputError(
            f"unknown preset {name!r} for {plugin!r}; choose one of {', '.join(sorted(presets))}"
        )
    return presets[name]


def _parse_size(text: str) -> tuple[int, int]:
    parts = text.lower().replace("×", "x").split("x")
    try:
        values = [int(p) for p in parts]
    except ValueError:
        raise UserInputError(f"--size expects N or HxW in pixels, got {text!r}") from None
    if len(values) == 1:
        values = values * 2
    if len(values) != 2 or min(values) < 1:
        raise UserInputError(f"--size expects N or HxW with positive sizes, got {text!r}")
    return values[0], values[1]


def _splits_text(preset: DatasetPreset) -> str:
    from physinfer.datasets import SPLITS

    return ", ".join(f"{s} {preset.sims[s]}/{preset.renders[s]}" for s in SPLITS)


def _summary_line(result: GenerateResult) -> str:
    units = (
        f"units: {result.units_generated} generated ({result.units_regenerated} damaged, regenerated), "
        f"{result.units_skipped} already complete"
    )
    failed = f"; {len(result.failed_sims)} simulations failed and were skipped" if result.failed_sims else ""
    return (
        f"[bold]{sum(result.renders.values())} renders[/] in {escape(str(result.root))} "
        f"({result.bytes / 1e9:.2f} GB); wrote {result.renders_generated} in {result.seconds:.1f} s "
        f"({result.renders_per_minute:.1f} renders/min); {units}{failed}"
    )


def _stderr(text: str) -> None:
    from rich.console import Console

    Console(stderr=True, highlight=False).print(text)


class _RichProgress:
    """A rich progress bar with ETA on stderr, fed by the engine's progress events."""

    def __init__(self) -> None:
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self._progress = Progress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=Console(stderr=True),
        )
        self._task: Any = None

    def __enter__(self) -> _RichProgress:
        self._progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._progress.stop()

    def start(self, phase: str, total: int, done: int = 0) -> None:
        """Begin a phase: ``verify`` counts units, ``generate`` counts renders."""
        label = {"verify": "checking units", "generate": "renders"}.get(phase, phase)
        if self._task is not None:
            self._progress.update(self._task, visible=False)
        self._task = self._progress.add_task(label, total=total, completed=done)

    def advance(self, n: int) -> None:
        """Advance the current phase by ``n``."""
        self._progress.advance(self._task, n)
