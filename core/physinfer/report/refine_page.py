"""The page of a ``physinfer refine`` run directory.

Reads ``run.json``, ``result.json`` (best fit, posterior, noise floor), ``noise_prior.json``,
``refinement.png`` and ``side_by_side.mp4``. A run that has not finished (no
``result.json``) still gets a page: its settings and whatever figures exist.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from physinfer.report.common import (
    NUISANCE_NOTE,
    Content,
    adequacy_section,
    correlations,
    parameter_table,
    read_json,
    units_of,
)
from physinfer.report.markup import figure, fmt, key_values, paragraph, section, table, video


def refine_content(run: Path) -> Content:
    """Title, summary line and sections of a refinement's page."""
    info = read_json(run / "run.json")
    result = read_json(run / "result.json", required=False)
    title = f"physinfer refine · {info.get('plugin', '?')}"
    target = f"target: {info.get('target', '?')}"
    if result is None:
        subtitle = f"{target} · no result.json yet: the run has not finished"
        body = [section("Parameters", paragraph("the run has not written its result yet", "note"))]
    else:
        subtitle = (
            f"{target} · {result.get('n_trials')} trials ({result.get('n_failed')} failed) · "
            f"best distance {fmt(result.get('best_distance'))} at step {result.get('best_step')} · "
            f"{fmt(result.get('wall_time_s'))} s"
        )
        prior = read_json(run / "noise_prior.json", required=False)
        body = [_parameters(result, info), noise_section(result.get("noise_floor"), prior)]
        if result.get("adequacy"):
            body.insert(0, adequacy_section(result["adequacy"]))
    figure_html = figure(run / "refinement.png", "distance and parameters against the step")
    body.append(section("Refinement", figure_html))
    clip = video(run / "side_by_side.mp4", "the target (left) beside the best fit")
    body.append(section("Target | best fit", clip))
    settings = {k: v for k, v in info.items() if k not in ("parameters", "truth")}
    body.append(section("Settings", key_values(settings)))
    return Content(title, subtitle, body)


def _parameters(result: Mapping[str, Any], info: Mapping[str, Any]) -> str:
    """The parameter table with bound and --fix notes, and where the intervals came from."""
    bounds = result.get("at_bounds") or {}
    fixed = result.get("fixed") or {}
    notes = {name: f"best fit on its {side} bound" for name, side in bounds.items()}
    notes.update({name: "fixed (--fix)" for name in fixed})
    notes.update({name: NUISANCE_NOTE for name in result.get("nuisance") or {}})
    best = {**result.get("best_params", {}), **fixed}
    truth = result.get("ground_truth") or info.get("truth")
    units = units_of(info.get("parameters"))
    parts = [parameter_table(best, result.get("posterior"), truth, units, notes=notes)]
    source = result.get("posterior_source")
    if source:
        where = f"{source.get('kind')}, {source.get('estimator')}"
        parts.append(paragraph(f"intervals: the target's posterior ({where})", "note"))
    elif result.get("posterior_note"):
        parts.append(paragraph(str(result["posterior_note"]), "note"))
    parts += correlations(result.get("correlations"))
    return section("Parameters", *parts)


def noise_section(floor: Mapping[str, Any] | None, prior: Mapping[str, Any] | None) -> str:
    """The noise floor at the best fit and the observation noise measured before refining."""
    parts = []
    if floor:
        headers = ("floor (re-simulations of the best fit)", "floor q95", "gap (best fit → target)",
                   "gap / floor", "n")  # fmt: skip
        keys = ("floor", "floor_q95", "gap", "ratio", "n")
        parts.append(table(headers, [tuple(floor.get(k) for k in keys)]))
        parts.append(
            paragraph(
                "A gap near the floor means the fit is as close as the phenomenon's own randomness "
                "allows; a gap far above it means the model or the search falls short.",
                "note",
            )
        )
    else:
        note = "noise floor not measured (--floor-samples 0, or its re-simulations failed)"
        parts.append(paragraph(note, "note"))
    if prior:
        where = prior.get("at", "?")
        parts.append(
            paragraph(f"observation noise before refining (noise_prior.json, at the {where}):")
        )
        keys = ("sem", "floor", "gap", "n")
        rows = [tuple(prior.get(k) for k in keys)]
        parts.append(table(("log-distance std (sem)", "floor", "gap", "n"), rows))
    return section("Noise floor", *parts)
