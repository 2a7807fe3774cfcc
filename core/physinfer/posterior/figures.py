"""The corner plot of a posterior: the identified parameters and the strongest correlated
pair, drawn with sbi's ``pairplot`` in physical units."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from physinfer.io import atomic_path
from physinfer.parameters import ParameterSpace

#: At most this many parameters share one corner plot.
MAX_PANELS = 5
#: Histogram bins per panel (1D) and per axis (2D). Fixed: sbi's default sizes bins from the
#: samples' spread (Freedman–Diaconis over the panel), which for a posterior a millionth of
#: its range wide asked for 5·10⁸ bins and took the machine's memory.
DIAG_BINS, PAIR_BINS = 60, 40
#: A posterior narrower than this share of its prior range is drawn zoomed in on itself.
ZOOM_BELOW = 0.25


def panel_limits(samples: np.ndarray, bounds: tuple[float, float], truth: float | None) -> list[float]:
    """A panel's axis range: the prior's, or, for a posterior much narrower than the prior,
    its central 99 % padded by half its width on each side (and widened to show the truth)."""
    low, high = float(bounds[0]), float(bounds[1])
    q_lo, q_hi = (float(v) for v in np.quantile(samples, [0.005, 0.995]))
    if q_hi - q_lo >= ZOOM_BELOW * (high - low):
        return [low, high]
    pad = max(0.5 * (q_hi - q_lo), 1e-3 * (high - low))
    lo, hi = q_lo - pad, q_hi + pad
    if truth is not None and np.isfinite(truth):
        lo, hi = min(lo, truth - pad), max(hi, truth + pad)
    return [max(low, lo), min(high, hi)]


def corner_subset(report: Any) -> list[int]:
    """Indices to draw: identified first, then weakly identified, then the strongest
    correlated pair's members; at most :data:`MAX_PANELS` (at least two)."""
    names = report.names
    order = {"identified": 0, "weakly identified": 1, "not identified": 2}
    chosen = [n for n in names if report.marginals[n]["label"] == "identified"]
    if report.correlations:
        chosen += [report.correlations[0]["a"], report.correlations[0]["b"]]
    ranked = sorted(names, key=lambda n: (order[report.marginals[n]["label"]], -report.marginals[n]["contraction"]))
    chosen += ranked
    subset: list[int] = []
    for name in chosen:
        i = names.index(name)
        if i not in subset:
            subset.append(i)
    keep = max(2, min(MAX_PANELS, sum(report.marginals[n]["label"] != "not identified" for n in names) + 2))
    return sorted(subset[: min(keep, len(names))])


def corner_plot(report: Any, space: ParameterSpace, path: str | Path, *, title: str = "") -> Path:
    """Write :func:`corner_figure` to ``path`` (PNG, atomically) and return ``path``."""
    import matplotlib

    matplotlib.use("Agg")  # files only; a notebook calls corner_figure and keeps its backend
    import matplotlib.pyplot as plt

    fig = corner_figure(report, space, title=title)
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
    return path


def corner_figure(report: Any, space: ParameterSpace, *, title: str = "") -> Any:
    """The corner plot of ``report``'s samples (a matplotlib figure); truth marked if known.

    Drawn with sbi's ``pairplot``, which draws with pyplot: the figure is also pyplot's
    current one (close it with ``matplotlib.pyplot.close(fig)`` when drawing many).
    """
    from sbi.analysis import pairplot

    subset = corner_subset(report)
    specs = [space[report.names[i]] for i in subset]
    samples = np.stack([spec.from_unit(report.samples_unit[:, i]) for spec, i in zip(specs, subset, strict=True)], axis=1)
    labels = [f"{s.name} [{s.unit}]" if s.unit else s.name for s in specs]
    points = None
    if report.truth and all(s.name in report.truth for s in specs):
        points = np.array([[report.truth[s.name] for s in specs]])
    limits = [panel_limits(samples[:, k], s.bounds, None if points is None else points[0, k]) for k, s in enumerate(specs)]
    size = 2.2 * len(subset)
    fig, _ = pairplot(
        samples, points=points, limits=limits, labels=labels, figsize=(size, size),
        upper="hist", diag="hist",
        diag_kwargs={"mpl_kwargs": {"bins": DIAG_BINS}}, upper_kwargs={"np_hist_kwargs": {"bins": PAIR_BINS}},
    )  # fmt: skip
    if title:
        fig.suptitle(title, fontsize=9)
    return fig
