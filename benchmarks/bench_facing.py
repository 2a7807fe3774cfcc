"""Does a phenomenon read which way round a video shows its subject (``Phenomenon.facing``)?

Draws ``--targets`` θ uniformly (the wind, for the flag, uniformly in ``--wind``), a random
look per target (``Renderer.sample_render_params``), simulates and renders each, passes it
through the camera model users' videos are trained against (:mod:`physinfer.as_given`: blur,
noise, white balance; with ``--wide`` pasted at a random place into a frame that much wider),
and reads the side of the clip and of its mirror. A render is the renderer's way round, so a
reading of at least 1 is right, under -1 wrong, and between them "cannot tell" (the video is
then used as it is). Prints one JSON object: per target θ's first parameters and the two
readings, and the counts.

Usage::

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_facing.py --plugin flag --targets 40 --seed 99
"""

from __future__ import annotations

import argparse
import json

import numpy as np


def main() -> None:
    from physinfer.as_given import CameraModel, camera
    from physinfer.plugins import load_registry
    from physinfer.types import Clip

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plugin", default="flag")
    parser.add_argument("--targets", type=int, default=40)
    parser.add_argument("--seed", type=int, default=99)
    parser.add_argument("--wind", type=float, nargs=2, default=(0.3, 9.5), help="the flag's wind range (m/s)")
    parser.add_argument("--wide", type=float, default=1.8, help="frame width over the render's (1: as rendered)")
    args = parser.parse_args()
    phenomenon = load_registry()[0].phenomenon(args.plugin)
    if phenomenon.facing is None:
        raise SystemExit(f"{args.plugin} reads no side (Phenomenon.facing is None)")
    simulator, renderer = phenomenon.make_simulator([]), phenomenon.make_renderer()
    rng = np.random.default_rng(args.seed)
    rows = []
    for index in range(args.targets):
        theta = phenomenon.parameter_space.sample(rng, 1)[0]
        if "wind_speed" in theta:
            theta["wind_speed"] = float(rng.uniform(*args.wind))
        clip = renderer.render(simulator.simulate(theta, seed=args.seed * 1000 + index), renderer.sample_render_params(rng))
        frames = _widened(camera(clip, CameraModel().draw(rng), rng).frames, args.wide, rng)
        reading = float(phenomenon.facing(Clip(frames, clip.fps)))
        mirrored = float(phenomenon.facing(Clip(np.ascontiguousarray(frames[:, :, ::-1]), clip.fps)))
        rows.append({"theta": {k: round(v, 3) for k, v in list(theta.items())[:3]}, "reading": reading, "mirrored": mirrored})
    readings = np.array([r["reading"] for r in rows] + [-r["mirrored"] for r in rows])
    print(json.dumps({
        "plugin": args.plugin, "targets": args.targets, "seed": args.seed, "wide": args.wide,
        "right": int((readings[: len(rows)] >= 1).sum()),
        "cannot_tell": int((np.abs(readings[: len(rows)]) < 1).sum()),
        "wrong": int((readings[: len(rows)] <= -1).sum()),
        "mirrors_read_exactly_opposite": bool(np.allclose(readings[: len(rows)], readings[len(rows):], atol=1e-3)),
        "rows": rows,
    }, indent=1))  # fmt: skip


def _widened(frames: np.ndarray, factor: float, rng: np.random.Generator) -> np.ndarray:
    """``frames`` pasted at a random column into a frame ``factor`` times as wide, filled
    with their mean colour (a plain wall)."""
    if factor <= 1.0:
        return frames
    count, height, width = frames.shape[:3]
    wide = np.empty((count, height, int(round(width * factor)), 3), np.uint8)
    wide[:] = frames.mean(axis=(0, 1, 2)).astype(np.uint8)
    left = int(rng.integers(0, wide.shape[2] - width + 1))
    wide[:, :, left : left + width] = frames
    return wide


if __name__ == "__main__":
    main()
