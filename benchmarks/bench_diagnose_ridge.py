"""Benchmark of ``diagnose`` on an effect that trades off with a base parameter (issue 46).

Two test plugins written as a newcomer writes one (``--case``):

- ``ball`` (tests/core/bouncing_ball_plugin.py): restitution and drop height, and the effect
  ``ball_drag`` (quadratic drag ``drag_k``), which takes height off each bounce as a lower
  restitution does; base θ drawn per seed: restitution 0.6–0.85, height 1.2–1.8 m.
- ``friction`` (tests/core/spring_friction_plugin.py): a block on a spring (frequency,
  viscous damping, start offset), and the effect ``dry_friction`` (Coulomb friction
  ``mu_g``), which takes amplitude off as the damping does; base θ drawn per seed:
  frequency 0.6–1.0 Hz, damping 0.05–0.25 1/s, offset 0.4–0.7 m.

For each seed a target is made at each ``--strengths`` value of the effect's parameter (0:
the clean target), written to MP4 (64 px), and diagnosed with the phenomenon's defaults
(``--seed`` = the case's seed, one worker unless ``--workers``). ``--no-ridge-starts``
diagnoses as before the ridge starts (each effect's search from the baseline fit alone);
``--check-limits`` checks each not-named limit with the diagnosis' own stages
(:mod:`physinfer.discrepancy.limit_check`) — run over a finished ``--out``, the diagnoses
resume and only the checks run.

Prints one JSON object: ``cases`` (one row each: truth, named, misspecified, the effect
model's gap ratio and fitted θ, the stated limit ``detectable_from``, wall time),
``by_strength`` (named / cases), ``clean_limits`` (each seed's clean target's limit),
``half_way`` (the strength named half the time, interpolated linearly between strengths,
at the first strength named half the time), ``half_way_logistic`` (the same from a logistic
fit to every case, with a 90 % interval from resampling the seeds: five seeds a strength
leave the first crossing at the mercy of one case), ``named_at_or_above_own_limit`` (named /
cases among the targets at or above their seed's clean limit) and ``false_discoveries`` (clean targets called misspecified or given a name). Each case's
row is kept in ``<out>/<case>/case.json``, and a case found there is not run again.

Example (docs/benchmarks.md, "Diagnose: effects on a ridge")::

    PYOPENGL_PLATFORM=egl nice -n 5 .venv/bin/python benchmarks/bench_diagnose_ridge.py \\
        --seeds 5 --strengths 0 0.1 0.2 0.4 0.8 --out /tmp/bench_ridge
    PYOPENGL_PLATFORM=egl nice -n 5 .venv/bin/python benchmarks/bench_diagnose_ridge.py --case friction \\
        --seeds 3 --strengths 0 0.3 0.6 0.9 --out /tmp/bench_ridge_friction
"""

from __future__ import annotations

import argparse
import importlib
import json
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Case:
    """A test plugin of tests/core and the effect hidden in its targets."""

    module: str
    registry: str
    target: str
    plugin: str
    effect: str
    param: str
    label: str  # the case folders' name for a strength: seed1-drag0.4
    base: dict[str, tuple[float, float]]  # each base parameter's range, drawn per seed

    def functions(self) -> tuple[Callable[[], Any], Callable[..., Any]]:
        """The plugin's registry factory and target maker."""
        module = importlib.import_module(self.module)
        return getattr(module, self.registry), getattr(module, self.target)


CASES = {
    "ball": Case("bouncing_ball_plugin", "ball_registry", "ball_target", "bouncing_ball", "ball_drag", "drag_k",
                 "drag", {"restitution": (0.6, 0.85), "height": (1.2, 1.8)}),
    "friction": Case("spring_friction_plugin", "friction_registry", "friction_target", "spring_block",
                     "dry_friction", "mu_g", "mu",
                     {"freq_hz": (0.6, 1.0), "damping": (0.05, 0.25), "offset": (0.4, 0.7)}),
}  # fmt: skip


def truth_of(case: Case, seed: int, strength: float) -> dict[str, float]:
    """The target's θ: a seeded base θ, the effect switched in when ``strength > 0``."""
    rng = np.random.default_rng([seed, 46])
    truth = {name: float(rng.uniform(low, high)) for name, (low, high) in case.base.items()}
    return {**truth, case.param: float(strength)} if strength > 0 else truth


def run_case(out: Path, seed: int, strength: float, args: argparse.Namespace) -> dict[str, Any]:
    """Diagnose one target (or read its row back)."""
    from physinfer.discrepancy.settings import DiagnoseSettings, LimitConfig
    from physinfer.discrepancy.workflow import run_diagnosis

    case = CASES[args.case]
    make_registry, make_target = case.functions()
    folder = out / f"seed{seed}-{case.label}{strength:g}"
    row_file = folder / ("case-checked.json" if args.check_limits else "case.json")
    if row_file.is_file():
        return json.loads(row_file.read_text())
    folder.mkdir(parents=True, exist_ok=True)
    truth = truth_of(case, seed, strength)
    target = folder / "target.mp4"
    if not target.is_file():  # a re-run with --check-limits resumes the diagnosis on the same file
        make_target(truth, target)
    settings = DiagnoseSettings(
        plugin=case.plugin, out=folder / "diagnosis", target_path=Path(target), seed=seed, workers=args.workers,
        videos=False, ridge_starts=not args.no_ridge_starts, registry_factory=make_registry,
        limit_config=LimitConfig(search_check=args.check_limits),
    )  # fmt: skip
    start = time.perf_counter()
    report = run_diagnosis(make_registry(), settings)
    cand = next((c for c in report["candidates"] if c["effect"] == case.effect), {})
    row = {
        "seed": seed, "strength": strength, "truth": truth, "named": report["named_effect"],
        "misspecified": report["misspecified"], "misspecified_by": report["misspecified_by"],
        "gap_before": report["gap_before"], "null_scale": report["null_scale"],
        "gap_ratio": cand.get("ratio"), "significant": cand.get("significant"),
        "fitted": cand.get("best_params"), "detectable_from": (cand.get("detectable_from") or {}).get(case.param),
        "limit_reason": (cand.get("limit") or {}).get("reason"), "unnamed": report.get("unnamed"),
        "lead": report.get("lead"),
        "local_limit": ((cand.get("limit") or {}).get("local_detectable_from") or {}).get(case.param),
        "wall_s": time.perf_counter() - start,
    }  # fmt: skip
    row_file.write_text(json.dumps(row, indent=1))
    return row


def half_way(by_strength: dict[float, float]) -> float | None:
    """The strength named half the time, linear between the measured strengths."""
    points = sorted((s, f) for s, f in by_strength.items() if s > 0)
    prev = (0.0, 0.0)
    for s, f in points:
        if f >= 0.5:
            (s0, f0) = prev
            return s0 + (0.5 - f0) * (s - s0) / (f - f0) if f > f0 else s
        prev = (s, f)
    return None


def _logistic_half_way(strengths: np.ndarray, named: np.ndarray) -> float | None:
    """The 50 % point of a logistic curve in the strength fitted to the named/not-named
    outcomes by maximum likelihood (Newton's method); ``None`` when the curve does not rise
    (or the outcomes separate perfectly, where no finite fit exists)."""
    design = np.c_[np.ones_like(strengths), strengths]
    w = np.zeros(2)
    for _ in range(50):
        p = 1.0 / (1.0 + np.exp(-design @ w))
        hessian = (design * (p * (1 - p))[:, None]).T @ design
        if np.linalg.cond(hessian) > 1e12:
            return None
        step = np.linalg.solve(hessian, design.T @ (named - p))
        w += step
        if np.abs(step).max() < 1e-10:
            break
    return float(-w[0] / w[1]) if w[1] > 0 and np.isfinite(w).all() else None


def logistic_half_way(rows: list[dict], effect: str, draws: int = 2000) -> dict[str, Any]:
    """The strength named half the time from a logistic fit to every case (a dose-response
    ED50: unlike :func:`half_way` it uses all strengths at once and is not moved by one
    non-monotone step), with a 90 % interval from resampling the seeds (each seed's cases
    together) ``draws`` times."""
    by_seed: dict[int, list[dict]] = {}
    for row in rows:
        by_seed.setdefault(row["seed"], []).append(row)

    def fit(seeds: list[int]) -> float | None:
        picked = [r for s in seeds for r in by_seed[s]]
        strengths = np.array([r["strength"] for r in picked], dtype=float)
        return _logistic_half_way(strengths, np.array([r["named"] == effect for r in picked], dtype=float))

    seeds = sorted(by_seed)
    rng = np.random.default_rng(0)
    resampled = [v for _ in range(draws) if (v := fit(list(rng.choice(seeds, len(seeds))))) is not None]
    interval = [float(v) for v in np.percentile(resampled, [5, 95])] if resampled else None
    return {"half_way": fit(seeds), "ci90": interval, "fits": len(resampled), "draws": draws}


def named_above_limit(rows: list[dict], effect: str) -> list[int]:
    """``[named, cases]`` over the hidden-effect cases at or above their seed's clean target's
    stated limit (what a user whose clean video was told "detectable from X" should expect)."""
    limits = {r["seed"]: r["detectable_from"] for r in rows if r["strength"] == 0}
    above = [r for r in rows if r["strength"] > 0 and limits.get(r["seed"]) is not None
             and r["strength"] >= limits[r["seed"]]]  # fmt: skip
    return [sum(r["named"] == effect for r in above), len(above)]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", choices=sorted(CASES), default="ball")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--strengths", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.4, 0.8])
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--no-ridge-starts", action="store_true")
    parser.add_argument(
        "--check-limits",
        action="store_true",
        help="diagnose --check-limits (rows in case-checked.json; a case diagnosed without it resumes)",
    )
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_diagnose_ridge"))
    args = parser.parse_args()
    sys.path.insert(0, str(ROOT / "tests" / "core"))
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        for strength in args.strengths:
            row = run_case(args.out, seed, strength, args)
            rows.append(row)
            print(json.dumps({k: row[k] for k in ("seed", "strength", "named", "gap_ratio", "detectable_from")}),
                  file=sys.stderr)  # fmt: skip
    effect = CASES[args.case].effect
    by_strength = {}
    for strength in args.strengths:
        group = [r for r in rows if r["strength"] == strength]
        by_strength[strength] = sum(r["named"] == effect for r in group) / len(group)
    clean = [r for r in rows if r["strength"] == 0]
    clean_limits = [r["detectable_from"] for r in clean]
    finite = [v for v in clean_limits if v is not None]
    summary = {
        "cases": rows,
        "by_strength": {f"{k:g}": v for k, v in by_strength.items()},
        "clean_limits": clean_limits,
        "median_clean_limit": statistics.median(finite) if finite else None,
        "half_way": half_way(by_strength),
        "half_way_logistic": logistic_half_way(rows, effect),
        "named_at_or_above_own_limit": named_above_limit(rows, effect),
        "false_discoveries": sum(bool(r["misspecified"] or r["named"]) for r in clean),
        "ridge_starts": not args.no_ridge_starts,
        "case": args.case,
    }
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
