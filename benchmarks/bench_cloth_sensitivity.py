"""How much the flag's motion changes per parameter group, at several grid resolutions.

For each grid and each context wind speed, every parameter group is moved to a low and a
high value around the base θ (all multipliers 1, area weight 0.135 kg/m²) — wind ±1 m/s,
area weight 0.10 vs 0.17 kg/m², the five bending multipliers of one direction (0°, 45°,
90°) 0.1 vs 10, all fifteen 0.1 vs 10 — and simulated with ``--seeds`` seeds. Each clip
(60 frames at 25 fps after the 2 s warm-up, as the refinement sees it) is reduced to the
scalar features of :func:`physinfer_flag.cloth_analysis.clip_features` (reach and height
of the fly edge, amplitude, flapping frequency, fold angle). The flag is chaotic, so the
effect of a group on a feature is an effect size: Cohen's d between the low and the high
clips (difference of means over the pooled spread across seeds). ``d > 1`` means a single
clip mostly tells the two settings apart; ``max_d`` is the most telling feature.

With ``--chaos-seeds N`` it also measures the chaos itself at the default grid: the
dominant flapping frequency (fly-edge spectrum, five points) of single 60-frame clips of
the same θ over ``N`` seeds, per wind speed. With ``--frequency-seeds N`` it measures the
flapping frequency against wind speed on long records (``--frequency-seconds``): the peak
and the centroid of fly-edge spectra averaged over five points and ``N`` seeds, and the
zero-crossing rate.

Usage::

    python benchmarks/bench_cloth_sensitivity.py --grids 16x11,31x21,37x25,46x31 --winds 2,6 --seeds 6
    python benchmarks/bench_cloth_sensitivity.py --grids 31x21 --seeds 6 --chaos-seeds 10
    python benchmarks/bench_cloth_sensitivity.py --grids "" --frequency-seeds 3

Prints exactly one JSON object on stdout; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import platform
import sys
import time
from typing import Any

import numpy as np

from physinfer_flag.cloth_analysis import (
    FEATURES,
    clip_features,
    dominant_frequency,
    effect_size,
    fly_edge_crosswind,
    spectral_centroid,
    zero_crossing_rate,
)
from physinfer_flag.material import BEND_DIRECTIONS_DEG, bending_parameter_names
from physinfer_flag.simulator import FlagSimConfig, make_simulator


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grids", default="16x11,31x21,46x31", help="comma-separated NUxNV grids")
    parser.add_argument("--winds", default="2,6", help="comma-separated context wind speeds in m/s")
    parser.add_argument("--seeds", type=int, default=6, help="seeds per parameter set (>= 2)")
    parser.add_argument("--frames", type=int, default=60, help="recorded frames per clip")
    parser.add_argument("--chaos-seeds", type=int, default=0, help="seeds of the chaos study (0: skip)")
    parser.add_argument("--chaos-winds", default="2,4,6,8,10", help="wind speeds of the chaos study")
    parser.add_argument("--frequency-seeds", type=int, default=0, help="seeds of the frequency study (0: skip)")
    parser.add_argument("--frequency-seconds", type=float, default=8.0, help="record length of the frequency study")
    parser.add_argument("--frequency-winds", default="1,2,3,4,6,8,10", help="wind speeds of the frequency study")
    return parser.parse_args(argv)


def groups(wind: float) -> dict[str, tuple[dict[str, float], dict[str, float]]]:
    """Low and high parameter overrides of each group around a context wind speed."""
    names = bending_parameter_names()
    out: dict[str, tuple[dict[str, float], dict[str, float]]] = {
        "wind_speed ±1 m/s": ({"wind_speed": max(wind - 1.0, 0.0)}, {"wind_speed": wind + 1.0}),
        "area_weight 0.10↔0.17": ({"area_weight": 0.10}, {"area_weight": 0.17}),
    }
    for d in BEND_DIRECTIONS_DEG:
        group = [n for n in names if n.startswith(f"bend_{d}deg_")]
        out[f"bend {d}° ×0.1↔×10"] = ({n: 0.1 for n in group}, {n: 10.0 for n in group})
    out["bend all ×0.1↔×10"] = ({n: 0.1 for n in names}, {n: 10.0 for n in names})
    return out


def substeps_for(nu: int, nv: int) -> int:
    """Steps per frame scaled with the grid spacing (the explicit limit is proportional to it)."""
    default = FlagSimConfig()
    h = max(default.width / (nu - 1), default.height / (nv - 1))
    h0 = max(default.width / (default.grid_u - 1), default.height / (default.grid_v - 1))
    return int(math.ceil(default.steps_per_frame * h0 / h - 1e-9))


def measure_grid(nu: int, nv: int, winds: list[float], seeds: int, frames: int) -> dict[str, Any]:
    """Simulate every clip of one grid in a single batch and reduce it to effect sizes."""
    substeps = substeps_for(nu, nv)
    sim = make_simulator(grid_u=nu, grid_v=nv, substeps=substeps, n_frames=frames)
    jobs: list[tuple[float, str, str]] = []
    params: list[dict[str, float]] = []
    for wind in winds:
        for name, (low, high) in groups(wind).items():
            for level, override in (("low", low), ("high", high)):
                jobs.append((wind, name, level))
                params.append({"wind_speed": wind, **override})
    all_params = [p for p in params for _ in range(seeds)]
    all_seeds = [s for _ in params for s in range(seeds)]
    start = time.perf_counter()
    trajs = sim.simulate_batch(all_params, seeds=all_seeds)
    elapsed = time.perf_counter() - start
    feats = [clip_features(t) for t in trajs]
    by_job = {job: feats[k * seeds:(k + 1) * seeds] for k, job in enumerate(jobs)}
    table: dict[str, Any] = {}
    for wind in winds:
        rows = {}
        for name in groups(wind):
            low, high = by_job[(wind, name, "low")], by_job[(wind, name, "high")]
            d = {f: effect_size([x[f] for x in low], [x[f] for x in high]) for f in FEATURES}
            means = {f: [float(np.mean([x[f] for x in low])), float(np.mean([x[f] for x in high]))]
                     for f in FEATURES}
            rows[name] = {"d": {f: round(v, 2) for f, v in d.items()}, "max_d": round(max(d.values()), 2),
                          "means_low_high": means}
        table[f"{wind:g} m/s"] = rows
    print(f"grid {nu}x{nv}: {len(trajs)} clips in {elapsed:.1f} s", file=sys.stderr, flush=True)
    return {
        "spacing_m": max(sim.config.width / (nu - 1), sim.config.height / (nv - 1)),
        "substeps": substeps,
        "clips": len(trajs),
        "batch_wall_s": round(elapsed, 2),
        "table": table,
    }


def measure_chaos(winds: list[float], seeds: int, frames: int) -> dict[str, Any]:
    """Scatter over seeds of the dominant frequency of single clips at the default grid."""
    sim = make_simulator(n_frames=frames)
    params = [{"wind_speed": w} for w in winds for _ in range(seeds)]
    trajs = sim.simulate_batch(params, seeds=[s for _ in winds for s in range(seeds)])
    out = {}
    for k, wind in enumerate(winds):
        freqs = np.array([dominant_frequency([fly_edge_crosswind(t)], sim.config.fps)
                          for t in trajs[k * seeds:(k + 1) * seeds]])
        out[f"{wind:g} m/s"] = {
            "dominant_hz": [round(float(f), 3) for f in freqs],
            "mean_hz": round(float(freqs.mean()), 3),
            "cv": round(float(freqs.std() / freqs.mean()), 3),
        }
    print(f"chaos: {len(trajs)} clips", file=sys.stderr, flush=True)
    return {"seeds": seeds, "frames": frames, "winds": out}


def measure_frequency(winds: list[float], seeds: int, seconds: float) -> dict[str, Any]:
    """Flapping frequency against wind speed from long records at the default grid."""
    sim = make_simulator(n_frames=int(round(seconds * FlagSimConfig().fps)))
    fps = sim.config.fps
    trajs = sim.simulate_batch([{"wind_speed": w} for w in winds for _ in range(seeds)],
                               seeds=[s for _ in winds for s in range(seeds)])
    out = {}
    for k, wind in enumerate(winds):
        sig = [fly_edge_crosswind(t) for t in trajs[k * seeds:(k + 1) * seeds]]
        out[f"{wind:g} m/s"] = {
            "dominant_hz": round(dominant_frequency(sig, fps), 3),
            "centroid_hz": round(spectral_centroid(sig, fps), 3),
            "zero_crossing_hz": round(zero_crossing_rate(sig, fps), 3),
            "rms_crosswind_m": round(float(np.sqrt(np.mean([np.mean(x**2) for x in sig]))), 4),
        }
    print(f"frequency: {len(trajs)} records", file=sys.stderr, flush=True)
    return {"seeds": seeds, "seconds": seconds, "winds": out}


def main(argv: list[str] | None = None) -> None:
    """Run the sensitivity study and print one JSON object."""
    args = parse_args(argv)
    if args.seeds < 2:
        raise SystemExit("--seeds must be at least 2 (the spread over seeds is the yardstick)")
    winds = [float(w) for w in args.winds.split(",")]
    result: dict[str, Any] = {
        "benchmark": "cloth_sensitivity",
        "date": datetime.date.today().isoformat(),
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "seeds": args.seeds,
        "frames": args.frames,
        "features": list(FEATURES),
        "grids": {},
    }
    for grid in args.grids.split(","):
        if grid:
            nu, nv = (int(n) for n in grid.lower().split("x"))
            result["grids"][f"{nu}x{nv}"] = measure_grid(nu, nv, winds, args.seeds, args.frames)
    if args.chaos_seeds > 0:
        chaos_winds = [float(w) for w in args.chaos_winds.split(",")]
        result["chaos"] = measure_chaos(chaos_winds, args.chaos_seeds, args.frames)
    if args.frequency_seeds > 0:
        freq_winds = [float(w) for w in args.frequency_winds.split(",")]
        result["frequency"] = measure_frequency(freq_winds, args.frequency_seeds, args.frequency_seconds)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
