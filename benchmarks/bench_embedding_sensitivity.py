"""How much the flag's *embedding* changes per parameter group, against its seed noise.

The companion of ``bench_cloth_sensitivity.py`` (which measures the motion): every group is
moved between a low and a high value around the centre of θ (wind ±1 m/s around
``--wind``, area weight 0.10 vs 0.17 kg/m², one direction's five bending multipliers or all
fifteen ×0.1 vs ×10), each setting simulated under ``--seeds`` seeds and rendered at the
default ζ, then embedded. The flag is chaotic, so a group's effect is a separation ratio:
the mean squared embedding distance between low and high clips over the mean distance
between clips of one setting under different seeds (the noise floor). A ratio near 1 means
the embedder cannot tell the two settings apart from one clip; the refinement can only
recover a parameter whose ratio is well above 1.

Usage: ``PYOPENGL_PLATFORM=egl python benchmarks/bench_embedding_sensitivity.py --embedder sdn --seeds 4``.
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import sys
import time

import numpy as np

from physinfer.evaluation import build_pipeline, squared_distance
from physinfer.plugins import load_registry


def groups(names: list[str], wind: float) -> dict[str, tuple[dict[str, float], dict[str, float]]]:
    """Low and high overrides per parameter group."""
    bend = {d: [n for n in names if n.startswith(f"bend_{d}deg")] for d in ("0", "45", "90")}
    out = {
        "wind_speed ±1 m/s": ({"wind_speed": wind - 1.0}, {"wind_speed": wind + 1.0}),
        "area_weight 0.10↔0.17": ({"area_weight": 0.10}, {"area_weight": 0.17}),
    }
    for d, members in bend.items():
        out[f"bend {d}° ×0.1↔×10"] = ({n: 0.1 for n in members}, {n: 10.0 for n in members})
    every = [n for n in names if n.startswith("bend_")]
    out["bend all ×0.1↔×10"] = ({n: 0.1 for n in every}, {n: 10.0 for n in every})
    return out


def embeddings(pipeline, params: dict[str, float], seeds: list[int]) -> np.ndarray:
    """``(S, D)`` embeddings of ``params`` under each seed at the default ζ."""
    zeta = pipeline.renderer.default_render_params
    return np.stack([
        pipeline.embedder.embed(pipeline.renderer.render(pipeline.simulator.simulate(params, seed=s), zeta))
        for s in seeds
    ])


def mean_within(e: np.ndarray) -> float:
    return float(np.mean([squared_distance(a, b) for a, b in itertools.combinations(e, 2)]))


def mean_between(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean([squared_distance(x, y) for x in a for y in b]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--embedder", default=None, help="default: the flag's default embedder")
    parser.add_argument("--weights", default=None)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--wind", type=float, default=5.0)
    args = parser.parse_args()
    registry, _ = load_registry()
    pipeline = build_pipeline(registry, "flag", embedder=args.embedder, weights=args.weights)
    space = pipeline.simulator.parameter_space
    base = space.from_unit(np.zeros(len(space)))
    base["wind_speed"] = args.wind
    seeds = list(range(1, args.seeds + 1))
    start = time.perf_counter()
    rows = {}
    for label, (low, high) in groups(space.names, args.wind).items():
        e_low = embeddings(pipeline, {**base, **low}, seeds)
        e_high = embeddings(pipeline, {**base, **high}, seeds)
        floor = 0.5 * (mean_within(e_low) + mean_within(e_high))
        between = mean_between(e_low, e_high)
        rows[label] = {"between": between, "floor": floor, "ratio": between / floor if floor > 0 else None}
        print(f"{label}: ratio {rows[label]['ratio']:.2f}", file=sys.stderr, flush=True)
    pipeline.renderer.close()
    print(json.dumps({
        "benchmark": "embedding_sensitivity",
        "embedder": args.embedder or pipeline.phenomenon.default_embedder,
        "weights": args.weights,
        "wind": args.wind,
        "seeds": args.seeds,
        "groups": rows,
        "seconds": time.perf_counter() - start,
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs",
        "load_average": os.getloadavg()[0],
    }))


if __name__ == "__main__":
    main()
