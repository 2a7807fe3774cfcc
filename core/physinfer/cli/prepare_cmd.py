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

import physinfer
from physinfer.cli.app import (
    EndOpt,
    JsonOpt,
    MirrorOpt,
    PluginOpt,
    StartOpt,
    emit_json,
    err_console,
    handle_errors,
)
from physinfer.cli.options import options_from_cli

# The options of ``prepare``, declared here so its signature reads as a list of settings.
_TargetOpt = Annotated[
    Path, typer.Option("--target", help="Video to prepare (mp4/mov/..., gif or image folder).")
]
_OutOpt = Annotated[
    Path,
    typer.Option(
        "--out",
        help="Prepared video (.mp4 or .gif); NAME.json and NAME_overlay.png go beside it.",
    ),
]
_OverwriteOpt = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Replace --out, NAME.json and NAME_overlay.png when they exist (by default any "
        "of them existing is refused before the video is read).",
    ),
]
_RoiOpt = Annotated[
    str | None,
    typer.Option(
        "--roi",
        help="x,y,w,h in the input's pixels: the region the subject moves in, instead of the one "
        "found (framed by the same rule).",
    ),
]
_FpsOpt = Annotated[
    float | None,
    typer.Option("--fps", help="Frame rate of --target, when the file does not say."),
]
_EmbedderOpt = Annotated[
    str | None,
    typer.Option(
        "--embedder",
        help="Embedder whose frame rate and input size to prepare for (default: the plugin's).",
    ),
]
_SizeOpt = Annotated[
    int | None,
    typer.Option("--size", help="Side of the square output in pixels (default: the embedder's)."),
]
_DurationOpt = Annotated[
    float | None,
    typer.Option("--duration", help="Seconds to keep from --start (default: to the end; or give --end)."),
]
_NoStabiliseOpt = Annotated[
    bool, typer.Option("--no-stabilise", help="Do not measure or remove camera shake.")
]
_NoFreezeOpt = Annotated[
    bool,
    typer.Option(
        "--no-freeze-background",
        help="Keep the noise and compression flicker of pixels that do not move (by default "
        "they are set to their temporal median, as a renderer draws a static background).",
    ),
]
_NoRenderEstimateOpt = Annotated[
    bool,
    typer.Option(
        "--no-render-estimate",
        help="Do not estimate the camera's render parameters (ζ) from the prepared clip.",
    ),
]


@handle_errors()
def prepare_cmd(
    plugin: PluginOpt,
    target: _TargetOpt,
    out: _OutOpt,
    overwrite: _OverwriteOpt = False,
    roi: _RoiOpt = None,
    fps: _FpsOpt = None,
    embedder: _EmbedderOpt = None,
    size: _SizeOpt = None,
    start: StartOpt = 0.0,
    end: EndOpt = None,
    duration: _DurationOpt = None,
    no_stabilise: _NoStabiliseOpt = False,
    no_freeze: _NoFreezeOpt = False,
    no_render_estimate: _NoRenderEstimateOpt = False,
    mirror: MirrorOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Find the moving subject in a video, steady the camera, crop it to the renderer's framing, resample."""
    given = dict(locals())
    with err_console.status(f"preparing {target.name}"):
        video = physinfer.prepare(plugin, options_from_cli(physinfer.PrepareOptions, given))
    if as_json:
        emit_json(video.to_dict())
        return
    for line in prepared_lines(video):
        err_console.print(line, highlight=False)
    err_console.print(
        f"wrote {video.paths['video']}, {video.paths['json']}, {video.paths['overlay']} (check the box)",
        markup=False,
        highlight=False,
    )


def prepared_lines(video: Any) -> list[str]:
    """What ``prepare`` prints (without ``--json``), as rich markup: the box found, the shake
    and the frames kept; the estimated render parameters; the warnings."""
    result, size = video.prepared, video.clip.size[0]
    x, y, w, h = result.box
    lines = [
        f"{result.roi_source} box x={x:.0f} y={y:.0f} w={w:.0f} h={h:.0f}; shake {result.shake_rms_px:.2f} px rms "
        f"({'removed, residual ' + format(result.residual_rms_px, '.2f') + ' px' if result.stabilised else 'left'}); "
        f"{result.clip.n_frames} frames at {result.fps_out:g} fps, {size}×{size}"
    ]
    if video.facing is not None and video.facing.mirrored:
        lines.append("mirrored: the video shows the subject the other way round from the renderer")
    if video.render_estimate is not None:
        lines.append(render_estimate_line(video.render_estimate))
    lines += [f"[yellow]warning:[/] {escape(warning)}" for warning in result.warnings]
    return lines


def render_estimate_line(estimate: dict[str, Any]) -> str:
    """One line: the estimated ζ with ± its standard error, as ``--render-set`` would take it."""
    if not estimate.get("values"):
        return f"render parameters not estimated: {estimate.get('note', '')}"
    parts = [f"{k}={v:g} (±{estimate['sd'][k]:.2g})" for k, v in estimate["values"].items()]
    return "estimated render parameters (pass with --render-set): " + ", ".join(parts)
