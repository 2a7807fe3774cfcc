"""A plugin's amortized posterior on targets as users give them (issue 44).

Targets: for the flag, wind speed uniform over 1–9.5 m/s and area weight over 0.10–0.17
kg/m², the other parameters at their defaults; for another plugin (``--plugin``), every
parameter drawn from its prior. The scene is the default or ``--scene-set``'s, the camera the
default; seeds no dataset uses (θ from ``700_000 + i``, the simulation from ``800_000 + i``).
Each is simulated and rendered as ``physinfer simulate --out target.mp4`` does (H.264 CRF 18),
and inferred as ``physinfer infer --target target.mp4 [--scene-set ...]`` does (read,
conditioned, embedded, 2,000 samples; no predictive check). ``--degraded`` adds a second
condition per target (the flag only): the render composited over a photographic background (a frame of a
real video from ``--photo``, else a procedural photo-like one), sensor noise of 3 grey levels
and H.264 at CRF 35. ``--scene-range NAME=LO:HI`` draws that scene value per target,
log-uniformly (seeded from ``900_000 + i``), and tells infer the drawn value (a flag's size).
``--render-set-told`` tells infer the camera and light the targets were rendered with (the
renderer's default ζ, its numeric settings, as ``infer --render-set``): an estimator told the
camera (``posterior train --told-camera``) needs them, and the shipped one for them is chosen;
``--told NAME=VALUE`` tells a value other than the targets' (a camera told wrongly).
``--duration SECONDS`` records longer targets (their first frames are the default-length
targets' own), for which ``infer`` chooses a shipped estimator of longer clips when there is one.

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_posterior_targets.py --targets 100 \\
        --posterior plugins/flag/physinfer_flag/data/posterior_default.safetensors --degraded --rows rows.jsonl
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_posterior_targets.py --plugin hanging_cloth --targets 50
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_posterior_targets.py --targets 100 --render-set-told \\
        --posterior plugins/flag/physinfer_flag/data/posterior_camera.safetensors --rows rows.jsonl

Prints one JSON object: per condition and per drawn parameter the 90 % coverage, the median
error of the posterior median and the median 90 % width (the flag's wind also under its old
names ``wind_coverage90``, ...), the targets flagged as extrapolated, the refusals and the
median seconds of ``infer`` after start-up; per-target rows go to ``--rows`` (appended, so a
run can resume with ``--first``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

THETA_SEED, SIM_SEED, SCENE_SEED = 700_000, 800_000, 900_000
#: Plugins whose targets vary only some parameters, uniformly over these boxes (the others at
#: their defaults); any other plugin's targets are drawn from the whole prior.
TARGET_BOXES: dict[str, dict[str, tuple[float, float]]] = {
    "flag": {"wind_speed": (1.0, 9.5), "area_weight": (0.10, 0.17)},
}


def drawn_parameters(plugin: str, space: Any) -> list[str]:
    """The parameters a plugin's targets vary (and the summary reports)."""
    return list(TARGET_BOXES.get(plugin, {}) or space.names)


def make_target(pipeline: Any, plugin: str, index: int) -> tuple[dict[str, float], Any]:
    """θ of target ``index`` and its trajectory."""
    rng = np.random.default_rng(THETA_SEED + index)
    space = pipeline.simulator.parameter_space
    box = TARGET_BOXES.get(plugin)
    if box:
        theta = space.complete({name: float(rng.uniform(*bounds)) for name, bounds in box.items()})
    else:
        theta = {k: float(v) for k, v in space.sample(rng, 1)[0].items()}
    return theta, pipeline.simulator.simulate(theta, seed=SIM_SEED + index)


def parse_ranges(items: list[str]) -> dict[str, tuple[float, float]]:
    """``["flag_length=0.9:3"]`` → ``{"flag_length": (0.9, 3.0)}``."""
    ranges = {}
    for item in items:
        name, _, bounds = item.partition("=")
        low, _, high = bounds.partition(":")
        ranges[name.strip()] = (float(low), float(high))
    return ranges


def draw_scene(ranges: dict[str, tuple[float, float]], index: int) -> dict[str, float]:
    """Target ``index``'s values of the ranged scene settings (log-uniform)."""
    rng = np.random.default_rng(SCENE_SEED + index)
    return {name: float(np.exp(rng.uniform(np.log(lo), np.log(hi)))) for name, (lo, hi) in ranges.items()}


def photo(path: str | None, size: tuple[int, int], seed: int) -> np.ndarray:
    """``(H, W, 3)`` a photographic background: the middle frame of ``path``, centre-cropped
    and resized, or a procedural photo-like image."""
    from physinfer.video import read_video

    if path:
        clip = read_video(path, max_frames=200)
        return _resize_rgb(clip.frames[len(clip.frames) // 2], size)
    from real_conditions import photo_background

    return photo_background(size[0], size[1], seed)


def _resize_rgb(frame: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    from PIL import Image

    h, w = frame.shape[:2]
    side = min(h, w)
    crop = frame[(h - side) // 2 : (h - side) // 2 + side, (w - side) // 2 : (w - side) // 2 + side]
    return np.asarray(Image.fromarray(crop).resize((size[1], size[0]), Image.Resampling.BILINEAR))


def degraded(pipeline: Any, trajectory: Any, background: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The flag over ``background``, with sensor noise (3 grey levels), before H.264."""
    from real_conditions import composite, render_rgba, sensor_noise

    zeta = dict(pipeline.renderer.default_render_params)
    rgba = render_rgba(pipeline.renderer, trajectory, zeta)
    frames = composite(rgba, background, (0, 0), None)
    return sensor_noise(frames, rng, sigma=3.0)


def told_camera(renderer: Any) -> dict[str, float]:
    """The numeric render settings of the renderer's default ζ, which the targets are rendered
    with: what a user who knows the camera passes as ``--render-set``."""
    return {
        k: float(v) for k, v in renderer.default_render_params.items()
        if isinstance(v, (int, float)) and not isinstance(v, bool)
    }  # fmt: skip


def infer_row(
    registry: Any, plugin: str, path: Path, posterior: Path | None, theta: dict[str, float],
    names: list[str], scene: dict[str, Any], out: Path, render_set: dict[str, float] | None = None,
) -> dict[str, Any]:
    """``physinfer infer --target path`` (no predictive check): each drawn parameter's median,
    error, 90 % width and whether its 90 % interval covers the truth."""
    from physinfer.conditioning import Conditioning
    from physinfer.posterior.infer_workflow import infer

    t0 = time.perf_counter()
    report = infer(
        registry, plugin=plugin, out=out, target_path=path, posterior=posterior, n_samples=2000,
        conditioning=Conditioning(), check=False, scene_set=scene or None,
        render_set=render_set or None,
    )  # fmt: skip
    params = {}
    for name in names:
        marginal, truth = report.marginals[name], theta[name]
        low, high = marginal["ci90"]
        params[name] = {
            "median": marginal["median"], "error": abs(marginal["median"] - truth),
            "covered90": bool(low <= truth <= high), "width90": high - low, "label": marginal["label"],
        }  # fmt: skip
    return {
        "params": params,
        "extrapolating": bool((report.inputs or {}).get("extrapolating")),
        "worst_sd": (report.inputs or {}).get("worst_sd"),  # the input check's farthest dimension
        "estimator": Path(report.estimator).name,
        "seconds_after_start_up": time.perf_counter() - t0 - report.seconds.get("start_up", 0.0),
        "seconds": time.perf_counter() - t0,
    }


def _parameter_summary(rows: list[dict[str, Any]], name: str) -> dict[str, float]:
    values = [r["params"][name] for r in rows]
    return {
        "coverage90": round(float(np.mean([v["covered90"] for v in values])), 3),
        "median_error": round(float(np.median([v["error"] for v in values])), 4),
        "median_width90": round(float(np.median([v["width90"] for v in values])), 4),
    }


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for condition in sorted({r["condition"] for r in rows}):
        rs = [r for r in rows if r["condition"] == condition and "params" in r]
        if not rs:
            continue
        per_parameter = {name: _parameter_summary(rs, name) for name in rs[0]["params"]}
        summary: dict[str, Any] = {"targets": len(rs), "parameters": per_parameter}
        if "wind_speed" in per_parameter:  # the names earlier tables quote
            wind = per_parameter["wind_speed"]
            summary.update(wind_coverage90=wind["coverage90"], wind_median_error=wind["median_error"],
                           wind_median_width90=wind["median_width90"])
        summary.update(
            extrapolating=int(sum(r["extrapolating"] for r in rs)),
            max_worst_sd=max((r["worst_sd"] for r in rs if r.get("worst_sd") is not None), default=None),
            median_seconds_after_start_up=round(float(np.median([r["seconds_after_start_up"] for r in rs])), 2),
            refused=sum(1 for r in rows if r["condition"] == condition and "refused" in r),
        )
        out[condition] = summary
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--plugin", default="flag")
    parser.add_argument("--scene-set", action="append", default=[], metavar="NAME=VALUE",
                        help="the targets' scene (as `physinfer simulate --scene-set`), told to infer too")
    parser.add_argument("--scene-range", action="append", default=[], metavar="NAME=LO:HI",
                        help="draw this scene value per target (log-uniform), told to infer too")
    parser.add_argument("--targets", type=int, default=10)
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--posterior", type=Path, action="append", default=None,
                        help="estimator file (default: the shipped one); repeat to compare several on the same targets")
    parser.add_argument("--degraded", action="store_true",
                        help="also: photo background, noise, H.264 CRF 35 (the flag's renderer only)")
    parser.add_argument("--render-set-told", action="store_true",
                        help="tell infer the targets' camera and light (the renderer's default ζ), as --render-set")
    parser.add_argument("--told", action="append", default=[], metavar="NAME=VALUE",
                        help="with --render-set-told: tell this value instead of the targets' own (a wrong camera)")
    parser.add_argument("--photo", default=None, help="a video whose middle frame is the background")
    parser.add_argument("--duration", type=float, default=None,
                        help="seconds each target records (as `physinfer simulate --duration`; default: the plugin's)")
    parser.add_argument("--rows", type=Path, default=None, help="append per-target rows (JSON lines)")
    parser.add_argument("--summarise", action="store_true", help="only summarise --rows")
    args = parser.parse_args()
    if args.degraded and args.plugin != "flag":
        parser.error("--degraded composites the flag renderer's RGBA renders; drop it for other plugins")
    if args.summarise:
        rows = [json.loads(line) for line in args.rows.read_text().splitlines() if line.strip()]
        print(json.dumps({"summary": summarise(rows), "rows": len(rows)}, indent=1))
        return

    from physinfer.evaluation import build_pipeline
    from physinfer.parameters import parse_assignments
    from physinfer.plugins import load_registry
    from physinfer.scene import parse_scene_set
    from physinfer.video import write_video

    registry = load_registry()[0]
    scene = parse_scene_set(args.scene_set)
    ranges = parse_ranges(args.scene_range)
    wrong = {name: float(value) for name, value in parse_assignments(args.told, "--told").items()}
    pipeline = build_pipeline(registry, args.plugin, embedder="", scene_set=scene or None, duration_s=args.duration)
    names = drawn_parameters(args.plugin, pipeline.simulator.parameter_space)
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-targets-") as tmp:
        folder = Path(tmp)
        for i in range(args.first, args.first + args.targets):
            if ranges:  # this target's scene: its own simulator and renderer
                pipeline.renderer.close()
                target_scene = {**scene, **draw_scene(ranges, i)}
                pipeline = build_pipeline(
                    registry, args.plugin, embedder="", scene_set=target_scene, duration_s=args.duration
                )  # fmt: skip
            else:
                target_scene = scene
            theta, trajectory = make_target(pipeline, args.plugin, i)
            clip = pipeline.renderer.render(trajectory, pipeline.renderer.default_render_params)
            cases = {"mp4 (as simulate writes it)": write_video(folder / f"t{i}.mp4", clip)}
            if args.degraded:
                rng = np.random.default_rng(THETA_SEED + i)
                h, w = clip.frames.shape[1:3]
                background = photo(args.photo, (h + 16, w + 16), i)  # composite's 8-px margin
                frames = degraded(pipeline, trajectory, background, rng)
                cases["photo background + noise + CRF 35"] = write_video(folder / f"d{i}.mp4", frames, clip.fps, crf=35)
            for (condition, path), posterior in product(cases.items(), args.posterior or [None]):
                label = condition if not args.posterior or len(args.posterior) == 1 else f"{posterior.name}: {condition}"
                row: dict[str, Any] = {"target": i, "condition": label, "theta": {k: theta[k] for k in names}}
                if ranges:
                    row["scene"] = {k: target_scene[k] for k in ranges}
                told = {**told_camera(pipeline.renderer), **wrong} if args.render_set_told else None
                if told:
                    row["render_set"] = told
                try:
                    row.update(infer_row(
                        registry, args.plugin, path, posterior, theta, names, target_scene, folder / f"out-{i}-{len(rows)}",
                        told,
                    ))  # fmt: skip
                except Exception as exc:  # noqa: BLE001 - a refusal is a result
                    row["refused"] = f"{type(exc).__name__}: {exc}"
                rows.append(row)
                if args.rows:
                    with args.rows.open("a") as f:
                        f.write(json.dumps(row) + "\n")
                errors = {k: round(v["error"], 4) for k, v in row.get("params", {}).items()}
                print(f"target {i} {label}: {errors or row.get('refused')}", file=sys.stderr, flush=True)
    print(json.dumps({
        "benchmark": "posterior_targets", "plugin": args.plugin, "scene": scene, "scene_ranges": ranges, "posterior": [str(p) for p in args.posterior or []] or "shipped", "render_set_told": args.render_set_told, "duration": args.duration,
        "first": args.first, "targets": args.targets, "summary": summarise(rows),
        "seconds": round(time.perf_counter() - started, 1),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "processor": platform.processor()},
        "date": time.strftime("%Y-%m-%d"),
    }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
