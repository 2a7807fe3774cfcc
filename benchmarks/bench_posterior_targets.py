"""The flag's amortized posterior on targets as users give them (issue 44).

Targets: wind speed uniform over 1–9.5 m/s and area weight over 0.10–0.17 kg/m², the other
parameters at their defaults, the default scene and camera, seeds no dataset uses (θ from
``700_000 + i``, the simulation from ``800_000 + i``). Each is simulated and rendered as
``physinfer simulate --out target.mp4`` does (H.264 CRF 18), and inferred as ``physinfer infer
--target target.mp4`` does (read, conditioned, embedded, 2,000 samples; no predictive check).
``--degraded`` adds a second condition per target: the flag composited over a photographic
background (a frame of a real video from ``--photo``, else a procedural photo-like one),
sensor noise of 3 grey levels and H.264 at CRF 35.

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_posterior_targets.py --targets 100 \\
        --posterior plugins/flag/physinfer_flag/data/posterior_default.safetensors --degraded --rows rows.jsonl

Prints one JSON object: per condition the 90 % coverage of the wind, the median error of the
posterior median, the median 90 % width, the area weight's coverage, the median seconds of
``infer`` after start-up; per-target rows go to ``--rows`` (appended, so a run can resume with
``--first``).
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

THETA_SEED, SIM_SEED = 700_000, 800_000
WIND, AREA_WEIGHT = (1.0, 9.5), (0.10, 0.17)


def make_target(pipeline: Any, index: int) -> tuple[dict[str, float], Any]:
    """θ of target ``index`` and its trajectory."""
    rng = np.random.default_rng(THETA_SEED + index)
    theta = pipeline.simulator.parameter_space.complete(
        {"wind_speed": float(rng.uniform(*WIND)), "area_weight": float(rng.uniform(*AREA_WEIGHT))}
    )
    return theta, pipeline.simulator.simulate(theta, seed=SIM_SEED + index)


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


def infer_row(registry: Any, path: Path, posterior: Path | None, theta: dict[str, float], out: Path) -> dict[str, Any]:
    """``physinfer infer --target path`` (no predictive check): the wind and area weight."""
    from physinfer.conditioning import Conditioning
    from physinfer.posterior.infer_workflow import infer

    t0 = time.perf_counter()
    report = infer(
        registry, plugin="flag", out=out, target_path=path, posterior=posterior, n_samples=2000,
        conditioning=Conditioning(), check=False,
    )  # fmt: skip
    wind, weight = report.marginals["wind_speed"], report.marginals["area_weight"]
    return {
        "wind_median": wind["median"],
        "wind_error": abs(wind["median"] - theta["wind_speed"]),
        "wind_covered90": bool(wind["ci90"][0] <= theta["wind_speed"] <= wind["ci90"][1]),
        "wind_width90": wind["ci90"][1] - wind["ci90"][0],
        "area_weight_covered90": bool(weight["ci90"][0] <= theta["area_weight"] <= weight["ci90"][1]),
        "area_weight_label": weight["label"],
        "extrapolating": bool((report.inputs or {}).get("extrapolating")),
        "seconds_after_start_up": time.perf_counter() - t0 - report.seconds.get("start_up", 0.0),
        "seconds": time.perf_counter() - t0,
    }


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for condition in sorted({r["condition"] for r in rows}):
        rs = [r for r in rows if r["condition"] == condition and "wind_error" in r]
        if not rs:
            continue
        out[condition] = {
            "targets": len(rs),
            "wind_coverage90": round(float(np.mean([r["wind_covered90"] for r in rs])), 3),
            "wind_median_error": round(float(np.median([r["wind_error"] for r in rs])), 3),
            "wind_median_width90": round(float(np.median([r["wind_width90"] for r in rs])), 3),
            "area_weight_coverage90": round(float(np.mean([r["area_weight_covered90"] for r in rs])), 3),
            "extrapolating": int(sum(r["extrapolating"] for r in rs)),
            "median_seconds_after_start_up": round(float(np.median([r["seconds_after_start_up"] for r in rs])), 2),
            "refused": sum(1 for r in rows if r["condition"] == condition and "refused" in r),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--targets", type=int, default=10)
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--posterior", type=Path, action="append", default=None,
                        help="estimator file (default: the shipped one); repeat to compare several on the same targets")
    parser.add_argument("--degraded", action="store_true", help="also: photo background, noise, H.264 CRF 35")
    parser.add_argument("--photo", default=None, help="a video whose middle frame is the background")
    parser.add_argument("--rows", type=Path, default=None, help="append per-target rows (JSON lines)")
    parser.add_argument("--summarise", action="store_true", help="only summarise --rows")
    args = parser.parse_args()
    if args.summarise:
        rows = [json.loads(line) for line in args.rows.read_text().splitlines() if line.strip()]
        print(json.dumps({"summary": summarise(rows), "rows": len(rows)}, indent=1))
        return

    from physinfer.pipeline import build_pipeline
    from physinfer.plugins import load_registry
    from physinfer.video import write_video

    registry = load_registry()[0]
    pipeline = build_pipeline(registry, "flag", embedder="")
    rows: list[dict[str, Any]] = []
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench-targets-") as tmp:
        folder = Path(tmp)
        for i in range(args.first, args.first + args.targets):
            theta, trajectory = make_target(pipeline, i)
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
                row: dict[str, Any] = {"target": i, "condition": label, "theta": {k: theta[k] for k in ("wind_speed", "area_weight")}}
                try:
                    row.update(infer_row(registry, path, posterior, theta, folder / f"out-{i}-{len(rows)}"))
                except Exception as exc:  # noqa: BLE001 - a refusal is a result
                    row["refused"] = f"{type(exc).__name__}: {exc}"
                rows.append(row)
                if args.rows:
                    with args.rows.open("a") as f:
                        f.write(json.dumps(row) + "\n")
                print(f"target {i} {label}: {row.get('wind_error', row.get('refused'))}", file=sys.stderr, flush=True)
    print(json.dumps({
        "benchmark": "posterior_targets", "posterior": [str(p) for p in args.posterior or []] or "shipped",
        "first": args.first, "targets": args.targets, "summary": summarise(rows),
        "seconds": round(time.perf_counter() - started, 1),
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "processor": platform.processor()},
        "date": time.strftime("%Y-%m-%d"),
    }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
