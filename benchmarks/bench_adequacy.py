"""False alarms of the adequacy verdict on clean simulated targets.

Draws ``--targets`` θ uniformly in the normalised cube (seed ``300_000 + i``, ``i`` from ``--first``), simulates
and renders each at the phenomenon's default ζ, writes it to mp4 as a user's video would
arrive, refines it with ``physinfer refine`` defaults and records the adequacy statistic and the
motion ratio (the best fit's motion energy over the target's).
A target that the model made itself must be reproduced: every ``reproduces: false`` is a
false alarm. Prints one JSON object: per target the statistic and verdict, the share of
false alarms, and the statistic's quantiles (what a threshold would give).

Usage::

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_adequacy.py --plugin pendulum --targets 10 \
        --duration 8 --out runs/bench_adequacy
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np


def main() -> None:
    from physinfer.plugins import load_registry
    from physinfer.video import write_video

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plugin", default="pendulum")
    parser.add_argument("--targets", type=int, default=10)
    parser.add_argument("--first", type=int, default=0, help="index of the first target (its seed 300_000 + index)")
    parser.add_argument("--duration", type=float, default=None, help="seconds each target lasts")
    parser.add_argument("--out", type=Path, default=Path("runs/bench_adequacy"))
    args = parser.parse_args()
    registry, _ = load_registry()
    phenomenon = registry.phenomenon(args.plugin)
    simulator = (
        phenomenon.make_simulator([], duration_s=args.duration) if args.duration else phenomenon.make_simulator([])
    )
    renderer = phenomenon.make_renderer()
    space = simulator.parameter_space
    args.out.mkdir(parents=True, exist_ok=True)
    if any(args.out.iterdir()):
        parser.error(f"--out {args.out} is not empty: give a new folder")
    rows = []
    for i in range(args.first, args.first + args.targets):
        theta = space.from_unit(np.random.default_rng(300_000 + i).uniform(-1, 1, len(space.names)))
        video = write_video(args.out / f"target{i}.mp4", renderer.render(simulator.simulate(theta, seed=i)))
        run = args.out / f"run{i}"
        binary = Path(sys.executable).parent / "physinfer"
        proc = subprocess.run(
            [str(binary), "refine", "--plugin", args.plugin, "--target", str(video), "--out", str(run), "--overwrite"],
            capture_output=True, text=True,
        )  # fmt: skip
        if proc.returncode != 0:
            rows.append({"target": i, "theta": theta, "error": proc.stderr.strip()[-300:]})
            print(json.dumps(rows[-1]), file=sys.stderr)
            continue
        result = json.loads((run / "result.json").read_text())
        adequacy = result.get("adequacy") or {}
        rows.append({"target": i, "theta": theta, "best": result["best_params"], "statistic": adequacy.get("statistic"),
                     "motion_ratio": (adequacy.get("motion") or {}).get("ratio"), "reproduces": adequacy.get("reproduces"), "wall_time_s": result.get("wall_time_s")})  # fmt: skip
        print(json.dumps(rows[-1]), file=sys.stderr)
    renderer.close()
    stats = np.array([r["statistic"] for r in rows if r.get("statistic") is not None], dtype=float)
    summary = {
        "plugin": args.plugin,
        "targets": len(rows),
        "false_alarms": sum(r.get("reproduces") is False for r in rows),
        "statistic_quantiles": {q: float(np.quantile(stats, q)) for q in (0.5, 0.9, 0.95, 1.0)} if len(stats) else None,
        "motion_ratio_range": _range([r.get("motion_ratio") for r in rows]),
        "rows": rows,
    }
    print(json.dumps(summary, indent=2))


def _range(values: list[float | None]) -> list[float] | None:
    """``[min, max]`` of the measured values (the motion check's bounds are 0.25 and 4)."""
    measured = [v for v in values if v is not None]
    return [min(measured), max(measured)] if measured else None


if __name__ == "__main__":
    main()
