"""One effect's detection limit: the rule's threshold at each rung, and where the refit gap clears it.

Part of :mod:`physinfer.discrepancy.limits` (the method is described there).

**The threshold of a rung.** The rule names an effect when the baseline's gap ``G`` beats
what the augmented model leaves, ``A``, by more than the null scale ``S`` (``G − A > S``),
pays for the effect's ``k`` parameters (``A ≤ f^k · G``), and the model is found
misspecified (the gap test ``G > factor · S``, unless the effect test can fire). The first
cut took ``A = S`` (the augmented model fits as well as a correct model). That holds for a
deterministic forcing, not for a random one: re-simulated under other seeds, a gusty wind
draws other gusts, so the augmented model leaves its own seed-to-seed noise on top. For
squared distances the noise adds: ``A = S + floor_rung − floor``, where ``floor_rung`` is
the median distance among the rung's own clips (free: they are already simulated) and
``floor`` that among θ̂'s re-simulations — counted only when ``floor_rung`` exceeds the 95th
percentile of θ̂'s distances (a rung has only a pair or a few of clips, and a deterministic
effect's threshold must not rise by chance). On 8-s flags at gust intensity 0.5
the rung's clips differ by 8-15× θ̂'s floor — more than the rung is shifted from θ̂ — which
is why no gust diagnosis named gusts although the shift cleared ``S``. The same holds for a
deterministic effect that makes the motion more chaotic (a strong updraft).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from physinfer.discrepancy.decide import DecisionRule, rank_test_less
from physinfer.discrepancy.ladder import (
    Ladder,
    Probe,
    cross_median,
    moved_values,
    pairwise,
    pairwise_median,
)
from physinfer.discrepancy.refit import (
    RefitState,
    linear_refit,
    measured_refit,
    movers,
    predicted_refit,
)
from physinfer.parameters import ParameterSpace

_Snapshot = tuple[np.ndarray, np.ndarray, np.ndarray]


@dataclass
class RefitLog:
    """The measured refits of one :func:`effect_limit` call, in order: ``(rung, gap, u, and
    the states they left: (jac, u, emb), and the fine refit's or None)`` — what a second
    reading of the same ladder replays."""

    entries: list[tuple[int, float, np.ndarray, _Snapshot, _Snapshot | None]] = field(default_factory=list)


@dataclass(frozen=True)
class Threshold:
    """``τ``: the baseline gap at which the rule would name an effect, given what its model leaves.

    Attributes:
        scale: The null scale ``S``.
        n_params: The effect's extra parameters ``k``.
        per_parameter_factor: The rule's ``f``.
        gap_factor: The gap test's factor where the effect test cannot fire, else 0.
    """

    scale: float
    n_params: int
    per_parameter_factor: float
    gap_factor: float = 0.0

    @classmethod
    def of(
        cls, scale: float, n_params: int, rule: DecisionRule, n_candidates: int, n_seeds: int
    ) -> Threshold:
        """The rule's threshold for ``n_candidates`` effects and ``K = n_seeds`` re-simulations."""
        best_p = rank_test_less(list(range(n_seeds)), list(range(n_seeds, 2 * n_seeds)))
        effect_test = rule.effect_evidence and best_p < rule.alpha / max(n_candidates, 1)
        gap_factor = 0.0 if effect_test else rule.misspecified_factor
        return cls(scale, n_params, rule.per_parameter_factor, gap_factor)

    def at(self, excess: float = 0.0) -> float:
        """``τ`` when the augmented model leaves ``S + excess`` (its own extra seed noise)."""
        left = self.scale + max(excess, 0.0)
        return max(
            left + self.scale,  # the improvement must exceed S
            left / self.per_parameter_factor**self.n_params,  # ... and pay for k parameters
            self.gap_factor * self.scale,  # ... and the gap test must fire
        )

    def scaled(self, ratio: float) -> Threshold:
        """The same rule with the null scale multiplied by ``ratio`` (another setting's)."""
        return replace(self, scale=self.scale * ratio)


def required_gap(
    scale: float, n_params: int, rule: DecisionRule, n_candidates: int, n_seeds: int
) -> float:
    """``τ`` for an effect whose model fits as well as a correct model (leaving ``S``).

    Args:
        scale: The null scale ``S`` of the diagnosis.
        n_params: The effect's extra parameters ``k``.
        rule: The decision rule.
        n_candidates: Effects tried (the effect test's Bonferroni divisor).
        n_seeds: ``K``, re-simulations per gap measurement.
    """
    return Threshold.of(scale, n_params, rule, n_candidates, n_seeds).at()


def interpolate_limit(
    fractions: Sequence[float],
    gaps: Sequence[float],
    floor_gap: float,
    threshold: float | Sequence[float],
) -> float | None:
    """The fraction where the refit gap first clears the threshold (one, or one per rung).

    Between rungs the ratio gap / threshold is interpolated as a power law (linear in
    log–log); below the first rung, the excess over the floor grows as the strength squared
    (a squared distance of a shift linear in a small strength), against the first rung's
    threshold.
    """
    taus = (
        [float(threshold)] * len(gaps)
        if isinstance(threshold, int | float)
        else [float(t) for t in threshold]
    )
    prev: tuple[float, float] | None = None
    for f, g, tau in zip(fractions, gaps, taus, strict=True):
        if not math.isfinite(g):
            continue
        # A zero threshold (a deterministic model without calibration: null scale 0) is
        # cleared by any positive gap.
        ratio = g / tau if tau > 0.0 else (math.inf if g > 0.0 else 0.0)
        if ratio > 1.0:
            if prev is None or prev[1] <= 0.0:
                if tau <= floor_gap:
                    return 0.0
                return f * math.sqrt((tau - floor_gap) / (g - floor_gap))
            (pf, pr) = prev
            return math.exp(
                math.log(pf)
                + (math.log(f) - math.log(pf)) * (-math.log(pr)) / (math.log(ratio) - math.log(pr))
            )
        prev = (f, ratio)
    return None


def effect_limit(
    probe: Probe,
    ladder: Ladder,
    theta: Mapping[str, float],
    base_embeddings: np.ndarray,
    jac: np.ndarray,
    threshold: Threshold,
    seeds: Sequence[int],
    *,
    effect_space: ParameterSpace,
    measure: str,
    keep: Sequence[bool] | None = None,
    refits: RefitLog | None = None,
    fine_jac: np.ndarray | None = None,
) -> dict[str, Any]:
    """The detection limit of one effect from its ladder.

    Args:
        probe: For the measured refits.
        ladder: The effect's rungs.
        theta: θ̂.
        base_embeddings: ``(K, D_e)`` re-simulations of θ̂.
        jac: The baseline's Jacobian at θ̂.
        threshold: The rule's ``τ``, raised at each rung by that rung's own extra seed noise.
        seeds: Seeds of the measured refits.
        effect_space: The effect's parameters.
        measure: ``"all"`` rungs' refits measured, ``"key"`` (the top and the limit's), or
            ``"none"`` (predicted only: a what-if).
        keep: Base parameters the refit may move (``None``: all).
        refits: The measured refits of an earlier call on the same ladder, Jacobian, seeds and
            ``keep`` (the same limit read at another threshold): as long as this call measures
            the rungs in the order that one did, its refits are taken from it instead of
            simulated again — exactly what they would be, since a refit depends only on the
            rung and the state the earlier ones left. This call's own are appended.
        fine_jac: A second Jacobian at θ̂ (a finer step, a deterministic baseline's): each
            measured refit is made from both and the better kept, as the diagnosis' searches
            are polished with that step (:func:`physinfer.discrepancy.refit.polished_start`).

    Returns:
        ``detectable_from``, ``fraction``, ``reason``, ``mimicked_by``, ``rungs`` (each with
        its ``floor`` — the median distance among its own clips — and its ``threshold``).
    """
    space: ParameterSpace = probe.base.simulator.parameter_space
    u0 = space.to_unit(space.complete(theta))
    floor_gap = pairwise_median(base_embeddings)
    rungs = _predicted_rungs(ladder, base_embeddings, jac, u0, keep, threshold, floor_gap)
    fine = None if fine_jac is None else RefitState(fine_jac.copy(), u0, base_embeddings)
    refitter = _Refitter(
        probe, ladder, rungs, RefitState(jac.copy(), u0, base_embeddings), u0, base_embeddings, seeds,
        mode=measure, keep=keep, log=refits, fine=fine,
    )  # fmt: skip
    order = range(len(rungs)) if measure == "all" else [len(rungs) - 1]
    for i in order:
        refitter.measure(i)
    fraction = _settled_limit(ladder.fractions, rungs, floor_gap, refitter)
    reason, mimicked_by = None, []
    if fraction is None:
        reason, mimicked_by = _why_not(rungs[-1], space, jac, threshold.at(), floor_gap)
    detectable = None if fraction is None else moved_values(effect_space, fraction)
    return {
        "detectable_from": detectable,
        "fraction": fraction,
        "reason": reason,
        "mimicked_by": mimicked_by,
        "rungs": [
            {
                **{k: v for k, v in r.items() if k != "delta"},
                "refit_step": {n: float(d) for n, d in zip(space.names, r["delta"], strict=True)},
            }
            for r in rungs
        ],
    }


def _predicted_rungs(
    ladder: Ladder,
    base_embeddings: np.ndarray,
    jac: np.ndarray,
    u0: np.ndarray,
    keep: Sequence[bool] | None,
    threshold: Threshold,
    floor_gap: float,
) -> list[dict[str, Any]]:
    """Each rung with its shift from θ̂, its floor, its threshold and the refit the Jacobian
    predicts (``measured`` False: :class:`_Refitter` replaces it by a measured one)."""
    # A rung's floor is one pair of clips or a few: it counts as its own noise only beyond the
    # spread of θ̂'s (its 95th percentile), or a deterministic effect's threshold would rise by chance.
    base_pairs = pairwise(base_embeddings)
    floor_q95 = float(np.quantile(base_pairs, 0.95)) if base_pairs else 0.0
    rungs = []
    for f, values, emb in zip(ladder.fractions, ladder.values, ladder.embeddings, strict=True):
        gap, delta = predicted_refit(base_embeddings, emb, jac, u0, keep)
        own = pairwise_median(emb)
        rungs.append(
            {
                "fraction": f,
                "values": values,
                "shift": cross_median(emb, base_embeddings),
                "refit_gap": gap,
                "floor": own,
                "threshold": threshold.at(own - floor_gap if own > floor_q95 else 0.0),
                "measured": False,
                "delta": delta,
            }
        )
    return rungs


@dataclass
class _Refitter:
    """Measures rungs' refits, each from the state the earlier ones left, in the order asked.

    A refit is taken from ``log`` (an earlier call's, see :func:`effect_limit`) as long as
    this one measures the rungs in the order that one did; this call's own are appended to it.

    Attributes:
        mode: ``"all"``, ``"key"`` or ``"none"`` (nothing is measured).
        fine: The state of a second refit from a finer Jacobian (``None``: none).
        done: The rungs measured, in order.
    """

    probe: Probe
    ladder: Ladder
    rungs: list[dict[str, Any]]
    state: RefitState
    u0: np.ndarray
    base_embeddings: np.ndarray
    seeds: Sequence[int]
    mode: str
    keep: Sequence[bool] | None = None
    log: RefitLog | None = None
    fine: RefitState | None = None
    done: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._replay = list(self.log.entries) if self.log is not None else []
        # A deterministic rung is one simulation per point: search more (see measured_refit).
        self._multipliers, self._polish = ((1.0, 1.5, 2.0, 3.0), 2) if self.mode == "all" else ((1.0, 2.0), 1)

    def measure(self, i: int) -> None:
        """Measure rung ``i``'s refit (once), keeping the predicted one where it was no better
        than the shift itself."""
        r = self.rungs[i]
        if r["measured"] or self.mode == "none":
            return
        k, done, replay = len(self.done), self.done, self._replay
        if k < len(replay) and replay[k][0] == i and [e[0] for e in replay[:k]] == done:
            _, gap, u, coarse, fine = replay[k]
            _restore(self.state, coarse)
            if self.fine is not None and fine is not None:
                _restore(self.fine, fine)
        else:
            gap, u = self._refit(i, self.state, r["delta"])
            if self.fine is not None:
                shift = np.nanmean(self.ladder.embeddings[i], axis=0) - np.nanmean(self.base_embeddings, axis=0)
                fine_gap, fine_u = self._refit(i, self.fine, linear_refit(self.fine.jac, shift, self.u0, self.keep))
                gap, u = (fine_gap, fine_u) if fine_gap < gap else (gap, u)
            if self.log is not None and [e[0] for e in self.log.entries] == done:
                fine = None if self.fine is None else _snapshot(self.fine)
                self.log.entries.append((i, gap, u, _snapshot(self.state), fine))
        done.append(i)
        if gap < r["shift"]:
            r.update(refit_gap=gap, delta=u - self.u0)
        else:
            r.update(refit_gap=r["shift"], delta=np.zeros_like(self.u0))
        r["measured"] = True

    def _refit(self, i: int, state: RefitState, delta: np.ndarray) -> tuple[float, np.ndarray]:
        return measured_refit(
            self.probe, self.ladder.embeddings[i], state, (self.u0, self.base_embeddings), delta,
            self.seeds, multipliers=self._multipliers, polish=self._polish, keep=self.keep,
        )  # fmt: skip


def _snapshot(state: RefitState) -> _Snapshot:
    return state.jac.copy(), state.u, state.emb


def _restore(state: RefitState, snapshot: _Snapshot) -> None:
    state.jac, state.u, state.emb = snapshot[0].copy(), snapshot[1], snapshot[2]


def _settled_limit(
    fractions: Sequence[float], rungs: list[dict[str, Any]], floor_gap: float, refitter: _Refitter
) -> float | None:
    """The limit, with both rungs around it measured: measuring a rung may move the limit up,
    so it is read again until it settles (at most once per rung)."""
    taus = [r["threshold"] for r in rungs]
    fraction = None
    for _ in range(len(rungs)):
        fraction = interpolate_limit(fractions, [r["refit_gap"] for r in rungs], floor_gap, taus)
        if fraction is None:
            break
        i = next(i for i, f in enumerate(fractions) if f >= fraction - 1e-12)
        # Both rungs around the limit: between a measured and a predicted refit the limit
        # depends on how far the prediction is off, which changes from one clip length to
        # another (the jittery pendulum's 1.6-s clip came out below its 3.2-s one).
        bracket = [j for j in (i - 1, i) if j >= 0 and not rungs[j]["measured"]]
        if not bracket or refitter.mode == "none":
            break
        for j in bracket:
            refitter.measure(j)
    return fraction


def _why_not(
    top: Mapping[str, Any], space: ParameterSpace, jac: np.ndarray, tau: float, floor: float
) -> tuple[str, list[str]]:
    """The reason the strongest rung is not detectable, and the base parameters that mimic it.

    Mimicked when the refit undoes a shift that clears the rung's own threshold, or brings
    one that clears a deterministic effect's ``tau`` below it (whatever the rung's own noise
    adds: on an 8-s flag a 30° updraft did both); hidden by its own randomness when only the
    rung's own noise keeps the refit gap below its threshold.
    """
    if top["shift"] > top["threshold"] or top["shift"] > tau >= top["refit_gap"]:
        mimicked_by = movers(space, top["delta"], jac)
        return f"mimicked by {' and '.join(mimicked_by) or 'the base parameters'}", mimicked_by
    if top["shift"] > tau:
        return (
            f"hidden by its own randomness: re-simulated under other seeds its strongest "
            f"rung's clips differ by {top['floor']:.3g} ({top['floor'] / max(floor, 1e-300):.2g} x "
            f"the baseline's noise floor), more than the shift {top['shift']:.3g} can beat "
            f"(its threshold {top['threshold']:.3g})"
        ), []
    return (
        f"no signature above the noise within its range (strongest shift "
        f"{top['shift']:.3g}, {top['shift'] / tau:.2f} x the threshold {tau:.3g})"
    ), []
