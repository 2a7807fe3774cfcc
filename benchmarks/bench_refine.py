"""Accuracy and speed of ``physinfer refine`` on held-out synthetic targets.

For each of ``--targets`` targets, θ is drawn uniformly in the normalised cube and ζ from
the renderer's dataset distribution, both from seeds no dataset uses (``100_000 + i``);
the target is simulated under its own seed (``200_000 + i``) while every refinement
simulates under seed 0, so no target is the realisation any trial can reproduce — as with a
real video. Each target is refined with every optimizer in ``--optimizers`` at the same
budget, render parameters fixed to the target's (oracle ζ, as the paper).

Prints one JSON object with, for the first optimizer (``ax`` by default):
``wall_time_s`` (median over targets of one refinement, noise measurement included) and its
split ``bo_s``, ``simulate_s``, ``render_s``, ``embed_s``, ``step_s`` (simulate + render +
embed per step), ``median_wind_abs_error``, ``share_wind_within_0_5``,
``median_area_weight_abs_error``, ``median_noise_ratio`` (gap / floor at the best fit), and
``by_optimizer`` with the same accuracy keys for every optimizer. Each finished refinement is
appended to ``--out/results.jsonl``, so an interrupted benchmark continues where it stopped.

Usage::

    PYOPENGL_PLATFORM=egl python benchmarks/bench_refine.py --plugin flag --steps 40 --targets 20 \
        --optimizers ax,random,cma --out runs/bench_refine

On a machine with more cores, run ``--shard 0/2`` and ``--shard 1/2`` (same ``--out``) as two
processes; each prints the summary of every row logged so far. Wall times then include the
other shard's load.

Variants (each its own rows in ``results.jsonl``): ``--fix NAME=VALUE`` holds parameters;
``--select-top M`` reports the best of the M best trials re-simulated under fresh seeds
(``--reuse-trials`` continues finished runs in ``--out`` instead of re-running them);
``--duration S`` makes every simulation, the targets' included, record S seconds (with
``--weights`` of an SDN trained on clips that long, or ``--embedder spectral
--embedder-frames N`` so the parameter-free embedder reads N frames instead of 30; as
``refine --duration / --embedder-frames``); ``--batch-size Q`` proposes and simulates Q
trials per optimizer step (``step_s`` then counts each trial's share of its
batch's time); ``--posterior shipped|FILE`` refines as ``refine`` does with an estimator
(first trial at the amortized posterior's median, the search confined to its box;
``--no-box``: the whole space) and records per target the posterior ``refine`` reports
(refined from the trials: the amortized samples reweighted by their likelihood, or the
amortized one where the trials give none), the amortized one, and the one refined with the
box proposal (``prior × likelihood`` alone): for each, how many
90 % wind intervals cover the truth, the posterior median's error and the interval's width.
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

from physinfer.evaluation import build_pipeline
from physinfer.fixed import split_fixed
from physinfer.io import atomic_write_json
from physinfer.loop import run_refinement
from physinfer.plugins import load_registry
from physinfer.refinement import SearchSpec
from physinfer.roles import Target
from physinfer.rundir import RunDirectory

THETA_SEED, TARGET_SIM_SEED = 100_000, 200_000


def make_target(pipeline: Any, index: int) -> Target:
    """Held-out target ``index``: seeded θ, ζ and simulation seed.

    Drawn over every parameter, fixed ones included: with ``--fix`` the refinement holds
    them at a guess while the target has its own values, as with a real video.
    """
    simulator = split_fixed(pipeline.simulator)[0]
    space = simulator.parameter_space
    rng = np.random.default_rng(THETA_SEED + index)
    truth = space.from_unit(rng.uniform(-1.0, 1.0, len(space)))
    zeta = pipeline.renderer.sample_render_params(rng)
    trajectory = simulator.simulate(truth, seed=TARGET_SIM_SEED + index)
    clip = pipeline.renderer.render(trajectory, zeta)
    return Target(clip=clip, truth=truth, render_params=zeta, description=f"held-out target {index}")


def refine_one(pipeline: Any, registry: Any, target: Target, optimizer: str, args: argparse.Namespace, out: Path) -> dict:
    """One refinement; returns its row for ``results.jsonl``."""
    config = SearchSpec(
        steps=args.steps,
        optimizer=optimizer,
        seed=0,
        noise_samples=args.noise_samples,
        seeds_per_trial=args.seeds_per_trial,
        floor_samples=args.floor_samples,
        select_top=args.select_top,
        select_seeds=args.select_seeds,
        batch_size=args.batch_size,
    )
    run_dir = RunDirectory(out)
    info = {"plugin": args.plugin, "optimizer": optimizer, "seed": 0, "effects": [], "embedder": args.embedder,
            "parameters": pipeline.simulator.parameter_space.to_dict(), "overwrite": True,
            "seeds_per_trial": args.seeds_per_trial}
    fixed = split_fixed(pipeline.simulator)[1]
    if fixed:
        info["fixed"] = fixed
    factory = registry.get("optimizers", optimizer).load()
    amortized = None
    start = time.perf_counter()
    if args.posterior:  # as `refine` does: start at the posterior median, search its box
        from physinfer.discrepancy.warmstart import warm_start_factory
        from physinfer.posterior.refined import posterior_start
        from physinfer.posterior.workflow import posterior_for_refinement

        estimator = None if args.posterior == "shipped" else Path(args.posterior)
        if estimator is None:
            from physinfer.posterior.workflow import load_estimator

            estimator = load_estimator(registry, args.plugin, None)[1]
        amortized, _ = posterior_for_refinement(
            registry, plugin=args.plugin, parameter_space=pipeline.simulator.parameter_space, clip=target.clip,
            posterior=estimator, seed=0,
        )
        post_start = posterior_start(amortized, pipeline.simulator.parameter_space)
        factory = warm_start_factory(factory, post_start.start_x, None if args.no_box else post_start.box)
    # The trials do not depend on the selection, so a finished run of the same settings is
    # continued (nothing re-simulated but the selection and the floor) instead of re-run.
    resume = args.reuse_trials and run_dir.run_file.is_file() and len(run_dir.read_trials()) >= args.steps
    result = run_refinement(pipeline, target, factory, run_dir, config, run_info=info, resume=resume)
    posterior_rows = {}
    if amortized is not None:
        posterior_rows = _posterior_rows(result, amortized, pipeline.simulator.parameter_space, post_start, target, out)
    wall = time.perf_counter() - start
    floor = result.noise.floor or {}  # the loop always reports its noise
    return {
        "optimizer": optimizer,
        "wall_time_s": wall,
        "bo_s": result.timings["optimizer_s"],
        "simulate_s": result.timings["simulate_s"],
        "render_s": result.timings["render_s"],
        "embed_s": result.timings["embed_s"],
        "abs_errors": result.abs_errors,
        "best_distance": result.best_distance,
        "noise_ratio": floor.get("ratio"),
        "observation_sem": result.noise.observation_sem,
        "n_failed": result.n_failed,
        "trials_reused": resume,
        "selection_s": (result.selection or {}).get("selection_s"),
        **posterior_rows,
    }


def _posterior_rows(result: Any, amortized: Any, space: Any, post_start: Any, target: Target, out: Path) -> dict:
    """The target's posterior as `refine` reports it (refined from the trials where they give
    one: the amortized samples reweighted by the trials' likelihood), the amortized one it
    started from, and the one refined with the other proposal (uniform over the search box):
    one row each."""
    from physinfer.posterior.refined import refine_posterior, report_posterior, trial_arrays

    report_posterior(result, amortized, space, post_start, out, seed=0)
    box, _ = refine_posterior(
        amortized.samples_unit, amortized.marginals, space, *trial_arrays(result, len(space.names)),
        (result.noise.floor or {}).get("pairwise") or [], post_start.box, method="box", seed=0,
    )
    return {
        "posterior": _posterior_row(result.target_posterior.marginals, target.truth),
        "posterior_kind": result.target_posterior.source["kind"],
        "posterior_amortized": _posterior_row(amortized.marginals, target.truth),
        "posterior_box": _posterior_row(box.marginals, target.truth) if box else None,
    }


def _posterior_row(marginals: dict, truth: dict) -> dict:
    """Wind and area-weight intervals, whether they cover the truth, and the median's errors."""
    row: dict[str, Any] = {}
    for name in ("wind_speed", "area_weight"):
        if name in marginals:
            m = marginals[name]
            row[name] = {
                "median": m["median"], "ci90": m["ci90"], "label": m["label"],
                "covers": bool(m["ci90"][0] <= truth[name] <= m["ci90"][1]),
                "median_abs_error": abs(m["median"] - truth[name]),
                "ci90_width": m["ci90"][1] - m["ci90"][0],
            }
    return row


def _same_run(a: dict, b: dict) -> bool:
    """Settings equal apart from the number of targets and the optimizer list."""
    ignore = {"targets", "optimizers", "shard"}
    return {k: v for k, v in a.items() if k not in ignore} == {k: v for k, v in b.items() if k not in ignore}


def parse_shard(text: str) -> tuple[int, int]:
    """``"K/N"`` → ``(K, N)`` with ``0 <= K < N``."""
    try:
        k, n = (int(part) for part in text.split("/"))
    except ValueError:
        k, n = -1, 0
    if not 0 <= k < n:
        raise SystemExit(f"--shard {text!r}: give K/N with 0 <= K < N, for example 0/2 and 1/2 for two processes")
    return k, n


def logged_rows(log: Path, settings: dict) -> dict[tuple[int, str], dict]:
    """Rows of ``results.jsonl`` run with these settings, by (target, optimizer).

    How many targets and which optimizers a run asked for do not change a row, so a run
    can be extended; rows run with other settings are ignored.
    """
    done: dict[tuple[int, str], dict] = {}
    if log.exists():
        for line in log.read_text().splitlines():
            row = json.loads(line)
            if _same_run(row.get("settings", {}), settings):
                done[(row["target"], row["optimizer"])] = row
    return done


def accuracy(rows: list[dict]) -> dict[str, Any]:
    """Median errors and the share of wind errors within 0.5 m/s (and, with a posterior, how
    often its 90 % interval covered the true wind)."""
    wind = [r["abs_errors"]["wind_speed"] for r in rows if "wind_speed" in r["abs_errors"]]
    area = [r["abs_errors"]["area_weight"] for r in rows if "area_weight" in r["abs_errors"]]
    ratios = [r["noise_ratio"] for r in rows if r.get("noise_ratio") is not None]
    return {
        "n_targets": len(rows),
        "median_wind_abs_error": statistics.median(wind) if wind else None,
        "share_wind_within_0_5": float(np.mean(np.asarray(wind) <= 0.5)) if wind else None,
        "median_area_weight_abs_error": statistics.median(area) if area else None,
        "median_noise_ratio": statistics.median(ratios) if ratios else None,
        "median_wall_time_s": statistics.median(r["wall_time_s"] for r in rows),
        **_coverage(rows),
    }


def _coverage(rows: list[dict]) -> dict[str, Any]:
    """Per posterior variant: targets whose 90 % wind interval covers the truth, the median
    error of the posterior median, the median interval width."""
    out: dict[str, Any] = {}
    for key in ("posterior", "posterior_amortized", "posterior_box"):
        winds = [r[key]["wind_speed"] for r in rows if (r.get(key) or {}).get("wind_speed")]
        if winds:
            out[key] = {
                "n": len(winds),
                "wind_ci90_covers": sum(p["covers"] for p in winds),
                "median_wind_abs_error": statistics.median(p["median_abs_error"] for p in winds),
                "share_wind_within_0_5": float(np.mean([p["median_abs_error"] <= 0.5 for p in winds])),
                "median_wind_ci90_width": statistics.median(p.get("ci90_width", float("nan")) for p in winds),
            }
    if "posterior" in out:
        out["refined_targets"] = sum(r.get("posterior_kind") == "refined" for r in rows)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plugin", default="flag")
    parser.add_argument("--steps", type=int, default=40)
    parser.add_argument("--targets", type=int, default=20)
    parser.add_argument("--optimizers", default="ax,random,cma")
    parser.add_argument("--embedder", default=None, help="default: the phenomenon's")
    parser.add_argument("--weights", default=None, help="embedder weights (default: shipped)")
    parser.add_argument("--duration", type=float, default=None,
                        help="seconds every simulation records, targets included (e.g. 4 for a 100-frame SDN)")
    parser.add_argument("--embedder-frames", type=int, default=None,
                        help="frames the spectral embedder reads (default 30; e.g. 200 with --duration 8)")
    parser.add_argument("--noise-samples", type=int, default=3)
    parser.add_argument("--seeds-per-trial", type=int, default=1)
    parser.add_argument("--floor-samples", type=int, default=4)
    parser.add_argument("--select-top", type=int, default=0,
                        help="report the best of the M best trials re-simulated under --select-seeds fresh seeds")
    parser.add_argument("--select-seeds", type=int, default=3)
    parser.add_argument("--batch-size", type=int, default=1,
                        help="trials per optimizer step, simulated as one batch (refine --batch-size)")
    parser.add_argument("--reuse-trials", action="store_true",
                        help="continue finished runs in --out instead of re-running them (e.g. to add --select-top)")
    parser.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                        help="hold parameters fixed in the refinements, as `physinfer refine --fix` (repeatable)")
    parser.add_argument("--posterior", default=None, metavar="shipped|FILE",
                        help="refine as `refine --posterior` does: the target's amortized posterior (the plugin's "
                        "shipped estimator, or FILE) gives the start and the intervals recorded per row")
    parser.add_argument("--no-box", action="store_true",
                        help="with --posterior: search the whole space (start at the median only)")
    parser.add_argument("--out", default="runs/bench_refine")
    parser.add_argument("--shard", default="0/1", help="K/N: run only targets with index %% N == K, so N "
                        "processes (or machines sharing --out) split the work; the summary covers every row logged")
    args = parser.parse_args()
    shard, n_shards = parse_shard(args.shard)

    registry, _ = load_registry()
    pipeline = build_pipeline(registry, args.plugin, embedder=args.embedder,
                              weights=Path(args.weights) if args.weights else None, fixed=args.fix,
                              duration_s=args.duration, embedder_frames=args.embedder_frames)
    args.embedder = args.embedder or pipeline.phenomenon.default_embedder
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "results.jsonl"
    settings = {k: v for k, v in vars(args).items() if k not in ("out", "shard")}
    if not args.fix:
        del settings["fix"]  # rows logged before --fix existed stay reusable
    if not args.select_top:
        del settings["select_top"], settings["select_seeds"]  # and rows from before --select-top
    del settings["reuse_trials"]  # how the trials were obtained does not change them
    if args.duration is None:
        del settings["duration"]  # rows from before --duration stay reusable
    if args.embedder_frames is None:
        del settings["embedder_frames"]  # and rows from before --embedder-frames
    if args.batch_size == 1:
        del settings["batch_size"]  # and rows from before --batch-size
    if args.posterior is None:
        del settings["posterior"]  # and rows from before --posterior
    if not args.no_box:
        del settings["no_box"]
    if args.posterior is not None:
        settings["refined_method"] = "product"  # rows before it was the default reported "box"
    done = logged_rows(log, settings)
    optimizers = [o.strip() for o in args.optimizers.split(",") if o.strip()]
    for index in range(shard, args.targets, n_shards):
        target = None
        for optimizer in optimizers:
            if (index, optimizer) in done:
                continue
            target = target or make_target(pipeline, index)
            row = refine_one(pipeline, registry, target, optimizer, args, out / f"t{index:02d}-{optimizer}")
            row.update(target=index, settings=settings, truth={k: target.truth[k] for k in ("wind_speed", "area_weight") if k in target.truth})
            with log.open("a") as fh:  # one write of one line: shards appending at once do not interleave
                fh.write(json.dumps(row) + "\n")
            done[(index, optimizer)] = row
            print(f"target {index} {optimizer}: wind err {row['abs_errors'].get('wind_speed', float('nan')):.3f} "
                  f"wall {row['wall_time_s']:.1f} s", file=sys.stderr, flush=True)
    pipeline.renderer.close()

    done = logged_rows(log, settings)  # other shards' rows too
    wanted = [r for r in done.values() if r["target"] < args.targets]
    by_optimizer = {o: accuracy([r for r in wanted if r["optimizer"] == o]) for o in optimizers}
    first = [r for r in wanted if r["optimizer"] == optimizers[0]]
    phases = {k: statistics.median(r[k] for r in first) for k in ("wall_time_s", "bo_s", "simulate_s", "render_s", "embed_s")}
    report = {
        "benchmark": "refine",
        "plugin": args.plugin,
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs, {platform.system()}",
        "settings": settings,
        **phases,
        "step_s": (phases["simulate_s"] + phases["render_s"] + phases["embed_s"]) / args.steps,
        **{k: v for k, v in by_optimizer[optimizers[0]].items() if k != "median_wall_time_s"},
        "by_optimizer": by_optimizer,
        "load_average": os.getloadavg()[0],
    }
    atomic_write_json(out / "summary.json", report)
    print(json.dumps(report))


if __name__ == "__main__":
    main()
