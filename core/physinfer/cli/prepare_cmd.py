"""``physinfer prepare``: frame a real video as the phenomenon's renderer frames its subject.

Registered as a command by physinfer's built-in plugin; the work is done by
:func:`physinfer.framing.prepare_clip`. Writes the prepared clip (``--out``), a JSON
beside it (``prepared.json``: the box, the framing square, the shake, the frame rates,
the frames kept, and the render parameters ζ estimated from the prepared clip by
:func:`physinfer.render_estimate.estimate_render_params` unless ``--no-render-estimate``) and an overlay PNG (``prepared_overlay.png``) to check the box by eye.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape

from physinfer.cli.app import JsonOpt, PluginOpt, emit_json, err_console, handle_errors


@handle_errors()
def prepare_cmd(
    plugin: PluginOpt,
    target: Annotated[
        Path, typer.Option("--target", help="Video to prepare (mp4/mov/..., gif or image folder).")
    ],
    out: Annotated[
        Path,
        typer.Option(
            "--out",
            help="Prepared video (.mp4 or .gif); NAME.json and NAME_overlay.png go beside it.",
        ),
    ],
    overwrite: Annotated[
        bool,
        typer.Option(
            "--overwrite",
            help="Replace --out, NAME.json and NAME_overlay.png when they exist (by default any "
            "of them existing is refused before the video is read).",
        ),
    ] = False,
    roi: Annotated[
        str | None,
        typer.Option(
            "--roi",
            help="x,y,w,h in the input's pixels: the region the subject moves in, instead of the one "
            "found (framed by the same rule).",
        ),
    ] = None,
    fps: Annotated[
        float | None,
        typer.Option("--fps", help="Frame rate of --target, when the file does not say."),
    ] = None,
    embedder: Annotated[
        str | None,
        typer.Option(
            "--embedder",
            help="Embedder whose frame rate and input size to prepare for (default: the plugin's).",
        ),
    ] = None,
    size: Annotated[
        int | None,
        typer.Option(
            "--size", help="Side of the square output in pixels (default: the embedder's)."
        ),
    ] = None,
    start: Annotated[float, typer.Option("--start", help="Seconds to trim from the start.")] = 0.0,
    duration: Annotated[
        float | None,
        typer.Option("--duration", help="Seconds to keep from --start (default: to the end)."),
    ] = None,
    no_stabilise: Annotated[
        bool, typer.Option("--no-stabilise", help="Do not measure or remove camera shake.")
    ] = False,
    no_freeze: Annotated[
        bool,
        typer.Option(
            "--no-freeze-background",
            help="Keep the noise and compression flicker of pixels that do not move (by default "
            "they are set to their temporal median, as a renderer draws a static background).",
        ),
    ] = False,
    no_render_estimate: Annotated[
        bool,
        typer.Option(
            "--no-render-estimate",
            help="Do not estimate the camera's render parameters (ζ) from the prepared clip.",
        ),
    ] = False,
    as_json: JsonOpt = False,
) -> None:
    """Find the moving subject in a video, steady the camera, crop it to the renderer's framing, resample."""
    given = dict(locals())
    from physinfer import api
    from physinfer.cli.options import options_from_cli

    with err_console.status(f"preparing {target.name}"):
        video = api.prepare(plugin, options_from_cli(api.PrepareOptions, given))
    if as_json:
        emit_json(video.to_dict())
        return
    result, size = video.prepared, video.clip.size[0]
    x, y, w, h = result.box
    err_console.print(
        f"{result.roi_source} box x={x:.0f} y={y:.0f} w={w:.0f} h={h:.0f}; shake {result.shake_rms_px:.2f} px rms "
        f"({'removed, residual ' + format(result.residual_rms_px, '.2f') + ' px' if result.stabilised else 'left'}); "
        f"{result.clip.n_frames} frames at {result.fps_out:g} fps, {size}×{size}",
        highlight=False,
    )
    if video.render_estimate is not None:
        err_console.print(render_estimate_line(video.render_estimate), highlight=False)
    for warning in result.warnings:
        err_console.print(f"[yellow]warning:[/] {escape(warning)}", highlight=False)
    err_console.print(
        f"wrote {video.paths['video']}, {video.paths['json']}, {video.paths['overlay']} (check the box)",
        markup=False,
        highlight=False,
    )


def render_estimate_line(estimate: dict[str, Any]) -> str:
    """One line: the estimated ζ with ± its standard error, as ``--render-set`` would take it."""
    if not estimate.get("values"):
        return f"render parameters not estimated: {estimate.get('note', '')}"
    parts = [f"{k}={v:g} (±{estimate['sd'][k]:.2g})" for k, v in estimate["values"].items()]
    return "estimated render parameters (pass with --render-set): " + ", ".join(parts)
