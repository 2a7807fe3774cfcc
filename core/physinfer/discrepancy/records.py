"""A diagnosis' records: each candidate effect as judged, each one screened out, and the verdict.

Frozen and typed where the diagnosis builds and reads them (:mod:`~physinfer.discrepancy.verdict`
→ :mod:`~physinfer.discrepancy.decide` → :mod:`~physinfer.discrepancy.outputs`), made dicts by ``to_dict()`` only where JSON is written:
a :class:`Candidate`'s and a :class:`Screened`'s are ``diagnosis.json``'s ``candidates`` and
``screened`` entries key for key, in the same order.

Each record also reads as its dict (``candidate["gap"]`` is ``candidate.gap``; ``get``, ``in``,
``keys``, ``{**candidate}`` and ``==`` against a dict work too): code written when these were
dicts keeps working (only ``json.dumps`` wants ``to_dict()``), and the rules that read a
candidate (:func:`~physinfer.discrepancy.decide.name_effect`,
:func:`~physinfer.discrepancy.verdict.closest_unnamed`, ...) accept either.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any


class _ReadsAsDict(Mapping[str, Any]):
    """The read-only dict view of a record: its ``to_dict()``. A record equals another record
    or a dict with the same ``to_dict()``, as the dicts it replaces did."""

    def to_dict(self) -> dict[str, Any]:  # pragma: no cover - each record defines it
        raise NotImplementedError

    def __getitem__(self, key: str) -> Any:
        return self.to_dict()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())

    def __eq__(self, other: object) -> bool:
        if isinstance(other, _ReadsAsDict):
            return type(self) is type(other) and self.to_dict() == other.to_dict()
        return self.to_dict() == dict(other) if isinstance(other, Mapping) else NotImplemented

    __hash__ = None  # type: ignore[assignment]  # as a dict's: the records hold dicts


@dataclass(frozen=True, eq=False)
class Candidate(_ReadsAsDict):
    """One candidate effect's refined model and whether its improvement counts.

    Attributes:
        effect: The effect's name.
        description: The effect's description.
        gap: The augmented model's gap (median re-simulation distance to the target).
        n_params: The effect's extra parameters ``k``.
        improvement: ``gap_before - gap``.
        ratio: ``gap / gap_before`` (``inf`` for a zero ``gap_before``).
        p_value: The one-sided rank test's p-value against the best baseline fit.
        required_ratio: The ratio that pays for ``k`` parameters.
        checks: ``beats_seed_noise``, ``beats_null_scale``, ``pays_for_parameters``.
        significant: All three checks hold.
        best_params: The augmented model's best θ.
        effect_params: The effect's parameters in ``best_params``.
        at_bounds: Parameters whose best value sits on a bound (name → ``"low"``/``"high"``).
        distances: The ``K`` re-simulation distances to the target.
        floor: The noise floor at the augmented model's fit.
        run_dir: The effect stage's run folder.
        detectable_from: The weakest strength this target could name (``None``: none found);
            meaningful only where the detection limits ran (``limit`` set).
        limit: The detection limit's record (``None``: the limits did not run; then neither
            ``detectable_from`` nor ``limit`` is among the dict's keys).
    """

    effect: str
    description: str
    gap: float
    n_params: int
    improvement: float
    ratio: float
    p_value: float
    required_ratio: float
    checks: Mapping[str, bool]
    significant: bool
    best_params: Mapping[str, float]
    effect_params: Mapping[str, float]
    at_bounds: Mapping[str, Any]
    distances: tuple[float, ...]
    floor: float
    run_dir: Any
    detectable_from: Mapping[str, float] | None = None
    limit: Mapping[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The candidate's entry of ``diagnosis.json``."""
        out = {
            "effect": self.effect,
            "description": self.description,
            "gap": self.gap,
            "n_params": self.n_params,
            "improvement": self.improvement,
            "ratio": self.ratio,
            "p_value": self.p_value,
            "required_ratio": self.required_ratio,
            "checks": self.checks,
            "significant": self.significant,
            "best_params": self.best_params,
            "effect_params": self.effect_params,
            "at_bounds": self.at_bounds,
            "distances": list(self.distances),
            "floor": self.floor,
            "run_dir": self.run_dir,
        }
        if self.limit is not None:
            out.update(detectable_from=self.detectable_from, limit=self.limit)
        return out

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> Candidate:
        """A candidate from its ``diagnosis.json`` entry (``to_dict()``'s inverse)."""
        names = [f.name for f in dataclasses.fields(cls)]
        return cls(**{**{k: record[k] for k in names if k in record}, "distances": tuple(record["distances"])})

    def with_limit(self, detectable_from: Mapping[str, float] | None, limit: Mapping[str, Any]) -> Candidate:
        """This candidate with its detection limit set."""
        return dataclasses.replace(self, detectable_from=detectable_from, limit=limit)


@dataclass(frozen=True, eq=False)
class Screened(_ReadsAsDict):
    """A candidate left out before refinement: no fit could name it on this target
    (:mod:`physinfer.discrepancy.screen`).

    Attributes:
        effect: The effect's name.
        description: The effect's description.
        reason: Why, in words (e.g. "no signature above the noise ...").
        rungs: The screen's ladder: each strength's shift against its threshold.
    """

    effect: str
    description: str
    reason: str
    rungs: list[dict[str, Any]]

    def to_dict(self) -> dict[str, Any]:
        """The record's entry of ``diagnosis.json``'s ``screened``."""
        return {"effect": self.effect, "description": self.description, "reason": self.reason, "rungs": self.rungs}

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> Screened:
        """A record from its ``diagnosis.json`` entry."""
        return cls(record["effect"], record["description"], record["reason"], record["rungs"])


@dataclass(frozen=True, eq=False)
class Note(_ReadsAsDict):
    """A note on the verdict: ``named_leaves`` (what the named model still leaves), ``unnamed``
    (misspecified, nothing named: the closest candidate) or ``lead`` (not misspecified, but a
    candidate took most of the gap) — :func:`~physinfer.discrepancy.verdict.verdict_notes`,
    :func:`~physinfer.discrepancy.decide.remainder_after_naming`.

    Attributes:
        effect: The candidate the note is about.
        message: The printed sentence.
        settle: What would settle it (options, in words); empty for ``named_leaves``.
        fields: Every entry of the note as ``diagnosis.json`` holds it (``ratio``, ``failed``,
            ``trades_off_with``, ``gap``, ``threshold``, ... by kind).
    """

    effect: str
    message: str
    settle: tuple[str, ...]
    fields: Mapping[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """The note's entry of ``diagnosis.json``, key for key as the rule made it."""
        return dict(self.fields)

    @classmethod
    def from_dict(cls, record: Mapping[str, Any] | None) -> Note | None:
        """The note of a ``diagnosis.json`` entry (or of the rule's dict); ``None`` stays ``None``."""
        if record is None:
            return None
        fields = dict(record)
        return cls(str(fields["effect"]), str(fields["message"]), tuple(fields.get("settle") or ()), fields)


@dataclass(frozen=True, eq=False)
class Verdict(_ReadsAsDict):
    """The decision: is the model misspecified, by which test, and which effect it lacks.

    :func:`~physinfer.discrepancy.decide.final_verdict` makes the tests' part;
    :func:`~physinfer.discrepancy.verdict.judge_stages` adds the name and the gaps,
    :func:`~physinfer.discrepancy.verdict.verdict_notes` the notes (``named_leaves``, ``unnamed``, ``lead``).

    Attributes:
        misspecified: Whether either test found the model misspecified.
        threshold: The gap test's threshold (``misspecified_factor`` × the null scale).
        tested_gap: The gap the gap test compared.
        gap_over_null: ``tested_gap`` / the null scale (``None`` for a zero scale).
        gap_test: Whether the gap test alone found it.
        evidence: The tests that found it: ``"gap"``, ``"effect"``.
        named_effect: The effect named, or ``None``.
        gap_before: The best baseline fit's gap (``None`` until judged).
        gap_after: The named effect's gap (the best baseline fit's when none is named).
        named_leaves: What the named model still leaves above the threshold, or ``None``
            (:func:`~physinfer.discrepancy.decide.remainder_after_naming`).
        unnamed: Misspecified and nothing named: the closest candidate, or ``None``
            (:func:`~physinfer.discrepancy.verdict.closest_unnamed`).
        lead: Not misspecified, but a candidate took most of the gap, or ``None``
            (:func:`~physinfer.discrepancy.verdict.closest_lead`).
    """

    misspecified: bool
    threshold: float
    tested_gap: float
    gap_over_null: float | None
    gap_test: bool
    evidence: tuple[str, ...]
    named_effect: str | None = None
    gap_before: float | None = None
    gap_after: float | None = None
    named_leaves: Note | None = None
    unnamed: Note | None = None
    lead: Note | None = None

    def to_dict(self) -> dict[str, Any]:
        """The decision as a dict: the tests' keys as :func:`final_verdict` gave them
        (``misspecified``, ``threshold``, ``tested_gap``, ``gap_over_null``, ``gap_test``,
        ``evidence``), then the name, the gaps and the notes."""
        return {
            "misspecified": self.misspecified,
            "threshold": self.threshold,
            "tested_gap": self.tested_gap,
            "gap_over_null": self.gap_over_null,
            "gap_test": self.gap_test,
            "evidence": list(self.evidence),
            "named_effect": self.named_effect,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "named_leaves": None if self.named_leaves is None else self.named_leaves.to_dict(),
            "unnamed": None if self.unnamed is None else self.unnamed.to_dict(),
            "lead": None if self.lead is None else self.lead.to_dict(),
        }

    @classmethod
    def from_report(cls, report: Mapping[str, Any]) -> Verdict:
        """The verdict a ``diagnosis.json`` report holds."""
        scale = report.get("null_scale")
        tested = report["tested_gap"]
        return cls(
            misspecified=bool(report["misspecified"]),
            threshold=report["threshold"],
            tested_gap=tested,
            gap_over_null=(tested / scale) if scale is not None and scale > 0 else None,  # as misspecification()
            gap_test=bool(report["gap_test"]),
            evidence=tuple(report.get("misspecified_by") or ()),
            named_effect=report.get("named_effect"),
            gap_before=report["gap_before"],
            gap_after=report["gap_after"],
            named_leaves=Note.from_dict(report.get("named_leaves")),
            unnamed=Note.from_dict(report.get("unnamed")),
            lead=Note.from_dict(report.get("lead")),
        )
