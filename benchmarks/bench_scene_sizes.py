"""Flags of other sizes: what the shipped SDN, its posterior and a refinement make of them.

Issue 23, item 0: physinfer's SDN and posterior estimator were trained on 1.5 m × 1 m flags
only, and a flag twice as long flaps at about half the frequency in the same wind. This
benchmark measures, on targets of other sizes (``--sizes``, default 0.9 × 0.6 m and
3 × 2 m) at known winds (``--winds``):

- **embedding shift**: the squared SDN distance between the mean embeddings of the default
  flag and a flag of another size at the same wind, against the distance that 1 m/s more
  wind makes on the default flag, and against the seed noise (mean squared distance between
  seeds of one setting); and what 1 m/s more wind and the seed noise make on the other-size
  flag itself (can the SDN measure wind on it?); ``--seeds`` seeds each, default ζ.
- **posterior**: the wind median and 90 % interval of the shipped estimator ``infer`` picks
  for the target's scene (the one trained across sizes where it covers the size, with the
  size as input), and of the 1.5 m estimator, as ``infer`` would report it if nothing
  refused it.
- **refinement**: ``refine --steps N`` of each target (its mp4, conditioned as the CLI does)
  with ``--scene-set`` of its size (from the estimator that covers the size) and without it
  (the default 1.5 m flag and estimator): the best fit's wind error.

Usage: ``PYOPENGL_PLATFORM=egl nice -n 10 python benchmarks/bench_scene_sizes.py --steps 16``.
Prints one JSON object.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from physinfer.conditioning import Conditioning
from physinfer.evaluation import build_pipeline, squared_distance
from physinfer.plugins import load_registry
from physinfer.roles import Target
from physinfer.session import refine


def truth_at(space, wind: float) -> dict[str, float]:
    """The embedded target's truth (bending ×1, area weight 0.12) at ``wind``."""
    truth = space.defaults()
    truth.update({n: 1.0 for n in truth if n.startswith("bend_")})
    truth.update(wind_speed=wind, area_weight=0.12)
    return truth


def scene_of_size(size: tuple[float, float]) -> dict[str, float]:
    return {"flag_length": size[0], "flag_height": size[1]}


def clips(pipeline, params: dict[str, float], seeds: list[int]) -> list:
    zeta = pipeline.renderer.default_render_params
    return [
        pipeline.renderer.render(pipeline.simulator.simulate(params, seed=s), zeta) for s in seeds
    ]


def mean_within(e: np.ndarray) -> float:
    return float(np.mean([squared_distance(a, b) for a, b in itertools.combinations(e, 2)]))


def embedding_shift(registry, sizes, winds, seeds) -> list[dict]:
    """Per wind and size: SDN distance of the size change vs +1 m/s vs seed noise."""
    base = build_pipeline(registry, "flag", embedder="sdn", device="cpu")
    rows = []
    for wind in winds:
        truth = truth_at(base.simulator.parameter_space, wind)
        e0 = base.embedder.embed_many(clips(base, truth, seeds))
        e1 = base.embedder.embed_many(clips(base, {**truth, "wind_speed": wind + 1.0}, seeds))
        wind_d = squared_distance(e0.mean(0), e1.mean(0))
        noise = mean_within(e0)
        for size in sizes:
            other = build_pipeline(registry, "flag", embedder="", scene_set=scene_of_size(size))
            es = base.embedder.embed_many(clips(other, truth, seeds))
            # What the SDN sees of wind on this flag itself: +1 m/s and the seed noise.
            es1 = base.embedder.embed_many(clips(other, {**truth, "wind_speed": wind + 1.0}, seeds))
            other.renderer.close()
            size_d = squared_distance(e0.mean(0), es.mean(0))
            rows.append(
                {
                    "wind": wind,
                    "size": list(size),
                    "size_shift": size_d,
                    "wind_plus_1_shift": wind_d,
                    "seed_noise": noise,
                    "size_over_wind": size_d / wind_d,
                    "own_wind_plus_1_shift": squared_distance(es.mean(0), es1.mean(0)),
                    "own_seed_noise": mean_within(es),
                }
            )
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    base.renderer.close()
    return rows


def run(args: argparse.Namespace) -> dict:
    from physinfer.posterior.workflow import (
        estimator_embedder,
        load_estimator,
        posterior_of_clip,
    )
    from physinfer.video import write_video

    registry, _ = load_registry()
    sizes = [tuple(float(v) for v in s.split("x")) for s in args.sizes.split(",")]
    winds = [float(w) for w in args.winds.split(",")]
    seeds = list(range(1, args.seeds + 1))
    t0 = time.perf_counter()
    shift = embedding_shift(registry, sizes, winds, seeds)
    t_shift = time.perf_counter() - t0
    if args.shift_only:
        return {"benchmark": "scene_sizes", "date": time.strftime("%Y-%m-%d"), "args": vars(args),
                "embedding_shift": shift, "seconds": {"embedding_shift": t_shift}}  # fmt: skip
    from physinfer.scene import default_scene

    phenomenon = registry.phenomenon("flag")
    estimator, path = load_estimator(registry, "flag", None, "cpu")
    post_pipe = estimator_embedder(registry, estimator, "cpu")
    targets, work = [], Path(tempfile.mkdtemp(prefix="bench_scene_"))
    for size in sizes:
        pipeline = build_pipeline(registry, "flag", embedder="", scene_set=scene_of_size(size))
        for wind in winds:
            truth = truth_at(pipeline.simulator.parameter_space, wind)
            target = Target.synthetic(
                pipeline.simulator, pipeline.renderer, truth, seed=12345, description=""
            )
            video = work / f"target_{size[0]:g}x{size[1]:g}_{wind:g}.mp4"
            write_video(video, target.clip)
            report = posterior_of_clip(
                estimator, post_pipe.embedder, target.clip, n_samples=2000, seed=0
            )
            m = report.marginals["wind_speed"]
            row = {
                "size": list(size),
                "wind": wind,
                "posterior_wind_median": m["median"],
                "posterior_wind_ci90": m["ci90"],
                "posterior_covers_truth": m["ci90"][0] <= wind <= m["ci90"][1],
            }
            scene = {**default_scene(phenomenon), **scene_of_size(size)}
            chosen, chosen_path = load_estimator(registry, "flag", None, "cpu", scene=scene)
            if chosen_path != path:  # a shipped estimator covers this size: what infer reports
                chosen_pipe = estimator_embedder(registry, chosen, "cpu")
                m = posterior_of_clip(
                    chosen, chosen_pipe.embedder, target.clip, n_samples=2000, seed=0, scene=scene
                ).marginals["wind_speed"]
                chosen_pipe.renderer.close()
                row["scene_posterior"] = {
                    "estimator": str(chosen_path),
                    "wind_median": m["median"],
                    "wind_ci90": m["ci90"],
                    "covers_truth": m["ci90"][0] <= wind <= m["ci90"][1],
                }
            if args.steps == 0:
                targets.append(row)
                print(json.dumps(row), file=sys.stderr, flush=True)
                continue
            for label, scene in (("with_scene", scene_of_size(size)), ("without_scene", None)):
                t1 = time.perf_counter()
                result = refine(
                    registry, plugin="flag", target_path=video, truth=[f"wind_speed={wind}"], steps=args.steps,
                    seed=0, out=work / f"run_{video.stem}_{label}", progress=False, noise_samples=0,
                    floor_samples=0, scene_set=scene, device="cpu", conditioning=Conditioning(),
                )  # fmt: skip
                posterior = result.target_posterior
                row[label] = {
                    "wind": result.best_params["wind_speed"],
                    "wind_error": abs(result.best_params["wind_speed"] - wind),
                    "posterior_note": posterior.note if posterior is not None else None,
                    "posterior_used": posterior is not None and posterior.marginals is not None,
                    "seconds": time.perf_counter() - t1,
                }
            targets.append(row)
            print(json.dumps(row), file=sys.stderr, flush=True)
        pipeline.renderer.close()
    post_pipe.renderer.close()
    arms = ("with_scene", "without_scene") if args.steps else ()
    errors = {k: [r[k]["wind_error"] for r in targets] for k in arms}
    return {
        "benchmark": "scene_sizes",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
        "date": time.strftime("%Y-%m-%d"),
        "args": vars(args),
        "estimator": str(path),
        "embedding_shift": shift,
        "targets": targets,
        "median_wind_error": {k: float(np.median(v)) for k, v in errors.items()},
        "seconds": {"embedding_shift": t_shift, "total": time.perf_counter() - t0},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--sizes", default="0.9x0.6,3x2", help="LxH flag sizes in metres, comma-separated"
    )
    parser.add_argument("--winds", default="3,6", help="target wind speeds in m/s")
    parser.add_argument(
        "--seeds", type=int, default=3, help="seeds per setting for the embedding shift"
    )
    parser.add_argument(
        "--shift-only", action="store_true", help="only the embedding shift (no posteriors, no refinements)"
    )
    parser.add_argument(
        "--steps", type=int, default=16, help="refinement budget per target (0: no refinements)"
    )
    print(json.dumps(run(parser.parse_args())))


if __name__ == "__main__":
    main()
