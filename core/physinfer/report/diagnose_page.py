"""The page of a ``physinfer diagnose`` output directory.

Reads ``diagnosis.json`` (verdict, candidates, localisation), ``model.json``, the figures
``maps.png`` and ``gaps.png``, ``side_by_side.mp4`` and each stage folder's ``gap.json``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from html import escape
from pathlib import Path
from typing import Any

from physinfer.discrepancy.limit_text import limit_line, screened_line
from physinfer.discrepancy.self_consistency import limits_scale_note, null_scale_words
from physinfer.report.common import Content, adequacy_section, parameter_table, read_json, units_of
from physinfer.report.markup import (
    figure,
    fmt,
    interval,
    key_values,
    paragraph,
    section,
    table,
    video,
)


def diagnose_content(run: Path) -> Content:
    """Title, summary line and sections of a diagnosis's page."""
    report = read_json(run / "diagnosis.json")
    model = read_json(run / "model.json", required=False) or {}
    title = f"physinfer diagnose · {report.get('plugin', '?')}"
    subtitle = f"target: {report.get('target', '?')} · {fmt(report.get('wall_time_s'))} s"
    figures = report.get("figures") or {}
    maps = run / Path(figures.get("maps", "maps.png")).name
    gaps = run / Path(figures.get("gaps", "gaps.png")).name
    clip = "the target beside the baseline fit (and the named effect's)"
    settings = {"plugin": report.get("plugin"), "target": report.get("target")}
    settings.update(report.get("settings") or {})
    adequacy = report.get("adequacy")
    body = [
        *([adequacy_section(adequacy)] if adequacy else []),
        section("Verdict", verdict(report), candidates(report.get("candidates") or []),
                screened(report.get("screened") or [])),
        detection_limits(report),
        _parameters(report, model),
        section(
            "Where the fit disagrees",
            figure(maps, "motion-energy maps of the target and the fits, and where they differ"),
            localisation(report.get("localisation") or {}, report.get("regions") or []),
        ),
        section("Gaps", figure(gaps, "the gap each model leaves, against the noise floor")),
        section("Target | fits", video(run / "side_by_side.mp4", clip)),
        section("Stages", stages(run)),
        section("Settings", key_values(settings)),
    ]
    return Content(title, subtitle, body)


def _parameters(report: Mapping[str, Any], model: Mapping[str, Any]) -> str:
    units = units_of(model.get("parameters"))
    truth = report.get("truth")
    baseline = (report.get("baseline") or {}).get("best_params")
    effects = ", ".join(model.get("effects") or []) or "none"
    return section(
        "Parameters",
        paragraph("the baseline's best fit:"),
        parameter_table(baseline, None, truth, units),
        paragraph(f"the model to refine with next (model.json; effects: {effects}):"),
        parameter_table(model.get("values"), None, truth, units, value_label="value"),
    )


def verdict(report: Mapping[str, Any]) -> str:
    """The decision in words: misspecified or not, the named effect, the gaps behind it."""
    if report.get("misspecified"):
        named = report.get("named_effect") or "none of those tried"
        lines = [f"misspecified: the model misses something; named effect: {named}"]
        cls = "verdict bad"
    else:
        lines = ["not misspecified: the gap is within what a correct model leaves"]
        cls = "verdict good"
    lines.append(
        f"gap {fmt(report.get('gap_before'))} → {fmt(report.get('gap_after'))} "
        f"(noise floor {fmt(report.get('noise_floor'))}, {null_scale_words(report)}, "
        f"gap-test threshold {fmt(report.get('threshold'))})"
    )
    if report.get("misspecified_by"):
        lines.append("evidence: " + ", ".join(str(e) for e in report["misspecified_by"]))
    if report.get("named_leaves"):
        lines.append("but " + str(report["named_leaves"]["message"]))
    for note in (report.get("unnamed"), report.get("lead")):
        if note:
            lines.append(str(note["message"]))
    return f'<div class="{cls}">' + "<br>".join(escape(line) for line in lines) + "</div>"


def candidates(found: Sequence[Mapping[str, Any]]) -> str:
    """One row per effect tried: its gap, the test's numbers, its fitted values."""
    if not found:
        return paragraph("no effects were tried", "note")
    headers = ("effect", "what it adds", "gap", "gap ratio", "p-value", "significant",
               "its values", "on a bound")  # fmt: skip
    rows = []
    for c in found:
        values = ", ".join(f"{k}={fmt(v)}" for k, v in (c.get("effect_params") or {}).items())
        bounds = ", ".join(f"{k} {v}" for k, v in (c.get("at_bounds") or {}).items())
        numbers = (c.get("gap"), c.get("ratio"), c.get("p_value"), c.get("significant"))
        rows.append((c.get("effect"), c.get("description"), *numbers, values, bounds))
    return table(headers, rows)


def screened(found: Sequence[Mapping[str, Any]]) -> str:
    """The effects left out before refinement: no fit could name them on this target."""
    return "".join(paragraph(screened_line(c), "note") for c in found)


def detection_limits(report: Mapping[str, Any]) -> str:
    """Per candidate, the weakest strength this clip could name (``--no-limits``: a note)."""
    limits = report.get("limits")
    if not limits:
        return section("Detection limits", paragraph("not computed (--no-limits)", "note"))
    lines = [
        paragraph(limit_line(c, report.get("named_effect"), limits.get("clip_seconds")))
        for c in report.get("candidates") or []
        if "detectable_from" in c
    ]
    if note := limits_scale_note(report):
        lines.append(paragraph(note, "note"))
    return section("Detection limits", *lines)


def localisation(loc: Mapping[str, Any], regions: Sequence[Mapping[str, Any]]) -> str:
    """The worst frequency band and the image regions that disagree most."""
    parts = []
    if loc:
        headers = ("worst band (Hz)", "dominant frequency target / fit (Hz)",
                   "non-stationarity target / fit")  # fmt: skip
        row = (
            interval(loc.get("worst_band")),
            f"{fmt(loc.get('freq_target_hz'))} / {fmt(loc.get('freq_fit_hz'))}",
            f"{fmt(loc.get('nonstationarity_target'))} / {fmt(loc.get('nonstationarity_fit'))}",
        )
        parts.append(table(headers, [row]))
    if regions:
        parts.append(
            paragraph("regions that disagree most (image grid row and column, top first):")
        )
        rows = [
            (
                r.get("row"),
                r.get("col"),
                r.get("log10_power_ratio"),
                interval(r.get("band")),
                r.get("score"),
            )
            for r in regions[:5]
        ]
        parts.append(table(("row", "col", "log10 power ratio", "band (Hz)", "score"), rows))
    return "".join(parts)


def stages(run: Path) -> str:
    """Each stage folder with the gap its best fit left (from its ``gap.json``)."""
    rows = []
    for stage in sorted(p for p in run.iterdir() if p.is_dir() and (p / "run.json").is_file()):
        gap = read_json(stage / "gap.json", required=False)
        summary = gap.get("summary", {}) if isinstance(gap, Mapping) else {}
        rows.append((stage.name, summary.get("gap"), summary.get("floor"), summary.get("n")))
    if not rows:
        return paragraph("no stage folders", "note")
    return table(("stage folder", "gap", "floor", "re-simulations"), rows)
