"""``physinfer render``: draw a given trajectory with a phenomenon's renderer.

The trajectory comes from a file (:func:`physinfer.meshio.load_trajectory`: physinfer's
NPZ or another simulator's per-frame OBJ meshes), so other simulators can be compared
with physinfer through the same camera and render parameters ζ. Registered as a command
by physinfer's built-in plugin; works for every phenomenon whose renderer draws a
:class:`~physinfer.types.Trajectory`.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Any

import typer

from physinfer.cli.app import (
    JsonOpt,
    PluginOpt,
    SceneSetOpt,
    emit_json,
    err_console,
    handle_errors,
    parse_render_set,
)
from physinfer.errors import UserInputError


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
    from physinfer.cli.app import registry_and_infos
    from physinfer.meshio import load_trajectory
    from physinfer.video import write_video

    if out.suffix.lower() not in (".mp4", ".gif"):
        raise UserInputError(f"--out {out}: write a .mp4 or .gif file")
    if out.is_dir():
        raise UserInputError(f"--out {out} is a directory; give a file name")
    from physinfer.scene import bind_scene, parse_scene_set, resolve_scene

    registry, _ = registry_and_infos()
    phenomenon = registry.phenomenon(plugin)
    scene = resolve_scene(phenomenon, parse_scene_set(scene_set))
    renderer = bind_scene(phenomenon, scene).make_renderer()
    # ζ and the file are checked before any rendering, as simulate checks ζ before simulating.
    zeta = renderer.check_render_params(
        {**renderer.default_render_params, **parse_render_set(render_set)}
    )
    loaded = load_trajectory(trajectory, fps)
    t0 = time.perf_counter()
    try:
        clip = renderer.render(loaded, zeta)
    finally:
        renderer.close()
    render_s = time.perf_counter() - t0
    write_video(out, clip)
    result: dict[str, Any] = {
        "plugin": plugin,
        "trajectory": str(trajectory),
        "source": "obj" if trajectory.is_dir() else "npz",
        "n_frames": loaded.n_frames,
        "n_vertices": int(loaded.vertices.shape[1]),
        "n_faces": int(loaded.faces.shape[0]),
        "fps": loaded.fps,
        "uv": "uv" in loaded.extras,
        "render_params": zeta,
        **({"scene": scene} if scene is not None else {}),
        "render_s": render_s,
        "video": str(out),
    }
    if as_json:
        emit_json(result)
    else:
        err_console.print(
            f"rendered {loaded.n_frames} frames at {loaded.fps:g} fps to {out}", highlight=False
        )
