"""Figures of a diagnosis: spectral maps (target, best fit, augmented fit) and the gaps.

``maps.png``: per row a clip (target, baseline fit, augmented fit if an effect was named),
per column the dominant frequency of each pixel, its motion power (log10), and — for the
fits — the per-region log10 power ratio target / fit with each region's frequency
difference written in, so the regions that disagree stand out and the figure shows
whether the augmented model removed the disagreement.

``gaps.png``: every model's re-simulation distances to the target (dots) and their median
(the gap, bar), with the noise floor, the null scale and the gap test's threshold
as lines: the gap shrinking from the baseline to the named effect.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.discrepancy.localise import SpectralMaps
from physinfer.io import atomic_path


@functools.cache
def _pyplot() -> Any:
    """matplotlib's pyplot on the Agg backend (files only; never needs a display), imported
    when the first figure is drawn: the API's results import this module without drawing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> Path:
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    _pyplot().close(fig)
    return path


def plot_maps(rows: Sequence[tuple[str, SpectralMaps]], path: str | Path) -> Path:
    """Draw dominant-frequency, power and (for fits) region-ratio maps, one row per clip.

    Args:
        rows: ``(label, maps)`` pairs; the first is the target, the others fits of it.
        path: PNG to write (atomically).

    Returns:
        ``path``.
    """
    target = rows[0][1]
    nyquist = target.fps / 2.0
    log_power = [np.log10(m.power + 1e-9) for _, m in rows]
    vmin, vmax = min(float(p.min()) for p in log_power), max(float(p.max()) for p in log_power)
    fig, axes = _pyplot().subplots(len(rows), 3, figsize=(10.5, 3.2 * len(rows)), squeeze=False)
    for i, ((label, maps), lp) in enumerate(zip(rows, log_power, strict=True)):
        im = axes[i, 0].imshow(maps.dominant, cmap="viridis", vmin=0.0, vmax=nyquist)
        axes[i, 0].set_title(f"{label}: dominant frequency", fontsize=9)
        fig.colorbar(im, ax=axes[i, 0], label="Hz", fraction=0.046)
        im = axes[i, 1].imshow(lp, cmap="magma", vmin=vmin, vmax=vmax)
        axes[i, 1].set_title(f"{label}: motion power (log10)", fontsize=9)
        fig.colorbar(im, ax=axes[i, 1], fraction=0.046)
        ax = axes[i, 2]
        if i == 0:
            env = maps.envelope.mean(axis=(0, 1))
            for j, (lab, m) in enumerate(rows):
                ax.plot(np.arange(len(env)) + 1, m.envelope.mean(axis=(0, 1)), "o-", label=lab, color=f"C{j}")
            ax.set_title("motion amplitude per segment", fontsize=9)
            ax.set_xlabel("segment of the clip")
            ax.legend(fontsize=7)
            continue
        ratio = np.log10((target.region_power() + 1e-9) / (maps.region_power() + 1e-9))
        lim = max(0.3, float(np.abs(ratio).max()))
        im = ax.imshow(ratio, cmap="coolwarm", vmin=-lim, vmax=lim)
        dfreq = target.region_dominant() - maps.region_dominant()
        for (r, c), v in np.ndenumerate(dfreq):
            ax.text(c, r, f"{v:+.1f} Hz", ha="center", va="center", fontsize=7)
        ax.set_title(f"target / {label}: region power (log10), Δf", fontsize=9)
        fig.colorbar(im, ax=ax, fraction=0.046)
    for ax in axes.flat:
        if ax.images:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.tight_layout()
    return _save(fig, Path(path))


def plot_gaps(
    models: Sequence[Mapping[str, Any]],
    *,
    floor: float,
    scale: float,
    threshold: float,
    named: str | None,
    path: str | Path,
) -> Path:
    """Write :func:`gaps_figure` to ``path`` (PNG, atomically) and return ``path``."""
    fig = gaps_figure(models, floor=floor, scale=scale, threshold=threshold, named=named)
    return _save(fig, Path(path))


def gaps_figure(
    models: Sequence[Mapping[str, Any]],
    *,
    floor: float,
    scale: float,
    threshold: float,
    named: str | None,
) -> Any:
    """Each model's distances to the target and its gap, with the reference lines.

    Args:
        models: Dicts with ``label``, ``gap`` and ``distances`` (the ``K`` re-simulation
            distances), baseline first.
        floor: Median distance between re-simulations of the baseline fit.
        scale: The null scale (see :mod:`physinfer.discrepancy.decide`).
        threshold: The gap test's threshold (a significant effect is evidence too).
        named: Label of the named effect (highlighted), or ``None``.

    Returns:
        The matplotlib figure.
    """
    fig, ax = _pyplot().subplots(figsize=(1.6 + 1.3 * len(models), 3.6))
    for i, m in enumerate(models):
        colour = "C2" if m["label"] == named else ("C0" if i == 0 else "C7")
        ax.bar(i, m["gap"], color=colour, alpha=0.6, width=0.6)
        d = np.asarray(m["distances"], dtype=float)
        ax.plot(np.full(d.shape, i) + np.linspace(-0.15, 0.15, max(len(d), 1))[: len(d)], d, "k.", ms=4)
    ax.axhline(floor, color="C1", ls=":", lw=1.2, label="noise floor")
    ax.axhline(scale, color="C3", ls="--", lw=1.0, label="null scale")
    ax.axhline(threshold, color="C3", ls="-", lw=1.0, label="gap test: misspecified above")
    ax.set_xticks(range(len(models)), [m["label"] for m in models], rotation=20, fontsize=8)
    ax.set_ylabel("distance to target")
    positive = [v for m in models for v in m["distances"] if v > 0] + [v for v in (floor, scale) if v > 0]
    if positive and max(positive) / min(positive) > 30:
        ax.set_yscale("log")
    ax.set_title("gap per model (bar: median; dots: re-simulations)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig
