"""The power table of ``benchmarks/bench_diagnose.py --power`` splits over processes so that
every diagnosis runs once (a seed's clean target serves every effect's curve) and the shares
are equal."""

import argparse
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCH))
import bench_diagnose as bd  # noqa: E402


def test_power_shards_run_each_diagnosis_once_in_equal_shares() -> None:
    args = argparse.Namespace(first_seed=100, seeds=5, strengths=[0.0, 0.5, 1.0])
    cases = bd.power_cases(args, ["wind_yaw", "wind_inclination", "wind_shear", "wind_gusts"])
    distinct = {(hidden, strength, seed) for hidden, strength, seed, _ in cases}
    assert len(cases) == 5 * 4 * 3 and len(distinct) == 5 * (1 + 4 * 2)  # clean once per seed
    shards = [bd.shard_of_power_cases(cases, k, 2) for k in range(2)]
    assert shards[0].isdisjoint(shards[1]) and shards[0] | shards[1] == distinct
    assert sorted(len(s) for s in shards) == [22, 23]
    assert bd.shard_of_power_cases(cases, 0, 1) == distinct


def test_an_effect_can_have_its_own_strengths() -> None:
    args = argparse.Namespace(first_seed=0, seeds=1, strengths=[0.0, 0.5, 1.0],
                              effect_strengths=["wind_yaw=0,0.25,0.5,1"])
    cases = bd.power_cases(args, ["wind_yaw", "wind_shear"])
    assert [(h, s) for h, s, _, e in cases if e == "wind_yaw"] == [(None, 0.0), ("wind_yaw", 0.25), ("wind_yaw", 0.5),
                                                                  ("wind_yaw", 1.0)]
    assert [s for _, s, _, e in cases if e == "wind_shear"] == [0.0, 0.5, 1.0]
    assert len({(h, s, seed) for h, s, seed, _ in cases}) == 1 + 3 + 2  # the clean target once
    args.effect_strengths = ["wind_yaw:0,1"]
    with pytest.raises(SystemExit, match="EFFECT=S,S"):
        bd.power_cases(args, ["wind_yaw"])


def test_rows_kept_in_a_tracked_folder_count_as_done(tmp_path: Path) -> None:
    args = argparse.Namespace(plugin="flag_lite", out=str(tmp_path / "out"), rows=str(tmp_path / "rows"))
    assert bd.stored_row(args, "wind_yaw", 100, 0.3) is None
    bd.keep_row(args, "wind_yaw", 100, 0.3, {"named": "wind_yaw", "strength": 0.3})
    kept = bd.stored_row(args, "wind_yaw", 100, 0.3)
    assert kept == tmp_path / "rows" / "flag_lite-wind_yaw-p0.3-s100" / "case.json"
    assert '"named": "wind_yaw"' in kept.read_text()
    # A row under --out (the run's own directory) is read first.
    own = bd.case_dir_of("flag_lite", "wind_yaw", 100, args.out, 0.3) / "case.json"
    own.parent.mkdir(parents=True)
    own.write_text("{}")
    assert bd.stored_row(args, "wind_yaw", 100, 0.3) == own
    args.rows = None
    bd.keep_row(args, None, 100, 0.0, {})  # without --rows nothing is kept
    assert bd.stored_row(args, None, 100, 0.0) is None


def _row(strength: float, named: str | None, limit: float | None, misspecified: bool = False, seed: int = 0) -> dict:
    return {"strength": strength, "seed": seed, "named": named, "misspecified": misspecified or named is not None,
            "limits": {"wind_yaw": {"fraction": limit}}}


def test_the_power_summary_reads_the_half_way_strength_and_the_limits_prediction() -> None:
    rows = [
        _row(0.0, None, 0.3, seed=0), _row(0.0, None, None, misspecified=True, seed=1),  # one false discovery
        _row(0.25, None, 0.3, seed=0), _row(0.25, "wind_yaw", 0.2, seed=1),  # 1 of 2 named; one limit <= 0.25
        _row(0.5, "wind_yaw", 0.4, seed=0), _row(0.5, "wind_yaw", None, seed=1),  # 2 of 2; the second "mimicked"
    ]
    summary = bd.summarise_power(rows, "wind_yaw", [0.0, 0.1, 0.25, 0.5])
    curve = {p["strength"]: p for p in summary["curve"]}
    assert curve[0.1]["n"] == 0 and curve[0.1]["named_rate"] is None  # a strength not run yet
    assert [curve[s]["named_rate"] for s in (0.0, 0.25, 0.5)] == [0.0, 0.5, 1.0]
    assert [curve[s]["predicted_rate"] for s in (0.0, 0.25, 0.5)] == [0.0, 0.5, 0.5]
    # From each seed's clean target: seed 0 from 0.3, seed 1 beyond the range.
    assert [curve[s]["predicted_from_clean"] for s in (0.0, 0.25, 0.5)] == [0.0, 0.0, 0.5]
    assert summary["false_discoveries"] == 1 and summary["n_clean"] == 2
    assert summary["s50"] == 0.25  # the named-rate reaches one half there
    # Six limits, two of them none (beyond the range): the median of 0.2, 0.3, 0.3, 0.4, inf, inf.
    assert summary["median_limit"] == 0.35 and summary["limit_over_s50"] == 0.35 / 0.25
    assert summary["median_clean_limit"] is None  # 0.3 and beyond the range: the median is beyond too
    # Never named: no half-way strength, no ratio.
    never = bd.summarise_power([_row(0.5, None, None), _row(1.0, None, None)], "wind_yaw", [0.5, 1.0])
    assert never["s50"] is None and never["median_limit"] is None and never["limit_over_s50"] is None


def test_expect_lists_every_case_whose_decisions_changed_and_every_case_it_cannot_compare(tmp_path: Path) -> None:
    def row(seed: int, named: str | None, misspecified: bool, significant: bool) -> dict:
        return {"hidden": "wind_yaw", "seed": seed, "strength": None, "named": named, "misspecified": misspecified,
                "candidates": {"wind_yaw": {"significant": significant, "gap": 1.0}}}

    stored = tmp_path / "stored"
    args = argparse.Namespace(plugin="flag_lite", out=str(tmp_path / "out"), rows=str(stored))
    for seed, named in ((0, "wind_yaw"), (1, None)):
        bd.keep_row(args, "wind_yaw", seed, None, row(seed, named, named is not None, named is not None))
    same = [row(0, "wind_yaw", True, True) | {"gap_ratio": 0.1}, row(1, None, False, False)]  # other numbers: same
    assert bd.changed_decisions(same, str(stored), "flag_lite") == []
    lost = [row(0, None, True, False), row(1, None, False, False), row(2, None, False, False)]
    changed = bd.changed_decisions(lost, str(stored), "flag_lite")
    assert len(changed) == 2 and changed[0].startswith("flag_lite-wind_yaw-s0: stored ('wind_yaw', True")
    assert changed[1] == "flag_lite-wind_yaw-s2: no stored row to compare with"


def test_power_merge_with_expect_fails_on_a_changed_decision(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    def row(hidden: str | None, strength: float, named: str | None) -> dict:
        return {"hidden": hidden, "seed": 100, "strength": strength, "named": named, "misspecified": named is not None,
                "candidates": {"wind_yaw": {"significant": named is not None}}, "limits": {}}

    stored, rerun = tmp_path / "stored", tmp_path / "rerun"
    args = argparse.Namespace(plugin="flag_lite", power=True, merge=True, out=str(rerun), rows=None, expect=str(stored),
                              first_seed=100, seeds=1, strengths=[0.0, 0.5], effect_strengths=[], shard=None,
                              plot=None, workers=None)
    for folder, named in ((stored, "wind_yaw"), (rerun, "wind_yaw")):
        bd.keep_row(argparse.Namespace(plugin="flag_lite", rows=str(folder)), None, 100, 0.0, row(None, 0.0, None))
        bd.keep_row(argparse.Namespace(plugin="flag_lite", rows=str(folder)), "wind_yaw", 100, 0.5,
                    row("wind_yaw", 0.5, named))
    bd.run_power(args, None, ["wind_yaw"])  # the same decisions: passes
    assert '"changed_decisions": []' in capsys.readouterr().out
    bd.keep_row(argparse.Namespace(plugin="flag_lite", rows=str(rerun)), "wind_yaw", 100, 0.5,
                row("wind_yaw", 0.5, None))
    with pytest.raises(SystemExit) as exit_:
        bd.run_power(args, None, ["wind_yaw"])
    assert exit_.value.code == 1
    assert "flag_lite-wind_yaw-p0.5-s100: stored ('wind_yaw'" in capsys.readouterr().err
