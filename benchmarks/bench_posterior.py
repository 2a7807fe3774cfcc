"""Amortized posterior benchmark: generate (or resume) a dataset, train an estimator with sbi,
and check its calibration on the held-out split; prints one JSON object.

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_posterior.py --plugin pendulum_lab \
        --sims 600,0,150 --frames 100 --size 64 --out runs/bench_posterior_pendulum
    # the flag's shipped estimator (make posterior made the data): calibration only
    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_posterior.py --plugin flag \
        --data runs/flag-posterior --estimator shipped --out runs/bench_posterior_flag

Reported per parameter: coverage of the 50 % and 90 % intervals, the verdict, the median
absolute error of the posterior median, the mean contraction; and the time of each stage and
of one ``infer`` (embed + sample) per held-out clip.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from physinfer.plugins import load_registry
from physinfer.posterior.workflow import (
    estimator_embedder,
    evaluate_calibration,
    load_estimator,
    posterior_of_clip,
    train_posterior,
)

BIN = Path(sys.executable).parent / "physinfer"


def generate(args: argparse.Namespace, data: Path) -> float:
    """``physinfer dataset generate`` (resumes); returns its wall time."""
    start = time.perf_counter()
    cmd = [str(BIN), "dataset", "generate", "--plugin", args.plugin, "--sims", args.sims, "--renders-per-sim", "1",
           "--frames", str(args.frames), "--size", str(args.size), "--gray", "--seed", str(args.seed), "--out", str(data)]
    subprocess.run(cmd, check=True)
    return time.perf_counter() - start


def infer_seconds(registry: object, estimator_path: Path, data: Path, plugin: str, n: int = 5) -> float:
    """Median seconds of embed + sample (5,000 samples) for ``n`` held-out clips."""
    from physinfer.datasets.loader import ClipDataset
    from physinfer.posterior.features import as_clip

    estimator, _ = load_estimator(registry, plugin, estimator_path)
    pipeline = estimator_embedder(registry, estimator, None)
    test = ClipDataset(data, "test")
    times = []
    for i in range(min(n, len(test))):
        clip = as_clip(np.asarray(test[i]), test.fps)
        t0 = time.perf_counter()
        posterior_of_clip(estimator, pipeline.embedder, clip, seed=i)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--plugin", default="pendulum_lab")
    parser.add_argument("--data", default=None, help="existing dataset (default: OUT/data, generated)")
    parser.add_argument("--sims", default="600,0,150", help="TRAIN,VAL,TEST simulations to generate")
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--estimator", default=None, help="'shipped' or a file: skip training")
    parser.add_argument("--samples", type=int, default=1000)
    parser.add_argument("--density", default="nsf", help="nsf, maf or mdn (as posterior train --density)")
    parser.add_argument("--patience", type=int, default=60, help="epochs without improvement before stopping")
    parser.add_argument("--out", default="runs/bench_posterior")
    args = parser.parse_args()

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    registry, _ = load_registry()
    data = Path(args.data) if args.data else out / "data"
    seconds: dict[str, float] = {}
    if args.data is None:
        seconds["generate"] = generate(args, data)
    if args.estimator is None:
        from physinfer.posterior.estimator import NetworkConfig

        network = NetworkConfig(density=args.density, stop_after_epochs=args.patience)
        trained = train_posterior(registry, plugin=args.plugin, data=data, out=out / "estimator.safetensors",
                                  device="cpu", network=network)
        seconds.update(trained.seconds)
        estimator_path: Path | None = trained.path
    else:
        estimator_path = None if args.estimator == "shipped" else Path(args.estimator)
    report = evaluate_calibration(registry, plugin=args.plugin, data=data, out=out / "calibration",
                                  posterior=estimator_path, n_samples=args.samples, device="cpu")
    seconds.update({f"calibration_{k}": v for k, v in report.seconds.items()})
    path = estimator_path or load_estimator(registry, args.plugin, None)[1]
    result = {
        "benchmark": "posterior",
        "plugin": args.plugin,
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.system()}",
        "data": str(data),
        "estimator": str(path),
        "network": {"density": args.density, "patience": args.patience} if args.estimator is None else None,
        "calibration": report.to_dict(),
        "infer_s_median": infer_seconds(registry, path, data, args.plugin),
        "seconds": seconds,
        "load_average": os.getloadavg()[0],
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
