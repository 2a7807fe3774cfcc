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
    limits = [list(s.bounds) for s in specs]
    points = None
    if report.truth and all(s.name in report.truth for s in specs):
        points = np.array([[report.truth[s.name] for s in specs]])
    size = 2.2 * len(subset)
    fig, _ = pairplot(
        samples, points=points, limits=limits, labels=labels, figsize=(size, size),
        upper="hist", diag="hist",
    )  # fmt: skip
    if title:
        fig.suptitle(title, fontsize=9)
    return fig
