"""What every run page shares: its content record, reading the run's JSON, the parameter table.

A file a run did not write (no noise floor with ``--floor-samples 0``, no video with
``--no-videos``) becomes a note on the page, not an error: the page shows what the run has.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from physinfer.adequacy import agreement_line, verdict_line
from physinfer.errors import UserInputError
from physinfer.report.markup import interval, paragraph, section, table


@dataclass
class Content:
    """What a page shows: its title, the line under it and the body sections (HTML)."""

    title: str
    subtitle: str
    body: list[str]


def read_json(path: Path, *, required: bool = True) -> Any:
    """A JSON file of the run; ``None`` when absent and not ``required``.

    Raises:
        UserInputError: the file is absent (when required) or not valid JSON.
    """
    if not path.is_file():
        if required:
            raise UserInputError(f"{path} is missing; the run folder is incomplete")
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UserInputError(f"{path} is not valid JSON ({exc}); re-run to rebuild it") from None


def units_of(parameters: Sequence[Mapping[str, Any]] | None) -> dict[str, str]:
    """``{name: unit}`` from a JSON parameter list (``run.json``, ``model.json``)."""
    return {
        p["name"]: p.get("unit", "")
        for p in parameters or []
        if isinstance(p, Mapping) and "name" in p
    }


#: The note beside a nuisance parameter (a pendulum's phase) in a parameter table.
NUISANCE_NOTE = "nuisance: what the video leaves open, not a measurement"


def parameter_table(
    values: Mapping[str, float] | None,
    posterior: Mapping[str, Mapping[str, Any]] | None,
    truth: Mapping[str, float] | None,
    units: Mapping[str, str],
    *,
    notes: Mapping[str, str] | None = None,
    value_label: str = "best fit",
    detail: bool = False,
) -> str:
    """One row per parameter: the fitted value, posterior median, interval and label, truth.

    Columns a run has no numbers for (no fit, no posterior, no truth) are left out. With a
    fit and a truth the error is shown; with only a posterior, whether the truth lies in its
    90 % interval. ``detail`` adds the 50 % interval and the contraction.
    """
    values, posterior, truth, notes = values or {}, posterior or {}, truth or {}, notes or {}
    names = list(values) + [n for n in posterior if n not in values]
    headers = ["parameter", "unit"] + ([value_label] if values else [])
    if posterior:
        headers += ["median"] + (["50 % interval"] if detail else []) + ["90 % interval"]
        headers += (["contraction"] if detail else []) + ["label"]
    if truth:
        headers += ["truth", f"|{value_label} − truth|" if values else "truth in 90 %"]
    headers += ["note"] if notes else []
    rows = []
    for name in names:
        post = posterior.get(name, {})
        row: list[Any] = [name, units.get(name) or post.get("unit", "")]
        row += [values.get(name)] if values else []
        if posterior:
            row += [post.get("median")] + ([interval(post.get("ci50"))] if detail else [])
            row += [interval(post.get("ci90"))] + ([post.get("contraction")] if detail else [])
            row += [post.get("label")]
        if truth:
            row += [truth.get(name), _error_or_coverage(name, values, post, truth)]
        row += [notes.get(name, "")] if notes else []
        rows.append(row)
    return table(headers, rows)


def _error_or_coverage(
    name: str, values: Mapping[str, float], post: Mapping[str, Any], truth: Mapping[str, float]
) -> float | bool | None:
    t = truth.get(name)
    if t is None:
        return None
    if values:
        return abs(values[name] - t) if name in values else None
    ci = post.get("ci90")
    return bool(ci[0] <= t <= ci[1]) if ci else None


def correlations(pairs: Sequence[Mapping[str, Any]] | None) -> list[str]:
    """The strongest posterior correlations as a small table (nothing when there are none)."""
    if not pairs:
        return []
    rows = [(p.get("a"), p.get("b"), p.get("r")) for p in pairs]
    return [paragraph("strongest posterior correlations:"), table(("a", "b", "r"), rows)]


def adequacy_section(adequacy: Mapping[str, Any]) -> str:
    """Whether the best fit reproduces the video: the verdict first (the record's own ``message``
    where the command wrote one, as ``diagnose`` does), then how it was measured."""
    said = (adequacy.get("message") or verdict_line(dict(adequacy)) or agreement_line(dict(adequacy)) or "").strip()
    text = said[:1].upper() + said[1:] if said else str(adequacy.get("note", "no verdict"))
    cls = {True: "verdict good", False: "verdict bad"}.get(adequacy.get("reproduces"), "note")
    return section("Does the model reproduce the video?", paragraph(text, cls), paragraph(str(adequacy.get("method")), "note"))
