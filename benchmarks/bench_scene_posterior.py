"""Flags of every size: a posterior estimator trained across sizes, on held-out simulations.

Issue 23, item 0. The held-out split of a dataset made with ``--scene-range`` (each clip a
flag of its own size, ζ from the renderer's dataset distribution) is embedded and every
clip's posterior drawn twice: by the estimator trained across sizes, with the clip's size as
input, and by the 1.5 m estimator (``--baseline``, default: the flag's shipped one), which
does not know the size — what ``infer`` would report if it did not refuse another scene.
Per band of flag length (``--bands``) and overall: the median absolute error of the
posterior median and the coverage of the 90 % central interval, for the wind speed and the
area weight, and the median width of the wind's interval.

Usage::

    python benchmarks/bench_scene_posterior.py --data runs/flag-posterior-sizes \\
        --posterior plugins/flag/physinfer_flag/data/posterior_sizes.safetensors

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from physinfer.datasets.loader import ClipDataset
from physinfer.plugins import load_registry
from physinfer.posterior.features import embed_dataset
from physinfer.posterior.workflow import estimator_embedder, load_estimator

PARAMETERS = ("wind_speed", "area_weight")


def embedded(registry, estimator, data: Path, split: str):
    """The split's pairs as the estimator sees them (cached beside the data)."""
    c = estimator.config
    pipeline = estimator_embedder(registry, estimator, "cpu")
    info = {
        "embedder": c.embedder,
        "embedder_frames": c.embedder_frames,
        "embedder_fps": c.embedder_fps,
        "probe": c.probe,
    }
    pairs = embed_dataset(data, split, pipeline.embedder, info)
    pipeline.renderer.close()
    return pairs


def posterior_stats(estimator, conditions: np.ndarray, n: int, seed: int):
    """Per clip and parameter: the posterior median and 90 % interval, physical units."""
    space = estimator.parameter_space
    medians, lows, highs = [], [], []
    for start in range(0, len(conditions), 50):
        s = estimator.sample_unit_batched(conditions[start : start + 50], n, seed=seed + start)
        phys = np.stack([spec.from_unit(s[..., i]) for i, spec in enumerate(space)], axis=-1)
        medians.append(np.median(phys, axis=0))
        lows.append(np.quantile(phys, 0.05, axis=0))
        highs.append(np.quantile(phys, 0.95, axis=0))
    return np.concatenate(medians), np.concatenate(lows), np.concatenate(highs)


def summarise(names, truth, stats, mask) -> dict:
    median, low, high = stats
    out: dict = {"clips": int(mask.sum())}
    for p in PARAMETERS:
        i = names.index(p)
        t = truth[mask, i]
        out[p] = {
            "median_abs_error": float(np.median(np.abs(median[mask, i] - t))),
            "coverage90": float(np.mean((low[mask, i] <= t) & (t <= high[mask, i]))),
            "median_width90": float(np.median(high[mask, i] - low[mask, i])),
        }
    return out


def run(args: argparse.Namespace) -> dict:
    registry, _ = load_registry()
    t0 = time.perf_counter()
    sized, sized_path = load_estimator(registry, "flag", Path(args.posterior), "cpu")
    baseline, baseline_path = load_estimator(
        registry, "flag", Path(args.baseline) if args.baseline else None, "cpu"
    )
    data = ClipDataset(args.data, args.split)
    names = data.param_names
    truth = data.params
    lengths = np.array([s["flag_length"] for s in data.scenes])
    pairs = embedded(registry, sized, Path(args.data), args.split)
    base_pairs = embedded(registry, baseline, Path(args.data), args.split)
    arms = {
        "sizes_estimator": posterior_stats(sized, pairs.conditions, args.samples, args.seed),
        "default_estimator_without_size": posterior_stats(
            baseline, base_pairs.x, args.samples, args.seed
        ),
    }
    edges = [float(v) for v in args.bands.split(",")]
    bands = [(lo, hi) for lo, hi in zip(edges[:-1], edges[1:], strict=False)]
    result: dict = {
        "benchmark": "scene_posterior",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
        "date": time.strftime("%Y-%m-%d"),
        "args": vars(args),
        "estimators": {"sizes": str(sized_path), "default": str(baseline_path)},
        "scene_ranges": sized.config.scene_ranges,
    }
    for arm, stats in arms.items():
        per_band = {
            f"{lo:g}-{hi:g} m": summarise(names, truth, stats, (lengths >= lo) & (lengths < hi))
            for lo, hi in bands
        }
        result[arm] = {
            "all": summarise(names, truth, stats, np.ones(len(lengths), bool)),
            "by_flag_length": per_band,
        }
    result["seconds"] = time.perf_counter() - t0
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="dataset made with --scene-range")
    parser.add_argument("--posterior", required=True, help="estimator trained across sizes")
    parser.add_argument("--baseline", default=None, help="estimator of one size (default: shipped)")
    parser.add_argument("--split", default="test")
    parser.add_argument("--samples", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--bands", default="0.9,1.3,2,3.0001", help="flag length band edges, m")
    print(json.dumps(run(parser.parse_args())))


if __name__ == "__main__":
    main()
