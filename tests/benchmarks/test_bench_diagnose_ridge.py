"""The ridge bench's half-way strength from a logistic fit to every case: it recovers a known
curve's 50 % point, is not moved by one non-monotone strength as the first crossing is, and
says nothing where the outcomes separate perfectly."""

import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
import bench_diagnose_ridge as br  # noqa: E402


def _rows(outcomes: dict[float, list[bool]]) -> list[dict]:
    return [{"seed": seed, "strength": strength, "named": "drag" if hit else None}
            for strength, hits in outcomes.items() for seed, hit in enumerate(hits)]  # fmt: skip


def test_the_logistic_half_way_recovers_a_known_curve() -> None:
    rng = np.random.default_rng(3)
    strengths = np.repeat([0.0, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4], 200)
    named = rng.random(strengths.size) < 1 / (1 + np.exp(-(strengths - 0.15) / 0.03))
    rows = [{"seed": i, "strength": float(s), "named": "drag" if n else None}
            for i, (s, n) in enumerate(zip(strengths, named, strict=True))]  # fmt: skip
    fit = br.logistic_half_way(rows, "drag", draws=50)
    assert fit["half_way"] == pytest.approx(0.15, abs=0.01)
    low, high = fit["ci90"]
    assert low < 0.15 < high and high - low < 0.03


def test_one_non_monotone_strength_moves_the_first_crossing_not_the_fit() -> None:
    outcomes = {0.0: [False] * 5, 0.1: [True, True, True, False, False], 0.2: [True, True, True, False, False],
                0.4: [True] * 5, 0.8: [True] * 5}  # fmt: skip
    fitted = br.logistic_half_way(_rows(outcomes), "drag", draws=0)["half_way"]
    crossing = br.half_way({s: sum(h) / len(h) for s, h in outcomes.items()})
    assert crossing == pytest.approx(0.0833, abs=1e-3)
    assert 0.1 < fitted < 0.2  # three of five at 0.1 and 0.2 alike: the curve crosses between


def test_perfectly_separated_outcomes_have_no_fitted_half_way() -> None:
    outcomes = {0.0: [False, False], 0.3: [False, False], 0.6: [True, True], 0.9: [True, True]}
    fit = br.logistic_half_way(_rows(outcomes), "drag", draws=20)
    assert fit["half_way"] is None and fit["ci90"] is None


def test_named_above_limit_counts_the_targets_at_or_above_their_seeds_clean_limit() -> None:
    rows = [{"seed": 1, "strength": 0.0, "named": None, "detectable_from": 0.2},
            {"seed": 1, "strength": 0.1, "named": "drag", "detectable_from": 0.2},  # below: not counted
            {"seed": 1, "strength": 0.2, "named": None, "detectable_from": 0.3},
            {"seed": 1, "strength": 0.4, "named": "drag", "detectable_from": 0.3},
            {"seed": 2, "strength": 0.0, "named": None, "detectable_from": None},  # no limit stated
            {"seed": 2, "strength": 0.4, "named": "drag", "detectable_from": 0.1}]  # fmt: skip
    assert br.named_above_limit(rows, "drag") == [1, 2]
