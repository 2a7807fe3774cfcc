"""How much the flag's motion changes per parameter group, at several grid resolutions.

For each grid and each context wind speed, the base θ (all multipliers 1, area weight
0.135 kg/m²) is simulated with several seeds; then each parameter group is moved to a
low and a high value — wind ±1 m/s, area weight 0.10 vs 0.17 kg/m², the five bending
multipliers of one direction (0°, 45°, 90°) 0.1 vs 10, all fifteen 0.1 vs 10 — and
simulated with the same seeds. Every clip (60 frames at 25 fps after the 2 s warm-up,
as the refinement sees them) is reduced to a motion descriptor on a common 11 × 16
lattice of material points (time-mean shape, RMS amplitude, spectral centroid) plus the
mean fold (dihedral) angle of the whole mesh; see :mod:`physinfer_flag.cloth_analysis`. The effect of a group is the mean descriptor
distance between its low and high clips over all seed pairs; the noise is the mean
distance between different seeds of the base θ (the flag is chaotic). A ratio
effect / noise above 1 means the group changes the motion more than chaos does.

With ``--chaos-seeds N`` it also measures the chaos itself at the default grid: the
dominant flapping frequency (fly-edge spectrum, five points) of single 60-frame clips of
the same θ over ``N`` seeds, per wind speed.

Usage::

    python benchmarks/bench_cloth_sensitivity.py --grids 16x11,31x21,46x31 --winds 2,6 --seeds 3
    python benchmarks/bench_cloth_sensitivity.py --grids 31x21 --chaos-seeds 10

Prints exactly one JSON object on stdout; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import math
import platform
import sys
import time
from typing import Any

import numpy as np

from physinfer_flag.cloth_analysis import (
    descriptor_distance,
    dominant_frequency,
    fly_edge_crosswind,
    motion_descriptor,
)
from physinfer_flag.material import BEND_DIRECTIONS_DEG, bending_parameter_names
from physinfer_flag.simulator import FlagSimConfig, make_simulator

METRICS = ("shape", "amplitude", "centroid", "fold")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grids", default="16x11,31x21,46x31", help="comma-separated NUxNV grids")
    parser.add_argument("--winds", default="2,6", help="comma-separated context wind speeds in m/s")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per parameter set")
    parser.add_argument("--frames", type=int, default=60, help="recorded frames per clip")
    parser.add_argument("--chaos-seeds", type=int, default=0, help="seeds of the chaos study (0: skip)")
    parser.add_argument("--chaos-winds", default="2,4,6,8,10", help="wind speeds of the chaos study")
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
    return int(math.ceil(default.substeps * h0 / h))


def mean_distance(a: list, b: list, *, same: bool) -> dict[str, float]:
    """Mean descriptor distance over seed pairs (distinct seeds when ``same``)."""
    pairs = [(x, y) for (i, x), (j, y) in itertools.product(enumerate(a), enumerate(b)) if not (same and i >= j)]
    dists = [descriptor_distance(x, y) for x, y in pairs]
    return {m: float(np.mean([d[m] for d in dists])) for m in METRICS}


def measure_grid(nu: int, nv: int, winds: list[float], seeds: int, frames: int) -> dict[str, Any]:
    """Simulate every clip of one grid in a single batch and reduce it to the table."""
    substeps = substeps_for(nu, nv)
    sim = make_simulator(grid_u=nu, grid_v=nv, substeps=substeps, n_frames=frames)
    jobs: list[tuple[float, str, str]] = []
    params: list[dict[str, float]] = []
    for wind in winds:
        jobs.append((wind, "base", ""))
        params.append({"wind_speed": wind})
        for name, (low, high) in groups(wind).items():
            for level, override in (("low", low), ("high", high)):
                jobs.append((wind, name, level))
                params.append({"wind_speed": wind, **override})
    seed_list = list(range(seeds))
    all_params = [p for p in params for _ in seed_list]
    all_seeds = [s for _ in params for s in seed_list]
    start = time.perf_counter()
    trajs = sim.simulate_batch(all_params, seeds=all_seeds)
    elapsed = time.perf_counter() - start
    desc = [motion_descriptor(t) for t in trajs]
    by_job = {job: desc[k * seeds:(k + 1) * seeds] for k, job in enumerate(jobs)}
    table: dict[str, Any] = {}
    for wind in winds:
        noise = mean_distance(by_job[(wind, "base", "")], by_job[(wind, "base", "")], same=True)
        rows = {}
        for name in groups(wind):
            effect = mean_distance(by_job[(wind, name, "low")], by_job[(wind, name, "high")], same=False)
            ratio = {m: effect[m] / max(noise[m], 1e-12) for m in METRICS}
            rows[name] = {"effect": effect, "ratio": ratio, "score": float(np.mean(list(ratio.values())))}
        table[f"{wind:g} m/s"] = {"noise": noise, "groups": rows}
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


def main(argv: list[str] | None = None) -> None:
    """Run the sensitivity study and print one JSON object."""
    args = parse_args(argv)
    winds = [float(w) for w in args.winds.split(",")]
    result: dict[str, Any] = {
        "benchmark": "cloth_sensitivity",
        "date": datetime.date.today().isoformat(),
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "seeds": args.seeds,
        "frames": args.frames,
        "grids": {},
    }
    for grid in args.grids.split(","):
        nu, nv = (int(n) for n in grid.lower().split("x"))
        result["grids"][f"{nu}x{nv}"] = measure_grid(nu, nv, winds, args.seeds, args.frames)
    if args.chaos_seeds > 0:
        chaos_winds = [float(w) for w in args.chaos_winds.split(",")]
        result["chaos"] = measure_chaos(chaos_winds, args.chaos_seeds, args.frames)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
