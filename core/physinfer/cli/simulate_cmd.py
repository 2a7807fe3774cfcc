"""``physinfer simulate``: one simulation, rendered to a video and/or saved as a trajectory."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

import physinfer
from physinfer.cli.common import emit_json, handle_errors
from physinfer.cli.options import (
    DurationOpt,
    JsonOpt,
    PluginOpt,
    SceneSetOpt,
    SeedOpt,
    options_from_cli,
)
from physinfer.console import err_console
from physinfer.errors import UserInputError


@handle_errors()
def simulate_cmd(
    plugin: PluginOpt,
    set_: Annotated[
        list[str], typer.Option("--set", help="Parameter value NAME=VALUE (repeatable).")
    ] = [],  # noqa: B006
    effect: Annotated[
        list[str], typer.Option("--effect", help="Switch an effect in (repeatable).")
    ] = [],  # noqa: B006
    render_set: Annotated[
        list[str], typer.Option("--render-set", help="Render setting NAME=VALUE (repeatable).")
    ] = [],  # noqa: B006
    seed: SeedOpt = 0,
    duration: DurationOpt = None,
    scene_set: SceneSetOpt = [],  # noqa: B006
    out: Annotated[
        Path | None, typer.Option("--out", help="Video to write (.mp4 or .gif).")
    ] = None,
    trajectory_out: Annotated[
        Path | None, typer.Option("--trajectory-out", help="Trajectory to write (*.npz).")
    ] = None,
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="Replace --out and --trajectory-out when they exist (by default an existing file "
            "is refused before anything is simulated).",
        ),
    ] = False,
    as_json: JsonOpt = False,
) -> None:
    """Run one simulation and render it to a video (and/or save the trajectory)."""
    given = dict(locals())
    options = options_from_cli(physinfer.SimulateOptions, given)
    if out is None and trajectory_out is None:
        raise UserInputError("nothing to write: give --out VIDEO and/or --trajectory-out FILE.npz")
    sim = physinfer.simulate(plugin, options, render=out is not None)
    if as_json:
        emit_json(sim.to_dict())
    else:
        written = ", ".join(str(p) for p in (out, trajectory_out) if p)
        err_console.print(f"wrote {written}", markup=False, highlight=False, soft_wrap=True)  # a path stays whole
