"""The options several ``physinfer`` commands declare alike (one declaration each, so ``refine``
and ``diagnose`` cannot drift), and how a command's parameters become the API's options object
(:func:`options_from_cli`, :data:`CLI_RENAMES`, :data:`CLI_ONLY`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from physinfer.parameters import parse_assignments
from physinfer.scene import parse_scene_set

JsonOpt = Annotated[bool, typer.Option("--json", help="Print exactly one JSON object on stdout.")]
PluginOpt = Annotated[
    str, typer.Option("--plugin", "-p", help="Phenomenon to use (see `physinfer plugins`).")
]
SeedOpt = Annotated[
    int, typer.Option("--seed", help="Seed of the optimizer and of every simulation.")
]
SelectTopOpt = Annotated[
    int,
    typer.Option(
        "--select-top",
        help="Re-simulate the M best trials under --select-seeds fresh seeds and keep the one with the lowest "
        "mean distance (0: the lowest logged distance; 4 suits chaotic phenomena such as the flag).",
    ),
]
SelectSeedsOpt = Annotated[
    int, typer.Option("--select-seeds", help="Fresh seeds per finalist of --select-top.")
]
FpsOpt = Annotated[
    float | None, typer.Option("--fps", help="Frame rate of --target if it cannot be read.")
]
OptimizerOpt = Annotated[str, typer.Option("--optimizer", help="ax, random, cma, or a plugin's.")]
EmbedderOpt = Annotated[
    str | None, typer.Option("--embedder", help="Embedder (default: the plugin's).")
]
WeightsOpt = Annotated[Path | None, typer.Option("--weights", help="Embedder weights file.")]
TorchDeviceOpt = Annotated[
    str | None, typer.Option("--device", help="torch device (default: cuda if present).")
]
RenderSetOpt = Annotated[
    list[str], typer.Option("--render-set", help="Render setting NAME=VALUE for simulations.")
]
DurationOpt = Annotated[
    float | None,
    typer.Option(
        "--duration",
        help="Seconds every simulation records (default: the plugin's; the flag's 2.4 s). Longer clips "
        "are for an embedder that reads more frames (--embedder-frames, or an SDN trained on them).",
    ),
]
FixOpt = Annotated[
    list[str],
    typer.Option(
        "--fix",
        help="Hold a parameter at a known value and leave it out of the search: NAME=VALUE, "
        "NAME may be a pattern such as 'bend_*' (repeatable).",
    ),
]
EmbedderFramesOpt = Annotated[
    int | None,
    typer.Option(
        "--embedder-frames",
        help="Frames a parameter-free embedder reads (the flag's spectral: default 30; e.g. 200 "
        "with --duration 8). An SDN's frames are set by its weights.",
    ),
]
SceneSetOpt = Annotated[
    list[str],
    typer.Option(
        "--scene-set",
        help="A known setting of the scene, not inferred: NAME=VALUE (repeatable). The flag: flag_length, "
        "flag_height, pole_height (m), pinning=hoist|corners; the hanging cloth: cloth_width, "
        "cloth_height (m), fan=W1|W2|W3. A wrong name lists the plugin's; `physinfer plugins --json` lists "
        "every phenomenon's (scene_settings).",
    ),
]
NoPrepareOpt = Annotated[
    bool,
    typer.Option(
        "--no-prepare",
        help="Use --target as it is. By default a video that is not square is framed as the renderer "
        "frames its subject, steadied and resampled first (as `physinfer prepare` does).",
    ),
]
RoiOpt = Annotated[
    str | None,
    typer.Option(
        "--roi",
        help="x,y,w,h: the region the subject moves in, in --target's pixels (instead of the one found).",
    ),
]
MirrorOpt = Annotated[
    bool | None,
    typer.Option(
        "--mirror/--no-mirror",
        help="--mirror: --target shows the subject the other way round from the renderer (a flag flying "
        "left): mirror it first. --no-mirror: use it as it is. Default: as read from the video.",
    ),
]
StartOpt = Annotated[
    float,
    typer.Option(
        "--start",
        help="Seconds of --target to leave out at its start (a hand letting go, a camera settling).",
    ),
]
EndOpt = Annotated[
    float | None,
    typer.Option("--end", help="Second of --target at which the part compared ends (default: its end)."),
]
BatchSizeOpt = Annotated[
    int,
    typer.Option(
        "--batch-size",
        help="Trials proposed per optimizer step and simulated as one batch (q); the flag simulates "
        "a batch in parallel threads. Same --steps budget, fewer optimizer rounds.",
    ),
]


DiagnoseBatchSizeOpt = Annotated[
    int | None,
    typer.Option(
        "--batch-size",
        help="Trials proposed per optimizer step of every stage and simulated as one batch (q). "
        "Default: the phenomenon's (2 for the pendulum example, whose trials are mostly Ax's GP "
        "fit; 1 for the flag).",
        show_default=False,
    ),
]


def parse_render_set(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE`` render settings; numbers become floats, ``true``/``false`` booleans."""
    out: dict[str, Any] = {}
    for name, raw in parse_assignments(items, "--render-set").items():
        low = raw.lower()
        if low in ("true", "false"):
            out[name] = low == "true"
            continue
        try:
            out[name] = float(raw)
        except ValueError:
            out[name] = raw
    return out


#: CLI parameters named otherwise in the API's options (``physinfer.api.options``).
CLI_RENAMES = {"effect": "effects", "set_": "set"}
#: CLI parameters that are not settings of the command.
CLI_ONLY = frozenset({"plugin", "as_json"})


def options_from_cli(kind: type, values: dict[str, Any]) -> Any:
    """The API's options object ``kind`` from a command's parameters (its ``locals()``).

    Repeated ``NAME=VALUE`` options become dicts (``--render-set``, ``--scene-set``) or
    tuples; every other parameter is a field of the same name (:data:`CLI_RENAMES` aside),
    so a CLI option without its field in the API fails at once (tests/core/test_library_api.py).
    """
    import dataclasses

    fields = {f.name for f in dataclasses.fields(kind)}
    settings: dict[str, Any] = {}
    for name, value in values.items():
        if name in CLI_ONLY:
            continue
        field_name = CLI_RENAMES.get(name, name)
        if field_name not in fields:
            raise TypeError(f"the CLI option {name!r} has no field in {kind.__name__}")
        if field_name == "render_set":
            value = parse_render_set(value)
        elif field_name == "scene_set":
            value = parse_scene_set(value)
        elif isinstance(value, list):
            value = tuple(value)
        settings[field_name] = value
    return kind(**settings)
