"""Figures: the refinement plot (distance and each parameter against the step, like the
paper's Fig. 6, with the ground truth dashed where known)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from physinfer.io import atomic_path
from physinfer.rundir import TrialRecord

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def plot_refinement(
    trials: Sequence[TrialRecord],
    truth: Mapping[str, float] | None,
    path: str | Path,
    max_params: int = 17,
    bands: Mapping[str, Mapping[str, object]] | None = None,
) -> Path:
    """Write :func:`refinement_figure` to ``path`` (PNG, atomically) and return ``path``."""
    fig = refinement_figure(trials, truth, max_params=max_params, bands=bands)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    return Path(path)


def refinement_figure(
    trials: Sequence[TrialRecord],
    truth: Mapping[str, float] | None,
    *,
    max_params: int = 17,
    bands: Mapping[str, Mapping[str, object]] | None = None,
) -> Figure:
    """Distance (and best so far) and every parameter against the step.

    Args:
        trials: Logged trials in step order.
        truth: Ground truth by name, drawn dashed; ``None`` for real targets.
        max_params: Parameters drawn at most (in space order).
        bands: The posterior's marginals by name (``ci90`` and ``label``, see
            :func:`physinfer.posterior.summary.marginals`): the 90 % interval is shaded
            and the label added to the panel's title.
    """
    # matplotlib (about a second to import) only when a figure is drawn: refine's engine and
    # command import this module. No pyplot: no backend or global state to disturb.
    from matplotlib.figure import Figure

    steps = np.array([t.step for t in trials])
    dist = np.array([np.nan if t.distance is None else t.distance for t in trials], dtype=float)
    best = np.fmin.accumulate(np.where(np.isnan(dist), np.inf, dist))
    names = list(trials[0].params)[:max_params] if trials else []
    n_panels = 1 + len(names)
    ncols = min(4, n_panels)
    nrows = math.ceil(n_panels / ncols)
    fig = Figure(figsize=(3.6 * ncols, 2.6 * nrows))
    axes = fig.subplots(nrows, ncols, squeeze=False)
    ax = axes.flat[0]
    ax.plot(steps, dist, "o-", ms=3, lw=1, label="distance")
    ax.plot(steps, np.where(np.isinf(best), np.nan, best), "k-", lw=1.5, label="best so far")
    failed = np.isnan(dist)
    if failed.any():
        ax.plot(steps[failed], np.zeros(failed.sum()), "rx", label="failed")
    ax.set_yscale("log" if np.nanmin(dist, initial=np.inf) > 0 else "linear")
    ax.set_title("embedding distance")
    ax.set_xlabel("step")
    ax.legend(fontsize=7)
    for ax, name in zip(axes.flat[1:], names, strict=False):
        ax.plot(steps, [t.params[name] for t in trials], "o-", ms=3, lw=1)
        title = name
        if bands and name in bands:
            lo, hi = bands[name]["ci90"]  # type: ignore[misc]
            ax.axhspan(lo, hi, color="tab:green", alpha=0.15, label="90 % posterior")
            title = f"{name} ({bands[name]['label']})"
        if truth and name in truth:
            ax.axhline(truth[name], ls="--", color="k", lw=1, label="ground truth")
            ax.legend(fontsize=7)
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("step")
    for ax in axes.flat[n_panels:]:
        ax.axis("off")
    fig.tight_layout()
    return fig
