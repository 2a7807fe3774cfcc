"""The diagnosis' records (Candidate, Screened, Verdict): typed, frozen, and their dicts exactly
what diagnosis.json held when they were dicts."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from physinfer.api.results import Diagnosis
from physinfer.discrepancy.decide import DecisionRule, final_verdict, misspecification, name_effect
from physinfer.discrepancy.limit_check import apply_checks, checked_limit
from physinfer.discrepancy.records import Candidate, Screened, Verdict
from physinfer.discrepancy.verdict import closest_lead

KEYS = ["effect", "description", "gap", "n_params", "improvement", "ratio", "p_value", "required_ratio",
        "checks", "significant", "best_params", "effect_params", "at_bounds", "distances", "floor", "run_dir"]  # fmt: skip


def _candidate(effect: str = "drag", gap: float = 1.0, significant: bool = True, p_value: float = 0.01) -> Candidate:
    return Candidate(
        effect=effect, description="air drag", gap=gap, n_params=1, improvement=9.0, ratio=gap / 10.0,
        p_value=p_value, required_ratio=0.8,
        checks={"beats_seed_noise": True, "beats_null_scale": significant, "pays_for_parameters": True},
        significant=significant, best_params={"length": 1.0, "k": 0.5}, effect_params={"k": 0.5}, at_bounds={},
        distances=(0.9, 1.1), floor=0.2, run_dir="/runs/d/effect-drag",
    )  # fmt: skip


def test_a_candidate_is_its_old_dict_key_for_key():
    cand = _candidate()
    record = cand.to_dict()
    assert list(record) == KEYS and record["distances"] == [0.9, 1.1]
    assert Candidate.from_dict(record) == cand and Candidate.from_dict(record).to_dict() == record
    limited = cand.with_limit({"k": 0.2}, {"fraction": 0.1, "reason": None})
    assert list(limited.to_dict()) == [*KEYS, "detectable_from", "limit"]
    assert Candidate.from_dict(json.loads(json.dumps(limited.to_dict()))) == limited
    # Read as the dict it was: indexing, get, in, ** and dict().
    assert cand["gap"] == cand.gap and cand.get("limit", {}) == {} and "limit" not in cand and "limit" in limited
    assert {**limited} == dict(limited) == limited.to_dict()
    assert cand == cand.to_dict() and cand != limited and limited == json.loads(json.dumps(limited.to_dict()))
    with pytest.raises(KeyError):
        cand["limit"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        cand.gap = 2.0  # type: ignore[misc]


def test_the_rules_read_records_and_dicts_alike():
    a, b = _candidate("a", gap=2.0), _candidate("b", gap=1.0)
    assert name_effect([a, b], misspecified=True) == name_effect([a.to_dict(), b.to_dict()], misspecified=True) == "b"
    gap = misspecification(5.0, 3.0, DecisionRule())
    verdict = final_verdict(gap, [a, b], DecisionRule())
    assert isinstance(verdict, Verdict) and verdict == final_verdict(gap, [a.to_dict(), b.to_dict()], DecisionRule())
    assert verdict.evidence == ("effect",) and verdict["evidence"] == ["effect"] and not verdict.gap_test
    assert verdict.gap_over_null == gap["gap_over_null"] and verdict.named_effect is None
    lead = _candidate("yaw", gap=3.0, significant=False, p_value=0.3)
    assert closest_lead([lead], {}, misspecified=False, named=None, effect_steps=8) == closest_lead(
        [lead.to_dict()], {}, misspecified=False, named=None, effect_steps=8
    )


def test_a_checked_limit_is_the_same_on_a_record_and_on_its_dict():
    check = {"checks": [], "detectable_from": {"k": 0.4}, "fraction": 0.2, "local": {"k": 0.2}, "reason": None}
    cand = _candidate().with_limit({"k": 0.2}, {"fraction": 0.1, "reason": None})
    record = cand.to_dict()
    apply_checks([record], {"drag": check})
    assert cand.with_limit(*checked_limit(cand.detectable_from, cand.limit or {}, check)).to_dict() == record


def test_a_diagnosis_holds_the_records_its_report_holds(tmp_path: Path):
    cand = _candidate().to_dict()
    screened = {"effect": "inert", "description": "nothing", "reason": "no signature", "rungs": []}
    report = {
        "misspecified": True, "misspecified_by": ["gap"], "gap_test": True, "named_effect": "drag",
        "gap_before": 10.0, "gap_after": 1.0, "null_scale": 2.0, "threshold": 4.0, "tested_gap": 10.0,
        "candidates": [cand], "screened": [screened], "named_leaves": None, "unnamed": None, "lead": None,
    }  # fmt: skip
    d = Diagnosis.from_report(report, tmp_path)
    assert d.to_dict() is report and d.candidates == [Candidate.from_dict(cand)]
    assert d.candidates[0]["effect"] == "drag" and d.screened == [Screened.from_dict(screened)]
    assert d.screened[0]["reason"] == "no signature" and d.screened[0].to_dict() == screened
    assert d.verdict == Verdict(misspecified=True, threshold=4.0, tested_gap=10.0, gap_over_null=5.0, gap_test=True,
                                evidence=("gap",), named_effect="drag", gap_before=10.0, gap_after=1.0)  # fmt: skip


def test_the_verdict_s_notes_are_typed_and_their_dicts_unchanged():
    from physinfer.discrepancy.records import Note

    lead = closest_lead([_candidate("yaw", gap=3.0, significant=False, p_value=0.3)], {}, misspecified=False,
                        named=None, effect_steps=8, clip_seconds=2.4)  # fmt: skip
    note = Note.from_dict(lead)
    assert note.effect == "yaw" and note.message == lead["message"] and note.settle == tuple(lead["settle"])
    assert note.to_dict() == lead and list(note) == list(lead) and note["ratio"] == lead["ratio"]
    report = {"misspecified": False, "threshold": 1.0, "tested_gap": 0.5, "null_scale": 0.5, "gap_test": False,
              "named_effect": None, "gap_before": 0.5, "gap_after": 0.5, "lead": json.loads(json.dumps(lead)),
              "unnamed": None, "named_leaves": None}  # fmt: skip
    verdict = Verdict.from_report(report)
    assert isinstance(verdict.lead, Note) and verdict.lead.effect == "yaw" and verdict.unnamed is None
    assert verdict.to_dict()["lead"] == lead and json.loads(json.dumps(verdict.to_dict()))["lead"] == lead
