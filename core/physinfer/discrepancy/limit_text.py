"""The detection limits in words: the verdict's line per candidate effect.

Part of :mod:`physinfer.discrepancy.limits`; reads the dictionaries it writes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any


def summary_phrase(limit: Mapping[str, Any]) -> str:
    """``could reveal shear_exponent ≥ 0.55`` or the reason it could not."""
    if limit["detectable_from"] is None:
        return f"could not reveal it at any strength in its range ({limit['reason']})"
    values = ", ".join(f"{k} ≥ {v:.3g}" for k, v in limit["detectable_from"].items())
    return f"could reveal {values}"


def reveal_phrase(limit: Mapping[str, Any]) -> str:
    """``(you would need …)``: the changes that lower the limit, best first; empty if none."""
    options = sorted(limit.get("reveal", []), key=lambda r: -(r["factor"] or math.inf))
    if not options:
        return ""
    parts = []
    for r in options[:3]:
        where = ", ".join(f"{k} ≥ {v:.3g}" for k, v in (r["detectable_from"] or {}).items())
        gain = "" if r["factor"] is None else f", {r['factor']:.2g}x lower"
        parts.append(f"{r['change']}: {where}{gain}")
    return " (lower with " + "; ".join(parts) + ")"


def limit_line(candidate: Mapping[str, Any], named: str | None, clip_seconds: float | None) -> str:
    """The verdict's line for one candidate, e.g.
    ``wind_shear: not named; this 8-s clip could reveal shear_exponent ≥ 0.55 (lower with …)``."""
    limit = {**candidate.get("limit", {}), "detectable_from": candidate.get("detectable_from")}
    status = "named" if candidate["effect"] == named else "not named"
    clip = "this clip" if clip_seconds is None else f"this {clip_seconds:.3g}-s clip"
    line = f"{candidate['effect']}: {status}; {clip} {summary_phrase(limit)}{reveal_phrase(limit)}"
    if (check := limit.get("search_check")) is not None:  # diagnose --check-limits
        local = ", ".join(f"{k} ≥ {v:.3g}" for k, v in (limit.get("local_detectable_from") or {}).items())
        tried = len(check.get("checks") or [])
        line += f" (checked: this diagnosis' stages on {tried} made target(s); the local refit said {local or 'none'})"
    low = limit.get("at_lower_scale")
    if low and low["detectable_from"] != limit["detectable_from"]:  # the null scale is a range
        line += f" [at the null scale's lower end: {summary_phrase(low).removeprefix('could reveal ')}]"
    return line


def screened_line(record: Mapping[str, Any]) -> str:
    """``wind_shear: screened out, not refined (<reason>)`` for a report's ``screened`` entry."""
    return f"{record['effect']}: screened out, not refined ({record['reason']})"
