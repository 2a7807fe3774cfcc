"""The page of a ``physinfer infer`` output directory: ``posterior.json`` and ``corner.png``."""

from __future__ import annotations

from pathlib import Path

from physinfer.report.common import NUISANCE_NOTE, Content, correlations, parameter_table, read_json
from physinfer.report.markup import figure, fmt, key_values, paragraph, section


def infer_content(run: Path) -> Content:
    """Title, summary line and sections of a posterior's page."""
    report = read_json(run / "posterior.json")
    seconds = report.get("seconds") or {}
    estimator = Path(str(report.get("estimator", "?"))).name
    subtitle = f"estimator: {estimator} · {report.get('n_samples')} samples · {fmt(sum(seconds.values()))} s"
    parts = [
        parameter_table(
            None, report.get("posterior") or {}, report.get("truth"), {}, detail=True,
            notes={name: NUISANCE_NOTE for name in report.get("nuisance") or ()},
        ),  # fmt: skip
        paragraph(
            "contraction: how much narrower the posterior is than the prior "
            "(1: pinned down, 0: nothing learnt).",
            "note",
        ),
        *correlations(report.get("correlations")),
    ]
    settings = {k: report.get(k) for k in ("estimator", "n_samples", "seconds")}
    body = [
        section("Posterior", *parts),
        section(
            "Corner plot", figure(run / "corner.png", "posterior samples: marginals and pairs")
        ),
        section("Settings", key_values(settings)),
    ]
    return Content("physinfer infer", subtitle, body)
