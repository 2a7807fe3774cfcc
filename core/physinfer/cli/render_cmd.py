"""``physinfer render``: draw a given trajectory with a phenomenon's renderer.

The trajectory comes from a file (:func:`physinfer.meshio.load_trajectory`: physinfer's
NPZ or another simulator's per-frame OBJ meshes), so other simulators can be compared
with physinfer through the same camera and render parameters ζ. Registered as a command
by physinfer's built-in plugin; works for every phenomenon whose renderer draws a
:class:`~physinfer.types.Trajectory`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

import physinfer
from physinfer.cli.app import (
    JsonOpt,
    PluginOpt,
    SceneSetOpt,
    emit_json,
    err_console,
    handle_errors,
)
from physinfer.cli.options import options_from_cli


@handle_errors()
def render_cmd(
    plugin: PluginOpt,
    trajectory: Annotated[
        Path,
        typer.Option(
            "--trajectory",
            help="Trajectory NPZ (`simulate --trajectory-out`, a run's best_trajectory.npz) or a folder of "
            "per-frame .obj meshes, in physinfer's frame (metres, z up, wind along +x).",
        ),
    ],
    out: Annotated[Path, typer.Option("--out", help="Video to write (.mp4 or .gif).")],
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="Replace --out when it exists (by default an existing file is refused before "
            "anything is rendered).",
        ),
    ] = False,
    fps: Annotated[
        float | None,
        typer.Option(
            "--fps",
            help="Frame rate of the trajectory: required for OBJ folders, overrides an NPZ's.",
        ),
    ] = None,
    render_set: Annotated[
        list[str], typer.Option("--render-set", help="Render setting NAME=VALUE (repeatable).")
    ] = [],  # noqa: B006
    scene_set: SceneSetOpt = [],  # noqa: B006
    as_json: JsonOpt = False,
) -> None:
    """Render a trajectory file (physinfer NPZ or a folder of OBJ meshes) to a video.

    The renderer frames the sheet from the trajectory's own size; of the scene settings, the
    flag's ``pole_height`` draws the pole of a trajectory that carries none (OBJ meshes).
    """
    given = dict(locals())
    rendering = physinfer.render(plugin, options_from_cli(physinfer.RenderOptions, given))
    if as_json:
        emit_json(rendering.to_dict())
    else:
        err_console.print(
            f"rendered {rendering.loaded.n_frames} frames at {rendering.loaded.fps:g} fps to {out}",
            markup=False,
            highlight=False,
        )
