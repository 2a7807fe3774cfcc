"""Benchmark of ``physinfer diagnose``: does it name a hidden effect, and only then?

For each hidden effect of a phenomenon (and for "none"), and each seed, a target video is
simulated with that effect switched on at a realistic strength (random base θ and effect
strength, seeded), written to MP4, and diagnosed with every registered effect as a
candidate. Prints one JSON object: ``cases`` (one per diagnosis), ``named_correctly``
(hidden-effect cases whose effect was named), ``false_discoveries`` (no-effect cases
declared misspecified or given a name), ``wrong_names`` (hidden-effect cases given another
effect's name), ``median_gap_ratio`` (gap_after / gap_before over the hidden-effect cases)
and ``confusion`` (hidden → named → count).

Each case's row is also written to ``<out>/<case>/case.json``, so a table can be split over
processes (``--shard K/N`` with a shared ``--out``) and summarised afterwards from the rows
on disk (``--merge``, the same case options, nothing is run). A case whose directory holds
finished stages continues from them.

Example (the numbers in docs/benchmarks.md)::

    PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_diagnose.py --plugin pendulum_lab \\
        --seeds 5 --steps 16 --optimizer ax --render-size 48 --out /tmp/bench_diagnose

    # the flag table in two processes, then the summary of both
    ... bench_diagnose.py --plugin flag_lite --embedder spectral ... --shard 0/2 --out DIR &
    ... bench_diagnose.py --plugin flag_lite --embedder spectral ... --shard 1/2 --out DIR
    ... bench_diagnose.py --plugin flag_lite --embedder spectral ... --merge --out DIR

``--timing`` diagnoses each case from scratch once per ``--timing-modes`` mode — ``w1-all``
(one process, every self-consistency run refined: how the stored tables were made), ``all``
(workers, every run), ``needed`` (workers, only the runs a decision needs: the default) —
prints the wall time per diagnosis and per stage, and exits 1 when any decision (named
effect, misspecified, each candidate's significance) differs between the modes.
``--timing-reuse`` takes a mode's row from an earlier invocation's ``case-timing-*.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

#: Realistic effect strengths: (low, high) per effect parameter, drawn uniformly; a
#: parameter listed with a sign choice is given a random sign.
STRENGTHS: dict[str, dict[str, tuple[float, float]]] = {
    "quadratic_drag": {"drag_quadratic": (0.8, 1.6)},
    "wind_gusts": {"gust_intensity": (0.25, 0.35), "gust_timescale": (0.4, 1.0)},
    "wind_shear": {"shear_exponent": (0.3, 0.45)},
    "wind_yaw": {"wind_yaw_deg": (25.0, 40.0)},
    "wind_inclination": {"wind_inclination_deg": (10.0, 20.0)},
}
SIGNED = {"wind_yaw_deg", "wind_inclination_deg"}
#: Base θ drawn from this central share of each parameter's normalised range ...
BASE_BOX = 0.6
#: ... except these, drawn from a physical range: drag grows with the swing's speed, so the
#: pendulum starts high enough for it to matter (below ~30° linear damping mimics it).
BASE_RANGES: dict[str, tuple[float, float]] = {"amplitude": (35.0, 55.0)}


def flag_lite(**config: Any) -> Any:
    """The flag phenomenon on a coarse grid with the bending held at 1× (still named ``flag``).

    The flag's 15 bending multipliers make a 17-dimensional search that a dozen trials
    cannot cover; ``flag_lite`` holds them at 1 (the material's own stiffness, which the
    targets use too), leaving wind speed, area weight and the effect's parameters to refine.
    """
    import dataclasses

    from physinfer.fixed import FixedParameters
    from physinfer_flag.phenomenon import make_phenomenon
    from physinfer_flag.simulator import flag_parameter_space, make_simulator

    full = make_phenomenon()
    fixed = {s.name: 1.0 for s in flag_parameter_space() if s.name.startswith("bend_")}
    settings = {"grid_u": 16, "grid_v": 11, "n_frames": 40, "warmup_s": 1.5, **config}
    lite_space = FixedParameters(make_simulator((), **settings), fixed).parameter_space

    def make(effects: Any = ()) -> Any:
        return FixedParameters(make_simulator(effects, **settings), fixed)

    return dataclasses.replace(full, parameter_space=lite_space, make_simulator=make)


def importable(function: Any) -> Any:
    """``function`` as imported from this file by its module name: a diagnosis' worker
    processes do not import the parent's ``__main__`` (physinfer.datasets.executors), so a
    registry factory pickled as ``__main__.load_bench_registry`` could not be read there (a
    pendulum table with ``--workers 2`` stopped on it). ``sys.path`` reaches the workers."""
    if function.__module__ != "__main__":
        return function
    import importlib

    folder = str(Path(__file__).resolve().parent)
    if folder not in sys.path:
        sys.path.insert(0, folder)
    return getattr(importlib.import_module(Path(__file__).stem), function.__name__)


def load_bench_registry(frames: int | None = None) -> Any:
    """The installed plugins plus the benchmark's ``flag_lite`` phenomenon (``frames`` long clips)."""
    from physinfer.plugins import load_registry

    registry, _ = load_registry()
    if "flag" in registry.entries["phenomena"]:
        lengths = {} if frames is None else {"n_frames": frames}
        registry.scoped("bench_diagnose").add_phenomenon(
            "flag_lite", lambda **config: flag_lite(**{**lengths, **config}), "flag, coarse, bending fixed"
        )
    return registry


def make_target(registry: Any, plugin: str, hidden: str | None, seed: int, render_size: int | None,
                path: Path, strength: float | None = None) -> dict[str, float]:
    """Simulate, render and write one target; returns its true parameters.

    ``strength``: the hidden effect's parameters that far along their path from off to the
    far end of their range (:func:`physinfer.discrepancy.ladder.strength_path`; the power
    curves) instead of a random realistic strength.
    """
    from physinfer.evaluation import build_pipeline
    from physinfer.video import write_video

    pipeline = build_pipeline(registry, plugin, effects=[hidden] if hidden else [], embedder="")
    truth, rng = base_truth(pipeline.phenomenon.parameter_space, seed)
    if hidden and strength is not None:
        from physinfer.discrepancy.ladder import strength_path, values_at

        effect_space = pipeline.effects[0].parameter_space
        truth.update(values_at(effect_space, *strength_path(effect_space), strength))
    elif hidden:
        for name, (lo, hi) in STRENGTHS[hidden].items():
            value = float(rng.uniform(lo, hi))
            truth[name] = value * (rng.choice([-1.0, 1.0]) if name in SIGNED else 1.0)
    zeta = dict(pipeline.renderer.default_render_params)
    if render_size is not None:
        zeta[_size_key(zeta)] = render_size
    clip = pipeline.renderer.render(pipeline.simulator.simulate(truth, seed=1000 + seed), zeta)
    pipeline.renderer.close()
    path.parent.mkdir(parents=True, exist_ok=True)
    # Lossless: a lossy encoding of the same frames differed from run to run (physinfer.video),
    # and with it every trial of the case's diagnosis.
    write_video(path, clip, lossless=True)
    return truth


def base_truth(base_space: Any, seed: int) -> tuple[dict[str, float], np.random.Generator]:
    """The base θ of case ``seed`` (for flag_lite without the fixed bending) and the generator after it."""
    rng = np.random.default_rng([seed, 2026])
    truth = base_space.from_unit(rng.uniform(-BASE_BOX, BASE_BOX, len(base_space)))
    for name, (lo, hi) in BASE_RANGES.items():
        if name in truth:
            truth[name] = float(rng.uniform(lo, hi))
    return truth, rng


def ladder_case(registry: Any, plugin: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    """``--ladder-only``: the detection limits at case ``seed``'s true base θ, without a diagnosis.

    The base fit is taken to be perfect (θ̂ = the truth) and the null scale to be
    ``--null-over-floor`` noise floors (the floor measured here from ``--floor-samples``
    re-simulations): what a diagnosis' self-consistency runs would measure, read off the
    stored tables. Cheap enough for the flag, whose full diagnosis costs tens of minutes.
    """
    from physinfer.discrepancy.candidates import augmented_pipeline
    from physinfer.discrepancy.decide import DecisionRule
    from physinfer.discrepancy.ladder import LimitInputs
    from physinfer.discrepancy.limits import detection_limits
    from physinfer.discrepancy.settings import LimitConfig
    from physinfer.evaluation import build_pipeline, measure_noise_floor, noise_seeds

    t0 = time.perf_counter()
    base = build_pipeline(registry, plugin, embedder=args.embedder, embedder_frames=args.embedder_frames)
    theta, _ = base_truth(base.phenomenon.parameter_space, seed)
    zeta = dict(base.renderer.default_render_params)
    if args.render_size is not None:
        zeta[_size_key(zeta)] = args.render_size
    floor = measure_noise_floor(base, theta, zeta, seeds=noise_seeds(seed + 2, args.floor_samples))
    effects = args.effects if args.effects is not None else registry.effects_of(base.phenomenon.name)
    augmented = {e: augmented_pipeline(base, [registry.effect(e, phenomenon=base.phenomenon.name)]) for e in effects}
    scale = args.null_over_floor * floor.floor
    inputs = LimitInputs(base=base, augmented=augmented, theta=theta, base_embeddings=floor.embeddings,
                         render_params=zeta, scale=scale, rule=DecisionRule(), floor_samples=args.floor_samples,
                         seed=seed, diagnosis_simulations=args.diagnosis_simulations)
    limits = detection_limits(inputs, LimitConfig(reveal=args.reveal))
    base.renderer.close()
    return {"seed": seed, "theta": theta, "floor": floor.floor, "null_scale": scale,
            "effects": {e: {**{k: lim[k] for k in ("detectable_from", "fraction", "reason", "reveal", "threshold")},
                            "rungs": [{k: r[k] for k in ("fraction", "shift", "floor", "threshold", "refit_gap",
                                                         "measured")} for r in lim["rungs"]]}
                        for e, lim in limits["effects"].items()},
            **{k: limits[k] for k in ("simulations", "seeds", "clip_seconds", "wall_time_s")},
            "wall_time_s": time.perf_counter() - t0}


def _size_key(zeta: dict[str, Any]) -> str:
    return "image_size" if "image_size" in zeta else "size"


def case_dir_of(plugin: str, hidden: str | None, seed: int, out: str, strength: float | None = None) -> Path:
    """The directory of one case (target, truth, diagnosis stages, row)."""
    power = "" if strength is None else f"-p{strength:g}"
    return Path(out) / f"{plugin}-{hidden or 'none'}{power}-s{seed}"


def run_case(plugin: str, hidden: str | None, seed: int, args: argparse.Namespace,
             strength: float | None = None, workers: int | None = 1, subdir: str = "diagnosis",
             calibrate_all: bool | None = None, screen: bool | None = None) -> dict[str, Any]:
    """Make one target and diagnose it in ``<case>/<subdir>``; the row is also written to
    ``<subdir>``'s ``case.json`` (``case.json`` for the default ``diagnosis``).

    ``workers``: processes running the stages after the baseline (1: all in this one, as
    the stored tables were made; the decisions do not depend on it). ``calibrate_all``:
    refine every self-consistency run (``None``: ``--calibrate-all``); the decisions do not
    depend on it either. ``screen``: screen the candidates before refining them (``None``:
    unless ``--no-screen``); a screened-out candidate is recorded as not significant."""
    import functools

    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.discrepancy.workflow import run_diagnosis
    from physinfer.io import atomic_write_json

    registry = load_bench_registry(args.frames)
    case_dir = case_dir_of(plugin, hidden, seed, args.out, strength)
    truth_file = case_dir / "truth.json"
    if truth_file.is_file():
        truth = json.loads(truth_file.read_text())
    else:
        truth = make_target(registry, plugin, hidden if strength != 0 else None, seed, args.render_size,
                            case_dir / "target.mp4", strength)
        truth_file.write_text(json.dumps(truth))
    render_set = {}
    if args.render_size is not None:
        probe = registry.phenomenon(plugin).make_renderer().default_render_params
        render_set[_size_key(dict(probe))] = args.render_size
    t0 = time.perf_counter()
    report = run_diagnosis(
        registry,
        DiagnoseSettings(
            plugin=plugin,
            out=case_dir / subdir,
            target_path=case_dir / "target.mp4",
            render_set=render_set,
            steps=args.steps,
            effect_steps=args.effect_steps,
            optimizer=args.optimizer,
            embedder=args.embedder,
            embedder_frames=args.embedder_frames,
            effects=tuple(args.candidates or ()),
            fixed=tuple(f"{name}={truth[name]!r}" for name in args.fix_truth),
            seed=seed,
            floor_samples=args.floor_samples,
            select_top=args.select_top,
            select_seeds=args.select_seeds,
            batch_size=args.batch_size,
            calibration_runs=args.calibration_runs,
            calibrate_all=args.calibrate_all if calibrate_all is None else calibrate_all,
            calibration_control=not args.no_calibration_control,
            videos=False,
            limits=not args.no_limits,
            screen=not args.no_screen if screen is None else screen,
            workers=workers,
            registry_factory=functools.partial(importable(load_bench_registry), args.frames),
        ),
    )
    row = {
        "plugin": plugin,
        "hidden": hidden,
        "seed": seed,
        "named": report["named_effect"],
        "misspecified": report["misspecified"],
        "misspecified_by": report["misspecified_by"],
        "gap_before": report["gap_before"],
        "gap_after": report["gap_after"],
        "gap_ratio": report["gap_ratio"],
        "noise_floor": report["noise_floor"],
        "null_scale": report["null_scale"],
        "null_scale_range": report.get("null_scale_range"),
        "baseline_gap": report["baseline"]["gap"],
        "self_consistency_gap": report["self_consistency_gap"],
        "self_consistency_gaps": report["self_consistency_gaps"],
        "calibration": report["calibration"],
        "tested_gap": report["tested_gap"],
        "gap_before_source": report["best_baseline"]["source"],
        "threshold": report["threshold"],
        "candidates": {
            c["effect"]: {"gap": c["gap"], "ratio": c["ratio"], "p_value": c["p_value"], "significant": c["significant"],
                          "checks": c["checks"], "effect_params": c["effect_params"]}
            for c in report["candidates"]
        } | {
            c["effect"]: {"gap": None, "ratio": None, "p_value": None, "significant": False, "screened": c["reason"]}
            for c in report.get("screened") or []
        },
        "truth": truth,
        "fixed": report["settings"]["fixed"],
        "strength": strength,
        "limits": {c["effect"]: {"detectable_from": c.get("detectable_from"),
                                 "fraction": c.get("limit", {}).get("fraction"),
                                 "reason": c.get("limit", {}).get("reason")} for c in report["candidates"]}
        | {c["effect"]: {"detectable_from": None, "fraction": None, "reason": c["reason"]}
           for c in report.get("screened") or []},
        "limit_cost": report.get("limits"),
        "wall_time_s": time.perf_counter() - t0,
        "timing": report.get("timing"),
    }
    atomic_write_json(case_dir / ("case.json" if subdir == "diagnosis" else f"case-{subdir}.json"), row)
    return row


#: ``--timing-modes``: name → (workers: "one" or "K" for --workers, refine every self-consistency
#: run, screen the candidates first).
TIMING_MODES = {
    "w1-all": ("one", True, False),  # every stage in one process, as the stored tables were made
    "all": ("K", True, False),  # the stages side by side on K workers (the code of 2026-11-24 morning)
    "needed": ("K", False, False),  # side by side, only the self-consistency runs the decisions need
    "screened": ("K", False, True),  # ... and the candidates no fit could name left out (the default)
}


def decision(row: dict[str, Any]) -> tuple[Any, ...]:
    """A case's decisions, comparable: the named effect, misspecified, each candidate's significance."""
    return row["named"], row["misspecified"], tuple((e, c["significant"]) for e, c in sorted(row["candidates"].items()))


def changed_decisions(cases: list[dict[str, Any]], expected_dir: str, plugin: str) -> list[str]:
    """``--expect DIR``: one line per case whose decisions differ from its row kept under ``DIR``
    (a case DIR has no row for is listed too: a comparison that compared nothing is no pass)."""
    lines = []
    for case in cases:
        kept = case_dir_of(plugin, case["hidden"], case["seed"], expected_dir, case.get("strength")) / "case.json"
        if not kept.is_file():
            lines.append(f"{kept.parent.name}: no stored row to compare with")
        elif (old := decision(json.loads(kept.read_text()))) != (new := decision(case)):
            lines.append(f"{kept.parent.name}: stored {old}, now {new}")
    return lines


def run_timing(args: argparse.Namespace, all_cases: list[tuple[str | None, int]]) -> dict[str, Any]:
    """Each case diagnosed from scratch once per ``--timing-modes`` mode (the first is
    "before", the last "after"); wall time per diagnosis and per stage, and whether every
    decision (named effect, misspecified, each candidate's significance) is the same."""
    from physinfer.datasets.executors import default_workers

    k = args.workers or default_workers()
    modes = args.timing_modes
    rows, same = [], 0
    for hidden, seed in all_cases:
        runs = {}
        for mode in modes:
            where, every, screen = TIMING_MODES[mode]
            workers = 1 if where == "one" else k
            # The directory names of the first version of this benchmark, so its runs are reused.
            subdir = f"timing-w{workers}" + ("" if every else "-needed") + ("-screened" if screen else "")
            stored = case_dir_of(args.plugin, hidden, seed, args.out) / f"case-{subdir}.json"
            if args.timing_reuse and stored.is_file():  # a mode measured by an earlier invocation
                runs[mode] = json.loads(stored.read_text())
                continue
            runs[mode] = run_case(args.plugin, hidden, seed, args, workers=workers, subdir=subdir, calibrate_all=every,
                                  screen=screen)
            print(json.dumps({"hidden": hidden, "seed": seed, "mode": mode, "named": runs[mode]["named"],
                              "misspecified": runs[mode]["misspecified"],
                              "wall_time_s": round(runs[mode]["wall_time_s"], 1)}), file=sys.stderr, flush=True)
        decisions = {decision(r) for r in runs.values()}
        same += len(decisions) == 1
        first = runs[modes[0]]
        rows.append({"hidden": hidden, "seed": seed, "named": first["named"], "misspecified": first["misspecified"],
                     "same_decision": len(decisions) == 1,
                     **{f"wall_s_{m}": r["wall_time_s"] for m, r in runs.items()},
                     **{f"stages_s_{m}": (r["timing"] or {}).get("stages_s") for m, r in runs.items()},
                     **{f"null_scale_range_{m}": r.get("null_scale_range") for m, r in runs.items()}})

    def stats(key: str) -> dict[str, float]:
        values = [r[key] for r in rows]
        return {"median": statistics.median(values), "max": max(values)}

    return {"workers": k, "modes": modes, "cases": len(rows), "same_decisions": same,
            **{f"wall_s_{m}": stats(f"wall_s_{m}") for m in modes}, "rows": rows}


def calibration_variants(case_dir: Path, rule: dict[str, float]) -> dict[str, dict[str, Any]]:
    """The case's decisions under earlier calibrations and rules, recomputed from its stored gaps.

    The decisions are functions of the measured gaps, so one finished diagnosis (with
    ``calibration-<r>/`` and ``calibration-<r>-control/`` stages) answers what a single
    calibration run (``R1``, run 0 — the earliest default), the median of the runs without
    their controls (``R3``) and with them (``R3+control``), and the largest of the runs with
    their controls (``R3max+control``) would have decided — each with the gap test alone
    deciding misspecification, as those versions did — and what the default decides: the
    largest of the runs with their controls, misspecified by the gap test or by a
    significant effect (``R3max+control+effect``).
    """
    from physinfer.discrepancy.decide import (
        DecisionRule,
        effect_significance,
        final_verdict,
        misspecification,
        name_effect,
        null_scale,
        self_consistency_gap,
    )

    diag = case_dir / "diagnosis"
    report = json.loads((diag / "diagnosis.json").read_text())

    def gap(stage: str) -> float:
        return float(json.loads((diag / stage / "gap.json").read_text())["summary"]["gap"])

    runs = len(report["calibration"])
    plain = [gap(f"calibration-{r}") for r in range(runs)]
    mirrored = [min(gap(f"calibration-{r}"), gap(f"calibration-{r}-control")) for r in range(runs)]
    floor, q95 = report["baseline"]["floor"], report["baseline"]["floor_q95"]
    variants = {
        "R1": (self_consistency_gap(plain[:1]), report["baseline"]["gap"], False),
        "R3": (self_consistency_gap(plain, "median"), report["baseline"]["gap"], False),
        "R3+control": (self_consistency_gap(mirrored, "median"), report["gap_before"], False),
        "R3max+control": (self_consistency_gap(mirrored, "max"), report["gap_before"], False),
        "R3max+control+effect": (self_consistency_gap(mirrored, "max"), report["gap_before"], True),
    }
    out = {}
    for name, (self_gap, tested, effect_evidence) in variants.items():
        decision = DecisionRule(**rule, effect_evidence=effect_evidence)
        scale = null_scale(floor, q95, self_gap)
        candidates = [
            {**c, **effect_significance(distances=c["distances"], baseline_distances=report["best_baseline"]["to_target"],
                                        gap=c["gap"], gap_before=report["gap_before"], n_params=c["n_params"],
                                        scale=scale, rule=decision)}
            for c in report["candidates"]
        ]
        verdict = final_verdict(misspecification(tested, scale, decision), candidates, decision)
        named = name_effect(candidates, verdict["misspecified"])
        ratio = next((c["ratio"] for c in candidates if c["effect"] == named), 1.0)
        out[name] = {"self_gap": self_gap, "null_scale": scale, "tested_gap": tested,
                     "misspecified": verdict["misspecified"], "named": named, "gap_ratio": ratio}
    return out


def case_list(args: argparse.Namespace, effects: list[str]) -> list[tuple[str | None, int]]:
    """Every (hidden effect or None, seed) of the table, in run order."""
    hidden_list: list[str | None] = list(effects) + ([] if args.no_null else [None])
    return [(h, s) for s in range(args.first_seed, args.first_seed + args.seeds) for h in hidden_list]


def parse_shard(text: str | None) -> tuple[int, int]:
    """``K/N`` → ``(K, N)``; ``None`` → ``(0, 1)``."""
    if text is None:
        return 0, 1
    try:
        k, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise SystemExit(f"--shard must look like K/N (e.g. 0/2), got {text!r}") from None
    if not 0 <= k < n:
        raise SystemExit(f"--shard K/N needs 0 <= K < N, got {text!r}")
    return k, n


def summarise(cases: list[dict[str, Any]]) -> dict[str, Any]:
    """The benchmark's headline numbers and confusion table."""
    hidden_cases = [c for c in cases if c["hidden"]]
    null_cases = [c for c in cases if not c["hidden"]]
    confusion: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for c in cases:
        confusion[c["hidden"] or "none"][c["named"] or "none"] += 1
    ratios = [c["gap_ratio"] for c in hidden_cases if c["gap_ratio"] is not None]
    return {
        "n_cases": len(cases),
        "named_correctly": sum(c["named"] == c["hidden"] for c in hidden_cases),
        "n_hidden": len(hidden_cases),
        "wrong_names": sum(c["named"] not in (None, c["hidden"]) for c in hidden_cases),
        "false_discoveries": sum(c["misspecified"] or c["named"] is not None for c in null_cases),
        "n_null": len(null_cases),
        "median_gap_ratio": statistics.median(ratios) if ratios else None,
        "share_gap_halved": (sum(r <= 0.5 for r in ratios) / len(ratios)) if ratios else None,
        "confusion": {k: dict(v) for k, v in confusion.items()},
    }


def strengths_of(args: argparse.Namespace, effect: str) -> list[float]:
    """The power table's strengths for ``effect``: its ``--effect-strengths`` entry, else ``--strengths``."""
    for item in getattr(args, "effect_strengths", None) or []:
        name, sep, values = item.partition("=")
        if not sep or not values:
            raise SystemExit(f"--effect-strengths takes EFFECT=S,S,... (e.g. wind_yaw=0,0.5,1), got {item!r}")
        if name == effect:
            try:
                return [float(v) for v in values.split(",")]
            except ValueError:
                raise SystemExit(f"--effect-strengths {item!r}: the strengths must be numbers") from None
    return list(args.strengths)


def power_cases(args: argparse.Namespace, effects: list[str]) -> list[tuple[str | None, float, int, str]]:
    """Every (hidden effect or None, strength, seed, effect) of the power table; strength 0 is clean."""
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        for effect in effects:
            for strength in strengths_of(args, effect):
                rows.append((None if strength == 0 else effect, strength, seed, effect))
    return rows


def shard_of_power_cases(
    cases: list[tuple[str | None, float, int, str]], shard: int, n_shards: int
) -> set[tuple[str | None, float, int]]:
    """The diagnoses shard ``shard`` of ``n_shards`` runs: every ``n_shards``-th distinct one.

    By distinct diagnosis, not by seed: a seed's clean target serves every effect's curve
    and is diagnosed once, by one shard; and the shards get equal shares (five seeds split
    by seed over two processes gave one of them three).
    """
    distinct = list(dict.fromkeys((hidden, strength, seed) for hidden, strength, seed, _ in cases))
    return {case for i, case in enumerate(distinct) if i % n_shards == shard}


def _crossing(xs: list[float], ys: list[float], level: float) -> float | None:
    """Where the piecewise-linear curve ``ys(xs)`` first reaches ``level``."""
    for (x0, y0), (x1, y1) in zip(zip(xs, ys, strict=True), list(zip(xs, ys, strict=True))[1:], strict=False):
        if y0 < level <= y1:
            return x0 + (x1 - x0) * (level - y0) / (y1 - y0)
    return xs[0] if ys and ys[0] >= level else None


def summarise_power(rows: list[dict[str, Any]], effect: str, strengths: list[float]) -> dict[str, Any]:
    """Named-rate against strength, the ladders' predictions of it, and the half-way strengths.

    Two predictions for one target at strength ``s``: its effect would be named if the limit
    that its own diagnosis reported (a fraction of the path) is at most ``s``
    (``predicted_rate``), or if the limit reported for the *clean* target of the same seed — the
    same scene, base θ and seeds without the effect: what ``diagnose`` tells a user whose video
    showed nothing — is at most ``s`` (``predicted_from_clean``; the claim "this clip could
    reveal it from L" put to the test). The strength named half the time (``s50``,
    interpolated) is compared with the median limit over every target and over the clean ones
    (a target whose effect has no limit counts as beyond the range).
    """
    def limit_of(row: dict[str, Any]) -> float | None:
        return row["limits"].get(effect, {}).get("fraction")

    clean_limit = {r["seed"]: limit_of(r) for r in rows if r["strength"] == 0}
    per = []
    for s in strengths:
        group = [r for r in rows if r["strength"] == s]
        limits = [limit_of(r) for r in group]
        from_clean = [clean_limit.get(r["seed"]) for r in group]
        per.append({
            "strength": s,
            "n": len(group),
            "named": sum(r["named"] == effect for r in group),
            "named_other": sum(r["named"] not in (None, effect) for r in group),
            "misspecified": sum(bool(r["misspecified"]) for r in group),
            "named_rate": (sum(r["named"] == effect for r in group) / len(group)) if group else None,
            "predicted_rate": _share_at_most(limits, s),
            "predicted_from_clean": _share_at_most(from_clean, s),
            "limits": limits,
        })
    curve = [p for p in per if p["n"]]
    s50 = _crossing([p["strength"] for p in curve], [p["named_rate"] for p in curve], 0.5)
    median_limit = _median_limit([f for p in per for f in p["limits"]])
    median_clean = _median_limit(list(clean_limit.values()))
    clean = next((p for p in per if p["strength"] == 0), None)
    return {
        "effect": effect,
        "curve": per,
        "false_discoveries": None if clean is None else sum(
            bool(r["misspecified"]) or r["named"] is not None for r in rows if r["strength"] == 0),
        "n_clean": 0 if clean is None else clean["n"],
        "s50": s50,
        "median_limit": median_limit,
        "limit_over_s50": (median_limit / s50) if s50 and median_limit else None,
        "median_clean_limit": median_clean,
        "clean_limit_over_s50": (median_clean / s50) if s50 and median_clean else None,
    }


def _share_at_most(limits: list[float | None], strength: float) -> float:
    """The share of ``limits`` at most ``strength`` (none: beyond the range); 0 at strength 0."""
    if not limits or strength <= 0:
        return 0.0
    return sum(f is not None and f <= strength for f in limits) / len(limits)


def _median_limit(limits: list[float | None]) -> float | None:
    """The median of ``limits``, a missing one counted as beyond the range; ``None`` if that is the median."""
    every = sorted(math.inf if f is None else f for f in limits)
    median = statistics.median(every) if every else math.inf
    return None if math.isinf(median) else median


def plot_power(summaries: list[dict[str, Any]], registry: Any, plugin: str, path: Path) -> None:
    """Named-rate (observed, and predicted by the limits) against strength, one panel per effect."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from physinfer.discrepancy.ladder import strength_path, values_at

    fig, axes = plt.subplots(1, len(summaries), figsize=(4.2 * len(summaries), 4.0), squeeze=False)
    for ax, summ in zip(axes[0], summaries, strict=True):
        effect_space = registry.effect(summ["effect"], phenomenon=plugin_name(registry, plugin)).parameter_space
        moved, held = strength_path(effect_space)
        name = next(iter(moved))

        def value(f: float, moved: Any = moved, held: Any = held, space: Any = effect_space, name: str = name) -> float:
            return values_at(space, moved, held, f)[name]

        curve = [p for p in summ["curve"] if p["n"]]  # strengths with no finished target yet are left out
        xs = [value(p["strength"]) for p in curve]
        ax.plot(xs, [p["named_rate"] for p in curve], "o-", label="named (diagnoses)")
        ax.plot(xs, [p["predicted_rate"] for p in curve], "s--", label="predicted (its own limit)")
        ax.plot(xs, [p["predicted_from_clean"] for p in curve], "^:", label="predicted (clean target's limit)")
        for key, colour, label in (("s50", "C0", "named half the time"), ("median_limit", "C1", "median limit"),
                                   ("median_clean_limit", "C2", "median clean-target limit")):
            if summ[key] is not None:
                ax.axvline(value(summ[key]), color=colour, lw=0.8, ls=":", label=label)
        ax.set_xlabel(name)
        ax.set_ylabel("share of targets")
        ax.set_ylim(-0.05, 1.05)
        fd = summ["false_discoveries"]
        ax.set_title(f"{summ['effect']}  (false discoveries at 0: {fd}/{summ['n_clean']})", fontsize=9)
    # One legend for every panel, below them (inside, it hid the curves).
    handles = {label: h for ax in axes[0] for h, label in zip(*ax.get_legend_handles_labels(), strict=True)}
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=3, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.12, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plugin_name(registry: Any, plugin: str) -> str:
    """The phenomenon's own name (``flag_lite`` is the flag)."""
    return registry.phenomenon(plugin).name


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plugin", default="pendulum_lab")
    parser.add_argument("--effects", nargs="*", default=None, help="hidden effects (default: all of the plugin's)")
    parser.add_argument("--candidates", nargs="*", default=None, metavar="EFFECT",
                        help="effects each diagnosis tries (default: all of the plugin's)")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=16)
    parser.add_argument("--effect-steps", type=int, default=None)
    parser.add_argument("--optimizer", default="ax")
    parser.add_argument("--embedder", default=None)
    parser.add_argument("--render-size", type=int, default=None)
    parser.add_argument("--frames", type=int, default=None,
                        help="flag_lite: recorded frames per clip (default 40; grid_spectrum needs 100)")
    parser.add_argument("--embedder-frames", type=int, default=None,
                        help="frames a parameter-free embedder reads (default: its own; spectral 30)")
    parser.add_argument("--fix-truth", nargs="*", default=[], metavar="NAME",
                        help="hold these parameters fixed at each target's true values (a user who measured "
                             "them, e.g. the cloth's area weight)")
    parser.add_argument("--floor-samples", type=int, default=4)
    parser.add_argument("--select-top", type=int, default=0,
                        help="each stage re-simulates its best M trials and keeps the lowest mean (0: off)")
    parser.add_argument("--select-seeds", type=int, default=3)
    parser.add_argument("--batch-size", type=int, default=None,
                        help="trials proposed per optimizer step of every stage (diagnose --batch-size; "
                             "default: the phenomenon's, 2 for the pendulum since 2026-11-25, 1 before)")
    parser.add_argument("--calibration-runs", type=int, default=3)
    parser.add_argument("--no-calibration-control", action="store_true",
                        help="self-consistency runs without their own control (the misspecification test then "
                             "uses the baseline stage's gap)")
    parser.add_argument("--shard", default=None, help="K/N: run the seeds whose index is K modulo N "
                        "(with --power: every N-th distinct diagnosis, from the K-th)")
    parser.add_argument("--merge", action="store_true", help="summarise the cases' rows under --out; run nothing")
    parser.add_argument("--compare-calibration", action="store_true",
                        help="with --merge: each case's decisions under earlier calibrations and rules (from its stored gaps)")
    parser.add_argument("--no-null", action="store_true", help="skip the no-effect targets")
    parser.add_argument("--no-limits", action="store_true", help="diagnose without the detection limits")
    parser.add_argument("--no-screen", action="store_true",
                        help="refine every candidate (default: screen out those no fit could name; --timing modes "
                             "say for themselves)")
    parser.add_argument("--power", action="store_true",
                        help="power curves: each hidden effect at --strengths (fractions of the way from off to the "
                             "far end of its range; 0 is a clean target) for --seeds seeds; the named-rate per "
                             "strength, the false discoveries at 0 and the per-target limits' prediction")
    parser.add_argument("--strengths", type=float, nargs="*", default=[0.0, 0.25, 0.5, 1.0])
    parser.add_argument("--effect-strengths", nargs="*", default=[], metavar="EFFECT=S,S,...",
                        help="with --power: an effect's own strengths instead of --strengths (e.g. "
                             "wind_yaw=0,0.25,0.5,1, where its limit lies lower than another's)")
    parser.add_argument("--plot", default=None, help="with --power: write the power curves to this PNG")
    parser.add_argument("--rows", default=None, metavar="DIR",
                        help="keep a copy of every finished case's row in DIR (e.g. a tracked "
                             "folder) and take a case found there as done, so a table of hours can be run over "
                             "several sessions; --merge --out DIR summarises them")
    parser.add_argument("--expect", default=None, metavar="DIR",
                        help="compare every case's decisions (named, misspecified, each candidate's significance) "
                             "with its row kept under DIR (e.g. benchmarks/results/pendulum_table) and exit 1 on "
                             "any difference or missing row")
    parser.add_argument("--ladder-only", action="store_true",
                        help="no diagnosis: each seed's detection limits at its true base θ, the null scale "
                             "--null-over-floor noise floors (the flag, whose diagnoses do not fit a session)")
    parser.add_argument("--null-over-floor", type=float, default=2.0)
    parser.add_argument("--diagnosis-simulations", type=int, default=536,
                        help="with --ladder-only: the diagnosis' simulations the ladder's budget is a share of "
                             "(536: the 24-trial flag table's)")
    parser.add_argument("--reveal", action="store_true", help="with --ladder-only: also another view")
    parser.add_argument("--timing", action="store_true",
                        help="diagnose each case twice, in one process and with --workers; wall times and "
                             "whether the decisions agree (exit 1 if any differs)")
    parser.add_argument("--workers", type=int, default=None,
                        help="with --timing: processes K (default: CPUs); with --power: each diagnosis' worker "
                             "processes, and likewise for a table (default 1: every stage in the benchmark's own process)")
    parser.add_argument("--timing-modes", nargs="+", choices=sorted(TIMING_MODES), default=["needed", "screened"],
                        help="with --timing: the modes, before first (w1-all: one process, every self-consistency "
                             "run; all: K workers, every run; needed: K workers, the runs the decisions need)")
    parser.add_argument("--calibrate-all", action="store_true",
                        help="refine every self-consistency run (the tables' self-gap columns), not only those "
                             "that can change a decision")
    parser.add_argument("--timing-reuse", action="store_true",
                        help="with --timing: take a mode's row from an earlier invocation's case-timing-w<K>.json "
                             "(delete it, and its timing-w<K>/ directory, to measure that mode again)")
    parser.add_argument("--out", default="/tmp/bench_diagnose")
    args = parser.parse_args()

    registry = load_bench_registry(args.frames)
    effects = args.effects if args.effects is not None else registry.effects_of(registry.phenomenon(args.plugin).name)
    if args.power:
        run_power(args, registry, effects)
        return
    if args.ladder_only:
        rows = []
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            rows.append(ladder_case(registry, args.plugin, seed, args))
            from physinfer.io import atomic_write_json

            atomic_write_json(Path(args.out) / f"ladder-{args.plugin}-s{seed}.json", rows[-1])  # a row per seed
            print(json.dumps({"seed": seed, **{e: [v["fraction"], v["detectable_from"], v["reason"]]
                                               for e, v in rows[-1]["effects"].items()}}), file=sys.stderr, flush=True)
        print(json.dumps({"plugin": args.plugin, "settings": dict(vars(args)), "cases": rows}))
        return
    all_cases = case_list(args, effects)
    if args.timing:
        timing = run_timing(args, all_cases)
        print(json.dumps({"plugin": args.plugin, "settings": dict(vars(args)), **timing}))
        sys.exit(0 if timing["same_decisions"] == timing["cases"] else 1)
    start = time.perf_counter()
    cases = []
    if args.merge:
        for hidden, seed in all_cases:
            row_file = stored_row(args, hidden, seed, None)
            if row_file is not None:
                cases.append(json.loads(row_file.read_text()))
            else:
                print(f"missing: {case_dir_of(args.plugin, hidden, seed, args.out)}", file=sys.stderr)
    else:
        shard, n_shards = parse_shard(args.shard)
        # By seed, so that each shard's finished cases cover every hidden effect.
        for hidden, seed in [(h, s) for h, s in all_cases if (s - args.first_seed) % n_shards == shard]:
            kept = case_dir_of(args.plugin, hidden, seed, args.rows) / "case.json" if args.rows else None
            if kept is not None and kept.is_file():  # kept by an earlier session: not run again
                case = json.loads(kept.read_text())
            else:  # (a row under --out alone is re-made from its stages: a changed rule re-decides)
                case = run_case(args.plugin, hidden, seed, args, workers=args.workers or 1)
                keep_row(args, hidden, seed, None, case)
            print(json.dumps({k: case[k] for k in ("hidden", "seed", "named", "misspecified", "gap_ratio")}),
                  file=sys.stderr, flush=True)
            cases.append(case)
    variants = {}
    if args.merge and args.compare_calibration:
        for c in cases:
            rule = {"misspecified_factor": 2.0, "alpha": 0.05, "per_parameter_factor": 0.8}
            c["calibration_variants"] = calibration_variants(case_dir_of(args.plugin, c["hidden"], c["seed"], args.out),
                                                             rule)
        for name in ("R1", "R3", "R3+control", "R3max+control", "R3max+control+effect"):
            variants[name] = summarise([{**c, **c["calibration_variants"][name]} for c in cases])
    out = {
        "plugin": args.plugin,
        "settings": {k: v for k, v in vars(args).items()},
        **summarise(cases),
        "calibration_variants": variants,
        "n_missing": len(all_cases) - len(cases) if args.merge else 0,
        "wall_time_s": time.perf_counter() - start,
        "cases": cases,
    }
    changed = changed_decisions(cases, args.expect, args.plugin) if args.expect else []
    if args.expect:
        out["changed_decisions"] = changed
    print(json.dumps(out))
    if changed:
        print("decisions differ from " + args.expect + ":\n  " + "\n  ".join(changed), file=sys.stderr)
        sys.exit(1)



def stored_row(args: argparse.Namespace, hidden: str | None, seed: int, strength: float | None) -> Path | None:
    """A finished case's row: under ``--out``, else under ``--rows``; ``None`` if neither has it."""
    dirs = [args.out] + ([args.rows] if getattr(args, "rows", None) else [])
    files = [case_dir_of(args.plugin, hidden, seed, d, strength) / "case.json" for d in dirs]
    return next((f for f in files if f.is_file()), None)


def keep_row(args: argparse.Namespace, hidden: str | None, seed: int, strength: float | None,
             row: dict[str, Any]) -> None:
    """``--rows``: a copy of a finished row where it outlives ``--out`` (a tracked folder).

    A table of hours is run over several sessions: the rows kept here are read back instead
    of diagnosed again, and ``--merge --out ROWS`` summarises them with nothing else on disk.
    """
    if getattr(args, "rows", None):
        from physinfer.io import atomic_write_json

        target = case_dir_of(args.plugin, hidden, seed, args.rows, strength) / "case.json"
        target.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_json(target, row)


def run_power(args: argparse.Namespace, registry: Any, effects: list[str]) -> None:
    """``--power``: run (or, with ``--merge``, read) the power table and print its summary."""
    start = time.perf_counter()
    rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
    shard, n_shards = parse_shard(args.shard)
    cases = power_cases(args, effects)
    mine = shard_of_power_cases(cases, shard, n_shards)
    for hidden, strength, seed, effect in cases:
        row_file = stored_row(args, hidden, seed, strength)
        if args.merge or (hidden, strength, seed) not in mine:
            if row_file is not None:
                rows[effect].append(json.loads(row_file.read_text()))
            elif args.merge:
                print(f"missing: {case_dir_of(args.plugin, hidden, seed, args.out, strength)}", file=sys.stderr)
            continue
        if row_file is not None:
            case = json.loads(row_file.read_text())
        else:
            # --workers: the stages side by side (the decisions do not depend on it); 1 by default.
            case = run_case(args.plugin, hidden, seed, args, strength, workers=args.workers or 1)
            keep_row(args, hidden, seed, strength, case)
        lim = case["limits"].get(effect, {})
        print(json.dumps({"effect": effect, "strength": strength, "seed": seed, "named": case["named"],
                          "limit": lim.get("fraction"), "reason": lim.get("reason")}), file=sys.stderr, flush=True)
        rows[effect].append(case)
    summaries = [summarise_power(rows[e], e, strengths_of(args, e)) for e in effects if rows[e]]
    if args.plot and summaries:
        plot_power(summaries, registry, args.plugin, Path(args.plot))
    # A clean target serves every effect's curve: compared once.
    every = list({(r["hidden"], r["seed"], r.get("strength")): r for e in effects for r in rows[e]}.values())
    changed = changed_decisions(every, args.expect, args.plugin) if args.expect else []
    print(json.dumps({"plugin": args.plugin, "settings": dict(vars(args)), "power": summaries,
                      "wall_time_s": time.perf_counter() - start, "cases": every,
                      **({"changed_decisions": changed} if args.expect else {})}))
    if changed:
        print("decisions differ from " + args.expect + ":\n  " + "\n  ".join(changed), file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
