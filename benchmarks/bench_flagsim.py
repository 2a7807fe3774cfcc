"""Dataset-generation throughput: renders per minute with 1 and 2 local worker processes.

Generates the same small dataset (all simulations in the train split) once per worker
count into fresh temporary directories through the real engine
(:func:`physinfer.datasets.generate_dataset`: spawned worker processes, simulator and
renderer built inside each worker, shards written and checksummed), times it end to
end, and checks that every worker count produced identical data (and, if not, by how
much the pixels differ: a renderer that is not bit-deterministic shows up here). Works for any
installed phenomenon: ``--plugin flag`` (the default), ``--plugin pendulum_lab``, ...

Usage::

    PYOPENGL_PLATFORM=egl python benchmarks/bench_flagsim.py --plugin flag \\
        --sims 8 --renders-per-sim 4 --workers 1,2

Prints exactly one JSON object on stdout; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plugin", default="flag", help="installed phenomenon to generate (default: flag)")
    parser.add_argument("--preset", default="cpu", help="preset giving the clip format (default: cpu)")
    parser.add_argument("--sims", type=int, default=8, help="simulations, all in the train split (default: 8)")
    parser.add_argument("--renders-per-sim", type=int, default=4, help="renders per simulation (default: 4)")
    parser.add_argument("--sims-per-unit", type=int, default=2, help="simulations per work unit (default: 2)")
    parser.add_argument("--frames", type=int, default=None, help="frames per clip (default: the preset's)")
    parser.add_argument("--size", type=int, default=None, help="square clip size (default: the preset's)")
    parser.add_argument("--workers", default="1,2", help="comma-separated worker counts (default: 1,2)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--keep", type=Path, default=None, help="keep the generated datasets under this folder")
    return parser.parse_args(argv)


def snapshot(root: Path) -> dict[str, str]:
    """Manifest text and file checksums: equal snapshots mean identical datasets."""
    from physinfer.datasets.storage import file_digest, npz_digest

    out = {"manifest": (root / "manifest.jsonl").read_text()}
    out.update({p.name: file_digest(p) for p in sorted((root / "shards").glob("*.npy"))})
    out.update({p.name: npz_digest(p) for p in sorted((root / "trajectories").glob("*.npz"))})
    return out


def pixel_differences(a: Path, b: Path) -> tuple[int, float]:
    """Largest absolute difference and fraction of differing values over two datasets' shards."""
    import numpy as np

    worst, differing, total = 0, 0, 0
    for shard in sorted((a / "shards").glob("*.npy")):
        x = np.load(shard, mmap_mode="r")
        y = np.load(b / "shards" / shard.name, mmap_mode="r")
        if x.shape != y.shape:
            return 255, 1.0
        diff = np.abs(x.astype(np.int16) - y.astype(np.int16))
        worst = max(worst, int(diff.max(initial=0)))
        differing += int(np.count_nonzero(diff))
        total += diff.size
    return worst, differing / max(total, 1)


def run(args: argparse.Namespace) -> dict[str, Any]:
    """Generate once per worker count; return the JSON report."""
    from physinfer.datasets import SplitCounts, generate_dataset, generator_for
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    generator = generator_for(registry.phenomenon(args.plugin))
    presets = generator.presets()
    if args.preset not in presets:
        raise SystemExit(f"unknown preset {args.preset!r}; choose one of {', '.join(sorted(presets))}")
    preset = presets[args.preset].with_overrides(
        sims=SplitCounts(args.sims, 0, 0),
        renders_per_sim=args.renders_per_sim,
        sims_per_unit=args.sims_per_unit,
        n_frames=args.frames,
        size=(args.size, args.size) if args.size else None,
    )
    worker_counts = [int(w) for w in args.workers.split(",")]
    base = Path(tempfile.mkdtemp(prefix="bench_flagsim_")) if args.keep is None else args.keep
    runs: list[dict[str, Any]] = []
    snapshots: list[dict[str, str]] = []
    try:
        for workers in worker_counts:
            root = base / f"workers-{workers}"
            shutil.rmtree(root, ignore_errors=True)
            print(f"generating {preset.renders.total} renders with {workers} worker(s)...", file=sys.stderr)
            t0 = time.perf_counter()
            result = generate_dataset(generator, root, preset=preset, seed=args.seed, workers=workers)
            seconds = time.perf_counter() - t0
            runs.append(
                {
                    "workers": workers,
                    "seconds": round(seconds, 3),
                    "renders": result.renders_generated,
                    "renders_per_minute": round(60.0 * result.renders_generated / seconds, 2),
                    "worker_simulate_s": round(result.worker_seconds["simulate_s"], 3),
                    "worker_render_s": round(result.worker_seconds["render_s"], 3),
                    "worker_total_s": round(result.worker_seconds["total_s"], 3),
                    "failed_sims": len(result.failed_sims),
                    "bytes": result.bytes,
                }
            )
            snapshots.append(snapshot(root))
            if len(runs) > 1:
                first = base / f"workers-{worker_counts[0]}"
                worst, fraction = pixel_differences(first, root)
                runs[-1]["max_pixel_difference_vs_first"] = worst
                runs[-1]["fraction_values_differing_vs_first"] = fraction
    finally:
        if args.keep is None:
            shutil.rmtree(base, ignore_errors=True)
    per_minute = {str(r["workers"]): r["renders_per_minute"] for r in runs}
    report: dict[str, Any] = {
        "benchmark": "flagsim_generation",
        "plugin": args.plugin,
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.system()}",
        "sims": args.sims,
        "renders_per_sim": args.renders_per_sim,
        "sims_per_unit": args.sims_per_unit,
        "clip": preset.clip.to_dict(),
        "renders_per_minute": per_minute,
        "runs": runs,
        "identical_across_workers": all(s == snapshots[0] for s in snapshots),
    }
    if "1" in per_minute and "2" in per_minute:
        report["speedup_2_vs_1"] = round(per_minute["2"] / per_minute["1"], 3)
    return report


def main() -> None:
    """Run the benchmark and print one JSON object."""
    print(json.dumps(run(parse_args())))


if __name__ == "__main__":  # worker processes are spawned: they must not rerun this
    main()
