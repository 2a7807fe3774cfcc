"""Flag rendering speed: milliseconds per frame at steady state, 224×224, textured flag, background, pole.

Renders a synthetic waving 1.5 m × 1 m flag (:func:`physinfer_flag.flag_scene.waving_sheet`,
32 × 21 vertices like the cloth simulator's default grid) with :class:`FlagRenderer`.
The first call (EGL context, shader compilation, texture upload) is timed on its own.
Steady state is measured on whole ``render`` calls after it: ``ms_per_frame`` is
``(t(T frames) - t(1 frame)) / (T - 1)``, the cost of one more frame with the per-call
scene set-up taken out (that set-up is reported as ``setup_ms_per_call``), median over
repeats. A breakdown times the parts of a frame separately (vertex normals and upload,
OpenGL render and read-back, compositing over the background).

Usage::

    PYOPENGL_PLATFORM=egl python benchmarks/bench_render.py --frames 60 --repeats 5

Set ``LP_NUM_THREADS`` to pin Mesa llvmpipe's rasteriser threads (it uses every core by
default). Prints exactly one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from typing import Any

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

GOAL_MS_PER_FRAME = 15.0


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60, help="frames per render call (default: 60)")
    parser.add_argument("--repeats", type=int, default=5, help="timed render calls of each length (default: 5)")
    parser.add_argument("--size", type=int, default=224, help="square image size in pixels (default: 224)")
    parser.add_argument("--texture", default="netherlands", help="flag texture (default: netherlands)")
    parser.add_argument("--background", default="sky_cloudy", help="background (default: sky_cloudy)")
    parser.add_argument("--resolution", type=int, default=21, help="sheet vertices along the hoist (default: 21)")
    parser.add_argument("--pyrender-shader", action="store_true",
                        help="shade with pyrender's physically based mesh shader instead of the plugin's Lambert one")
    return parser.parse_args(argv)


def _timed(function: Any) -> float:
    start = time.perf_counter()
    function()
    return time.perf_counter() - start


def _gl_renderer_name(context: Any) -> str:
    """The OpenGL renderer string (e.g. ``llvmpipe (LLVM 15.0.6, 256 bits)``)."""
    from OpenGL import GL

    platform_ = context._renderer._platform
    platform_.make_current()
    try:
        return GL.glGetString(GL.GL_RENDERER).decode()
    finally:
        platform_.make_uncurrent()


def breakdown(renderer: Any, trajectory: Any, zeta: dict[str, Any]) -> dict[str, float]:
    """Median milliseconds of each part of a frame, timed separately on one scene."""
    import numpy as np

    from physinfer_flag.backgrounds import background_image
    from physinfer_flag.flag_scene import measure_flag
    from physinfer_flag.render_params import FlagRenderParams
    from physinfer_flag.sheet_render import DoubleSidedSheet, composite_over

    params = FlagRenderParams.from_mapping(zeta)
    sheet = DoubleSidedSheet(trajectory.faces, trajectory.vertices.shape[1])
    scene, flag = renderer._build_scene(trajectory, measure_flag(trajectory), sheet, params)
    context = renderer._context_for(params.size[1], params.size[0])
    background = background_image(params.background, params.size)
    context.render(scene, rgba=True)  # first render of this scene uploads the mesh
    parts: dict[str, list[float]] = {"normals_and_buffers": [], "upload": [], "gl_render": [], "composite": []}
    for positions in trajectory.vertices:
        start = time.perf_counter()
        buffers = sheet.buffers(positions)
        parts["normals_and_buffers"].append(time.perf_counter() - start)
        parts["upload"].append(_timed(lambda b=buffers: context.update_vertices(flag, *b)))
        start = time.perf_counter()
        rgba = context.render(scene, rgba=True)
        parts["gl_render"].append(time.perf_counter() - start)
        parts["composite"].append(_timed(lambda r=rgba: composite_over(r, background)))
    return {name: round(float(np.median(times)) * 1000.0, 3) for name, times in parts.items()}


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Time the renderer; returns the JSON record."""
    import physinfer_flag.render as flag_render
    from physinfer_flag.flag_scene import waving_sheet
    from physinfer_flag.render import FlagRenderer

    if args.pyrender_shader:
        flag_render.MESH_SHADERS = None  # contexts are created with pyrender's own shaders
    if args.frames < 2:
        raise SystemExit("--frames must be at least 2")
    zeta = {"image_size": args.size, "texture": args.texture, "background": args.background, "pole": True}
    long = waving_sheet(n_frames=args.frames, resolution=args.resolution, amplitude=0.15)
    short = waving_sheet(n_frames=1, resolution=args.resolution, amplitude=0.15)
    renderer = FlagRenderer()
    try:
        first_s = _timed(lambda: renderer.render(short, zeta))
        long_s, short_s = [], []
        for _ in range(args.repeats):
            short_s.append(_timed(lambda: renderer.render(short, zeta)))
            long_s.append(_timed(lambda: renderer.render(long, zeta)))
        t_long, t_short = statistics.median(long_s), statistics.median(short_s)
        ms_per_frame = (t_long - t_short) / (args.frames - 1) * 1000.0
        parts = breakdown(renderer, long, zeta)
        gl_name = _gl_renderer_name(renderer._context)
    finally:
        renderer.close()
    return {
        "benchmark": "bench_render",
        "ms_per_frame": round(ms_per_frame, 3),
        "frames_per_second": round(1000.0 / ms_per_frame, 1),
        "goal_ms_per_frame": GOAL_MS_PER_FRAME,
        "meets_goal": ms_per_frame <= GOAL_MS_PER_FRAME,
        "ms_per_frame_with_setup": round(t_long / args.frames * 1000.0, 3),
        "ms_per_frame_spread": [round(min(long_s) / args.frames * 1000, 3), round(max(long_s) / args.frames * 1000, 3)],
        "setup_ms_per_call": round((t_short * 1000.0) - ms_per_frame, 3),
        "first_call_s": round(first_s, 3),
        "breakdown_ms": parts,
        "image_size": [args.size, args.size],
        "frames": args.frames,
        "repeats": args.repeats,
        "vertices": int(long.vertices.shape[1]),
        "faces": int(long.faces.shape[0]),
        "texture": args.texture,
        "background": args.background,
        "shader": "pyrender mesh.frag (PBR)" if args.pyrender_shader else "lambert",
        "gl_renderer": gl_name,
        "lp_num_threads": os.environ.get("LP_NUM_THREADS"),
        "cpu_count": os.cpu_count(),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "machine": platform.machine(),
    }


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print one JSON object."""
    print(json.dumps(run(parse_args(argv))))


if __name__ == "__main__":
    main()
