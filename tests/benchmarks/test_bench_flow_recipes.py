"""``benchmarks/bench_flow_recipes.py`` scores a recipe's members and their mixture as it says."""

import json
import sys
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
import bench_flow_recipes as recipes  # noqa: E402


def test_score_reads_coverage_error_and_width_from_samples():
    truth = np.array([0.0, 10.0])
    samples = np.stack([np.linspace(-1, 1, 101), np.linspace(1, 3, 101)], axis=1)  # (S, B)
    scored = recipes.score(samples, truth)
    assert scored == {"coverage90": 0.5, "median_error": 4.0, "median_width90": 1.8}


def test_summarise_mixes_members_with_equal_weight_and_keeps_the_first_five(tmp_path):
    from physinfer.posterior.estimator import PosteriorEstimator

    space = PosteriorEstimator.load(recipes.SHIPPED).parameter_space
    wind = space.names.index("wind_speed")
    theta = np.zeros((3, len(space)), np.float32)
    theta[:, wind] = [-0.5, 0.0, 0.5]  # 2.5, 5 and 7.5 m/s
    np.savez(tmp_path / "pairs.npz", te_c=np.zeros((3, 4), np.float32), te_t=theta)
    row = {"wind": 5.0, "x": [0.0] * 4, "shipped": {"error": 0.2, "covered90": True, "width90": 1.0}}
    (tmp_path / "targets.json").write_text(json.dumps({"clean": [row]}))
    (tmp_path / "members").mkdir()
    truths = np.array([2.5, 5.0, 7.5])
    for seed in range(6):  # members 0-4 centred on the truth, member 5 two m/s off
        shift = 2.0 if seed == 5 else 0.0
        held_out = truths + shift + np.random.default_rng(seed).normal(0, 0.1, (200, 3))
        clean = 5.0 + shift + np.random.default_rng(seed).normal(0, 0.1, (200, 1))
        np.savez(tmp_path / "members" / f"maf800-{seed}.npz", seconds=1.0, epochs=10, held_out=held_out, clean=clean)
    summary = recipes.summarise(tmp_path)
    row = summary["maf800"]
    assert row["members"] == 6 and summary["shipped"]["clean"]["median_error"] == 0.2
    assert row["held_out_first5"]["coverage90"] == 1.0 and row["held_out_first5"]["median_error"] < 0.05
    assert row["held_out_each_member_error"][5] > 1.9
    assert row["held_out"]["median_width90"] > row["held_out_first5"]["median_width90"]  # the off member widens the mixture
