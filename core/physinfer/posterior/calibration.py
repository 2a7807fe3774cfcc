"""Is an interval a true claim? Simulation-based calibration on held-out simulations.

For each held-out pair (θ*, x) the posterior of x is sampled and θ*'s rank among the
samples recorded, per parameter (Talts et al. 2018, as sbi's ``run_sbc`` with
``reduce_fns="marginals"``). A calibrated posterior gives uniform ranks; the share of
pairs whose θ* falls inside the central p-interval — the expected coverage — is then p.
An over-confident posterior piles ranks at the ends and covers less than p; an
under-confident one covers more.

The functions take any sampler, so the check itself is tested on a problem whose exact
posterior is known.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.io import atomic_path

#: Nominal levels whose coverage is reported.
LEVELS: tuple[float, ...] = (0.5, 0.9)


@dataclass(frozen=True)
class Calibration:
    """Ranks and expected coverage of a posterior on held-out pairs.

    Attributes:
        names: ``(D,)`` parameter names.
        ranks: ``(N, D)`` rank of each true value among ``n_samples`` posterior samples.
        n_samples: Posterior samples per pair.
        coverage: ``{level: (D,)}`` share of pairs whose true value lies in the central
            ``level`` interval.
        ks_pvalue: ``(D,)`` Kolmogorov–Smirnov p-value of the ranks' uniformity.
    """

    names: list[str]
    ranks: np.ndarray
    n_samples: int
    coverage: dict[float, np.ndarray]
    ks_pvalue: np.ndarray

    @property
    def n_pairs(self) -> int:
        """Held-out pairs ``N``."""
        return int(self.ranks.shape[0])

    def tolerance(self, level: float) -> float:
        """Three binomial standard errors of a coverage estimate at ``level`` with N pairs."""
        return 3.0 * float(np.sqrt(level * (1 - level) / max(self.n_pairs, 1)))

    def verdict(self, level: float, i: int) -> str:
        """``calibrated``, ``over-confident`` or ``under-confident`` for parameter ``i``."""
        c = float(self.coverage[level][i])
        if c < level - self.tolerance(level):
            return "over-confident"
        if c > level + self.tolerance(level):
            return "under-confident"
        return "calibrated"

    def to_dict(self) -> dict[str, Any]:
        """Per parameter: coverage at each level, its verdict and the KS p-value."""
        params = {}
        for i, name in enumerate(self.names):
            params[name] = {
                **{f"coverage{int(round(lv * 100))}": float(self.coverage[lv][i]) for lv in self.coverage},
                **{f"verdict{int(round(lv * 100))}": self.verdict(lv, i) for lv in self.coverage},
                "ks_pvalue": float(self.ks_pvalue[i]),
            }
        return {
            "n_pairs": self.n_pairs,
            "n_samples": self.n_samples,
            "levels": list(self.coverage),
            "tolerance": {f"coverage{int(round(lv * 100))}": self.tolerance(lv) for lv in self.coverage},
            "parameters": params,
        }


def ranks_of(truths: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """``(N, D)`` ranks of ``truths`` ``(N, D)`` among ``samples`` ``(S, N, D)``."""
    return (samples < truths[None]).sum(axis=0)


def coverage_from_ranks(ranks: np.ndarray, n_samples: int, level: float) -> np.ndarray:
    """``(D,)`` share of truths inside the central ``level`` interval of their posterior.

    Rank r of S means the truth sits at the posterior quantile ``(r + 0.5) / (S + 1)``; it
    is inside the central interval when that quantile is within ``level / 2`` of 0.5.
    """
    q = (ranks + 0.5) / (n_samples + 1)
    return (np.abs(q - 0.5) <= level / 2).mean(axis=0)


def calibrate(
    truths_unit: np.ndarray,
    xs: np.ndarray,
    sampler: Callable[[np.ndarray, int, int], np.ndarray],
    names: Sequence[str],
    *,
    n_samples: int = 1000,
    batch: int = 50,
    levels: Sequence[float] = LEVELS,
    seed: int = 0,
    on_progress: Callable[[int, int], None] | None = None,
) -> Calibration:
    """Ranks and coverage of ``sampler`` on held-out pairs.

    Args:
        truths_unit: ``(N, D)`` true θ (any coordinates the sampler's samples are in).
        xs: ``(N, E)`` their embeddings (or observations).
        sampler: ``(xs_batch (B, E), n, seed) -> (n, B, D)`` posterior samples.
        names: ``(D,)`` parameter names.
        n_samples: Posterior samples per pair.
        batch: Pairs per sampler call.
        levels: Nominal coverages to report.
        seed: Seed of the first batch (batch k uses ``seed + k``).
        on_progress: Called as ``(done, total)``.
    """
    n = len(truths_unit)
    ranks = np.empty(truths_unit.shape, dtype=np.int64)
    for k, start in enumerate(range(0, n, batch)):
        stop = min(start + batch, n)
        samples = sampler(xs[start:stop], n_samples, seed + k)
        ranks[start:stop] = ranks_of(truths_unit[start:stop], samples)
        if on_progress is not None:
            on_progress(stop, n)
    coverage = {float(lv): coverage_from_ranks(ranks, n_samples, lv) for lv in levels}
    # Ranks are discrete on 0..S; a KS test against the continuous uniform is accurate for S ≫ 1.
    u = (ranks + 0.5) / (n_samples + 1)
    # scipy.stats is imported here, not above: the posterior commands' face reaches this module,
    # and refine and infer load it without calibrating.
    from scipy import stats

    ks = np.array([stats.kstest(u[:, i], "uniform").pvalue for i in range(u.shape[1])])
    return Calibration(list(names), ranks, n_samples, coverage, ks)


def plot_calibration(cal: Calibration, path: str | Path, *, title: str = "") -> Path:
    """:func:`calibration_figure` as one PNG."""
    fig = calibration_figure(cal, title=title)
    path = Path(path)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=110)
    return path


def calibration_figure(cal: Calibration, *, title: str = "") -> Any:
    """Rank histograms (one panel per parameter, the uniform band shaded) and the coverage
    of each level against its nominal value (a matplotlib figure, no pyplot state)."""
    from matplotlib.figure import Figure

    d = len(cal.names)
    cols = min(d, 6)
    rows = (d + cols - 1) // cols + 1
    fig = Figure(figsize=(2.6 * cols, 2.2 * rows), layout="constrained")
    bins = 10
    expected = cal.n_pairs / bins
    band = 2.0 * np.sqrt(expected * (1 - 1 / bins))
    for i, name in enumerate(cal.names):
        ax = fig.add_subplot(rows, cols, i + 1)
        counts, _ = np.histogram(cal.ranks[:, i], bins=bins, range=(0, cal.n_samples))
        ax.axhspan(expected - band, expected + band, color="0.85")
        ax.bar(np.arange(bins), counts, width=0.9, color="tab:blue")
        ax.set_title(name, fontsize=8)
        ax.set_xticks([])
        ax.tick_params(labelsize=7)
    ax = fig.add_subplot(rows, 1, rows)
    x = np.arange(d)
    for k, level in enumerate(cal.coverage):
        ax.bar(x + (k - 0.5) * 0.4, cal.coverage[level], width=0.4, label=f"{int(level * 100)} % interval")
        ax.axhline(level, color=f"C{k}", ls="--", lw=1)
    ax.set_xticks(x, cal.names, rotation=60, ha="right", fontsize=7)
    ax.set_ylim(0, 1)
    ax.set_ylabel("coverage")
    ax.legend(fontsize=7, loc="lower right")
    fig.suptitle(title or f"simulation-based calibration on {cal.n_pairs} held-out simulations", fontsize=9)
    return fig
