"""Can the base model make a diagnosed target under some simulation seed? A measurement
behind docs/benchmarks.md ("Diagnose: effects on a ridge"), not a diagnosis step.

For one case folder of ``bench_diagnose.py`` (``target.mp4`` and ``diagnosis/``), the base
model is simulated at the control's fit (``diagnosis/control/gap.json``) under ``--seeds``
fresh seeds, rendered at the target's ζ and embedded as the diagnosis does; prints one JSON
object: the distances' minimum and quartiles, and how many come within the control's noise
floor and its 95th percentile (the spread between re-simulations of one θ). A target that
some seed reaches is one the base model makes, if rarely.

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_seed_search.py \\
        runs/power_rows/flag_lite-wind_shear-p0.5-s102 --seeds 40 --first-seed 6000
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_diagnose import _size_key, load_bench_registry  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("case", type=Path, help="a bench_diagnose case folder")
    parser.add_argument("--plugin", default="flag_lite")
    parser.add_argument("--frames", type=int, default=200, help="flag_lite's clip length (the rows': 200)")
    parser.add_argument("--embedder", default="spectral")
    parser.add_argument("--embedder-frames", type=int, default=200)
    parser.add_argument("--render-size", type=int, default=112)
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--first-seed", type=int, default=7000)
    args = parser.parse_args()

    from physinfer.evaluation import build_pipeline, squared_distance
    from physinfer.target import load_target

    registry = load_bench_registry(args.frames)
    pipeline = build_pipeline(registry, args.plugin, embedder=args.embedder, embedder_frames=args.embedder_frames)
    size = {_size_key(dict(pipeline.renderer.default_render_params)): args.render_size}
    target = load_target(pipeline, args.case / "target.mp4", fps=None, truth=[], render_set=size)
    target_embedding = pipeline.embedder.embed(target.clip)
    control = json.loads((args.case / "diagnosis" / "control" / "gap.json").read_text())
    params, summary = control["key"]["params"], control["summary"]
    distances = sorted(
        squared_distance(pipeline.embedder.embed(pipeline.renderer.render(
            pipeline.simulator.simulate(params, seed=seed), target.render_params)), target_embedding)
        for seed in range(args.first_seed, args.first_seed + args.seeds)
    )  # fmt: skip
    pipeline.renderer.close()
    print(json.dumps({
        "case": args.case.name, "params": params, "control_gap": summary["gap"], "floor": summary["floor"],
        "floor_q95": summary["floor_q95"], "seeds": [args.first_seed, args.first_seed + args.seeds - 1],
        "min": distances[0], "quartiles": [float(q) for q in np.quantile(distances, [0.25, 0.5, 0.75])],
        "within_floor": sum(d <= summary["floor"] for d in distances),
        "within_q95": sum(d <= summary["floor_q95"] for d in distances),
    }))  # fmt: skip


if __name__ == "__main__":
    main()
