"""Refinement with the camera estimated from the target vs given (issue 23 item 4b).

On the held-out targets of ``bench_real_conditions.py`` (same indices, same θ, ζ and
simulation seeds), ``refine`` as it runs by default (the shipped posterior's start and box,
``--steps`` trials, the noise floor) against:

- ``oracle ζ, clean``: the clean render, simulations rendered at the target's true ζ (the
  paper's setting, and every earlier accuracy number's);
- ``default ζ, prepared``: the clean render through ``prepare``, simulations at the
  renderer's default ζ (what a user without ``--render-set`` gets today);
- ``estimated ζ, prepared``: the same, at the default ζ with the estimated framing, azimuth
  and elevation (``physinfer.render_estimate``) — the texture, light and background stay
  unknown;
- ``estimated ζ, phone``: the ``phone (all, 1080p 30 fps)`` condition, prepared, at the
  estimated ζ;
- ``as refine conditions it``: the clean render through the product's own conditioning
  (:func:`physinfer.conditioning.condition_target`, framed as a wide video is): only the
  estimated components that read well (``MIN_EXPLAINED``; for the flag the framing) replace
  the defaults, the rest stay at the renderer's defaults — what ``refine --target`` does.

    PYOPENGL_PLATFORM=egl nice -n 10 .venv/bin/python benchmarks/bench_real_conditions_refine.py \
        --targets 4 --steps 16 --out runs/bench_real_conditions_refine

Rows go to ``OUT/results.jsonl`` as they finish (a second run skips the rows already there);
prints one JSON object: per arm the median wind error of the best fit and of the reported
posterior median, the share within 0.5 m/s, the 90 % coverage and the noise ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

import bench_real_conditions as brc  # noqa: E402
import bench_refine  # noqa: E402

from physinfer.conditioning import Conditioning, condition_target  # noqa: E402
from physinfer.evaluation import build_pipeline  # noqa: E402
from physinfer.framing import PrepareSettings, prepare_clip  # noqa: E402
from physinfer.plugins import load_registry  # noqa: E402
from physinfer.render_estimate import estimate_render_params  # noqa: E402
from physinfer.roles import Target  # noqa: E402

ARMS = {
    "oracle": "oracle ζ, clean",
    "default": "default ζ, prepared",
    "estimated": "estimated ζ, prepared",
    "phone": "estimated ζ, phone",
    "refine": "as refine conditions it",
}
"""``--arms`` keys and the labels of the rows."""


def arm_target(
    arm: str, target: dict[str, Any], pipeline: Any, clips: dict[str, Any]
) -> tuple[Target, dict]:
    """The :class:`Target` (clip and the ζ simulations are rendered with) of one arm."""
    default = dict(pipeline.renderer.default_render_params)
    truth = target["truth"]
    if arm == "oracle ζ, clean":
        return Target(
            clip=clips["clean (oracle framing)"], truth=truth, render_params=target["zeta"]
        ), {}
    condition = "phone (all, 1080p 30 fps)" if arm.endswith("phone") else "clean → prepare"
    if arm == ARMS["refine"]:
        clip, estimated, record = condition_target(
            pipeline.phenomenon, pipeline.embedder, clips[condition], Conditioning(prepare=True), {}
        )
        return Target(clip=clip, truth=truth, render_params={**default, **estimated}), record.get(
            "render_estimate", {}
        )
    settings = PrepareSettings(size=pipeline.embedder.size, fps=pipeline.embedder.fps)
    clip = prepare_clip(
        clips[condition], framing=pipeline.phenomenon.framing, settings=settings
    ).clip
    zeta, estimate = default, {}
    if arm.startswith("estimated"):
        estimate = estimate_render_params(pipeline.phenomenon, clip, embedder=pipeline.embedder)
        zeta = {**default, **estimate["values"]}
    return Target(clip=clip, truth=truth, render_params=zeta), estimate


def refine_args(steps: int) -> argparse.Namespace:
    """``bench_refine.refine_one``'s settings: refine's defaults with the shipped posterior."""
    return argparse.Namespace(
        plugin="flag",
        embedder=None,
        steps=steps,
        noise_samples=3,
        seeds_per_trial=1,
        floor_samples=4,
        select_top=0,
        select_seeds=3,
        batch_size=1,
        posterior="shipped",
        no_box=False,
        reuse_trials=False,
    )


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    out = {}
    for arm in ARMS.values():
        mine = [r for r in rows if r["arm"] == arm]
        if not mine:
            continue
        best = [r["abs_errors"]["wind_speed"] for r in mine]
        post = [r["posterior"]["wind_speed"] for r in mine if r.get("posterior")]
        out[arm] = {
            "n": len(mine),
            "median_wind_error_best_fit": statistics.median(best),
            "median_wind_error_posterior": statistics.median(p["median_abs_error"] for p in post)
            if post
            else None,
            "within_0.5_posterior": float(np.mean([p["median_abs_error"] <= 0.5 for p in post]))
            if post
            else None,
            "coverage90": float(np.mean([p["covers"] for p in post])) if post else None,
            "median_noise_ratio": statistics.median(
                r["noise_ratio"] for r in mine if r["noise_ratio"] is not None
            ),
            "median_wall_time_s": statistics.median(r["wall_time_s"] for r in mine),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--targets", type=int, default=4)
    parser.add_argument("--steps", type=int, default=16)
    parser.add_argument(
        "--arms", default=",".join(ARMS), help="comma-separated: " + ", ".join(ARMS)
    )
    parser.add_argument("--out", type=Path, default=Path("runs/bench_real_conditions_refine"))
    args = parser.parse_args()
    keys = [a.strip() for a in args.arms.split(",")]
    unknown = set(keys) - set(ARMS)
    if unknown:
        raise SystemExit(f"--arms: unknown {sorted(unknown)}; choose from {', '.join(ARMS)}")
    arms = [ARMS[k] for k in keys]
    args.out.mkdir(parents=True, exist_ok=True)
    log = args.out / "results.jsonl"
    rows = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    done = {(r["target"], r["arm"], r["steps"]) for r in rows}
    registry, _ = load_registry()
    pipeline = build_pipeline(registry, "flag")
    start = time.perf_counter()
    for index in range(args.targets):
        todo = [a for a in arms if (index, a, args.steps) not in done]
        if not todo:
            continue
        target = brc.make_target(pipeline.phenomenon, pipeline.renderer, index)
        makers = brc.conditions(target, pipeline.renderer, seed=brc.THETA_SEED + index)
        needed = {"clean (oracle framing)", "clean → prepare"}
        if ARMS["phone"] in todo:
            needed.add("phone (all, 1080p 30 fps)")
        clips = {name: makers[name]()[0] for name in needed}
        for arm in todo:
            refine_target, estimate = arm_target(arm, target, pipeline, clips)
            out = (
                args.out
                / f"target-{index:02d}"
                / arm.replace(" ", "_").replace(",", "").replace("ζ", "zeta")
            )
            row = bench_refine.refine_one(
                pipeline, registry, refine_target, "ax", refine_args(args.steps), out
            )
            row.update(
                target=index,
                arm=arm,
                steps=args.steps,
                estimate=estimate.get("values"),
                true_camera={
                    k: target["zeta"][k]
                    for k in ("framing", "camera_azimuth_deg", "camera_elevation_deg")
                },
            )
            rows.append(row)
            with log.open("a") as f:
                f.write(json.dumps(row) + "\n")
            print(
                f"target {index} {arm}: wind error {row['abs_errors']['wind_speed']:.2f} (best fit), "
                f"{(row.get('posterior') or {}).get('wind_speed', {}).get('median_abs_error', float('nan')):.2f} "
                f"(posterior)",
                file=sys.stderr,
                flush=True,
            )
    pipeline.renderer.close()
    print(
        json.dumps(
            {
                "benchmark": "real_conditions_refine",
                "targets": args.targets,
                "steps": args.steps,
                "arms": summarise(
                    [r for r in rows if r["steps"] == args.steps and r["target"] < args.targets]
                ),
                "seconds": time.perf_counter() - start,
                "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.system()}",
                "load_average": os.getloadavg()[0],
            }
        )
    )


if __name__ == "__main__":
    main()
