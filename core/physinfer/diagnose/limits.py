"""Detection limits: the weakest strength of each effect that this target's setting could name.

A diagnosis that names nothing cannot tell "no effect is there" from "an effect may be there
and this video could not show it". A measuring instrument states its detection limit; so
does ``diagnose``. For each candidate effect, at the best baseline fit θ̂:

1. **Ladder.** The augmented model is simulated at θ̂ with the effect switched on at a few
   strengths (fractions of the way from *off* to the far end of its range, in normalised
   coordinates) under ``n`` fresh seeds each (one for a deterministic phenomenon). The
   *shift* of a rung is the median squared distance from its clips' embeddings to those of
   θ̂'s own re-simulations (the ``K`` clips of the noise floor, reused, not redone): the gap
   the baseline would leave against that target if it could not adapt.
2. **Mimicry (the base parameters' reply).** The baseline refit to a rung cannot do worse
   than θ̂, and may do much better when its parameters reproduce the effect's signature.
   One Jacobian of the baseline's embedding at θ̂ (a forward difference per base parameter,
   ``n`` seeds each, shared by every effect) gives the linear refit of each rung — the bounded
   least-squares step ``Δ`` with ``J Δ ≈`` the rung's mean shift — and its predicted gap (the
   base clips moved by ``J Δ``). The refit is then *measured* (θ̂ + Δ simulated, a second
   Gauss–Newton step from there, the better kept) at the strongest rung and at the rung
   where the limit falls (at every rung for a deterministic phenomenon, where a rung is one
   simulation).
3. **The rule's threshold.** With the augmented model assumed to fit as well as a correct
   model does (leaving the null scale ``S``), an effect is named when the baseline's gap
   ``G`` gives an improvement ``G − S > S`` that pays for its ``k`` parameters
   (``S ≤ per_parameter_factor^k · G``) and the model is found misspecified — by the gap test
   (``G > misspecified_factor · S``) or by the effect test, when ``K`` against ``K``
   re-simulations can reach its Bonferroni level at all. So ``τ = S · max(2, f^-k[, factor])``.
4. **Limit.** The smallest strength whose refit gap clears ``τ``, interpolated between rungs:
   ``detectable_from`` gives the value of each parameter there. ``None`` with a reason when
   even the strongest rung does not: the base parameters mimic it (the shift clears ``τ``
   but the refit does not — the reason names the parameters that moved), or it leaves no
   signature above the null scale within its range.

**What would reveal it** (:func:`reveal_options`): holding a base parameter at a known value
(``--fix``) removes its column from the refit — free, from the same simulations. Another
camera view (the target's ``camera_elevation_deg`` / ``camera_azimuth_deg``, where its ζ has
them) re-renders the same trajectories; a longer clip (``--duration`` twice the current one,
the embedder reading twice the frames) re-simulates the ladder. For those two the null scale
is not known (no self-consistency runs there): it is taken as the same multiple of the noise
floor as here, so they are measured only for a chaotic phenomenon, and only when asked.

Multi-parameter effects: the ladder moves the parameters whose *off* value lies on a bound
(magnitudes, e.g. a gust intensity) and holds those with an interior default at it (shapes,
e.g. the gusts' time scale, 1 s); when none lies on a bound, all move.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from physinfer.diagnose.decide import DecisionRule, rank_test_less
from physinfer.errors import UserInputError
from physinfer.parameters import ParameterSpace
from physinfer.refine import Pipeline, simulate_many, squared_distance

Log = Callable[[str], None]

#: ζ keys of a camera view and the values a "what would reveal it" check tries.
VIEW_CHANGES: dict[str, tuple[float, ...]] = {
    "camera_elevation_deg": (30.0,),
    "camera_azimuth_deg": (15.0,),
}


@dataclass(frozen=True)
class LimitConfig:
    """Settings of the detection-limit ladder.

    Attributes:
        fractions: Rungs, as fractions of the way from off to the far end of the range.
        seeds: Fresh seeds per rung (one for a deterministic phenomenon).
        step: Forward-difference step of the Jacobian, in normalised coordinates.
        reveal: Also measure another view and a longer clip (chaotic phenomena; costly).
        budget_share: Most of the diagnosis's simulations the ladder may cost; fewer seeds
            per rung (at least two) are used to stay within it.
    """

    fractions: tuple[float, ...] = (0.125, 0.25, 0.5, 1.0)
    seeds: int = 3
    step: float = 0.4
    reveal: bool = False
    budget_share: float = 0.2

    def to_dict(self) -> dict[str, Any]:
        """JSON form (part of the cache key)."""
        return {
            "fractions": list(self.fractions),
            "seeds": self.seeds,
            "step": self.step,
            "reveal": self.reveal,
            "budget_share": self.budget_share,
        }


# ----------------------------------------------------------------------------- the rule


def required_gap(
    scale: float, n_params: int, rule: DecisionRule, n_candidates: int, n_seeds: int
) -> float:
    """``τ``: the baseline gap at which the rule would name an effect that fits as well as a correct model.

    Args:
        scale: The null scale ``S`` of the diagnosis.
        n_params: The effect's extra parameters ``k``.
        rule: The decision rule.
        n_candidates: Effects tried (the effect test's Bonferroni divisor).
        n_seeds: ``K``, re-simulations per gap measurement.
    """
    factor = max(2.0, rule.per_parameter_factor ** (-n_params))  # improvement > S; pays for k
    best_p = rank_test_less(list(range(n_seeds)), list(range(n_seeds, 2 * n_seeds)))
    effect_test = rule.effect_evidence and best_p < rule.alpha / max(n_candidates, 1)
    if not effect_test:
        factor = max(factor, rule.misspecified_factor)
    return factor * scale


# ------------------------------------------------------------------------- strength path


def strength_path(space: ParameterSpace) -> tuple[dict[str, tuple[float, float]], dict[str, float]]:
    """Which parameters a ladder moves, from where to where (normalised), and which it holds.

    Returns:
        ``moved`` (name → (off, on) in ``[-1, 1]``: off is the declared default or the low
        bound, on the bound farthest from it) and ``held`` (name → physical off value).
    """
    ends = {}
    for spec in space:
        off = float(spec.default) if spec.default is not None else float(spec.bounds[0])
        u_off = float(spec.to_unit(off))
        ends[spec.name] = (u_off, -1.0 if u_off > 0 else 1.0, off)
    on_bound = [n for n, (u, _, _) in ends.items() if abs(abs(u) - 1.0) < 1e-9]
    moving = on_bound or list(ends)
    moved = {n: (ends[n][0], ends[n][1]) for n in moving}
    held = {n: ends[n][2] for n in ends if n not in moving}
    return moved, held


def values_at(
    space: ParameterSpace,
    moved: Mapping[str, tuple[float, float]],
    held: Mapping[str, float],
    fraction: float,
) -> dict[str, float]:
    """The effect's physical parameters ``fraction`` of the way along its path."""
    values = dict(held)
    for name, (u_off, u_on) in moved.items():
        values[name] = float(space[name].from_unit(u_off + fraction * (u_on - u_off)))
    return values


# ---------------------------------------------------------------------------- measuring


class Probe:
    """Simulate (batched), render and embed at the target's ζ; counts its simulations."""

    def __init__(self, base: Pipeline, render_params: Mapping[str, Any]) -> None:
        self.base = base
        self.render_params = dict(render_params)
        self.simulations = 0

    def trajectories(
        self, simulator: Any, params: Sequence[Mapping[str, float]], seeds: Sequence[int]
    ) -> list[Any]:
        """One batch through the simulator's engine (``None`` for a failed simulation)."""
        self.simulations += len(params)
        return [t for t, _ in simulate_many(simulator, list(params), [int(s) for s in seeds])]

    def embed(
        self,
        trajectories: Sequence[Any],
        render_params: Mapping[str, Any] | None = None,
        embedder: Any = None,
    ) -> np.ndarray:
        """``(N, D)`` embeddings (a row of NaN for a failed simulation)."""
        zeta = self.render_params if render_params is None else render_params
        embedder = embedder or self.base.embedder
        rows: list[np.ndarray | None] = []
        for traj in trajectories:
            rows.append(
                None
                if traj is None
                else np.asarray(
                    embedder.embed(self.base.renderer.render(traj, zeta)), dtype=np.float64
                )
            )
        width = next((r.size for r in rows if r is not None), 0)
        return (
            np.stack([np.full(width, np.nan) if r is None else r for r in rows])
            if rows
            else np.zeros((0, 0))
        )


def cross_median(a: np.ndarray, b: np.ndarray) -> float:
    """Median squared distance between the rows of ``a`` and those of ``b`` (failed rows skipped)."""
    a, b = a[np.isfinite(a).all(axis=1)], b[np.isfinite(b).all(axis=1)]
    if len(a) == 0 or len(b) == 0:
        return float("nan")
    return float(np.median([squared_distance(x, y) for x in a for y in b]))


def pairwise_median(a: np.ndarray) -> float:
    """Median squared distance among the rows of ``a`` (the noise floor of one θ)."""
    a = a[np.isfinite(a).all(axis=1)]
    values = [squared_distance(a[i], a[j]) for i in range(len(a)) for j in range(i + 1, len(a))]
    return float(np.median(values)) if values else 0.0


def jacobian(
    probe: Probe,
    theta: Mapping[str, float],
    base_embeddings: np.ndarray,
    seeds: Sequence[int],
    step: float,
    simulator: Any = None,
) -> tuple[np.ndarray, list[Any]]:
    """Forward-difference Jacobian ``(D_e, P)`` of the mean embedding in normalised coordinates.

    Each column steps one base parameter by ``step`` towards the inside of its range and
    takes the mean over ``seeds`` minus the mean of ``base_embeddings``. Returns the
    Jacobian and the trajectories (for re-rendering from another view).
    """
    simulator = simulator or probe.base.simulator
    space: ParameterSpace = probe.base.simulator.parameter_space
    u0 = space.to_unit(space.complete(theta))
    jobs, signs = [], []
    for d in range(len(space)):
        sign = 1.0 if u0[d] + step <= 1.0 else -1.0
        u = u0.copy()
        u[d] += sign * step
        jobs += [space.from_unit(u)] * len(seeds)
        signs.append(sign)
    trajs = probe.trajectories(simulator, jobs, list(seeds) * len(space))
    return jacobian_from(probe.embed(trajs), base_embeddings, signs, len(seeds), step), trajs


def jacobian_from(
    embeddings: np.ndarray,
    base_embeddings: np.ndarray,
    signs: Sequence[float],
    n_seeds: int,
    step: float,
) -> np.ndarray:
    """The Jacobian of :func:`jacobian` from its stepped embeddings ``(P · n, D_e)``."""
    mean0 = np.nanmean(base_embeddings, axis=0)
    cols = [
        (np.nanmean(embeddings[d * n_seeds : (d + 1) * n_seeds], axis=0) - mean0) / (s * step)
        for d, s in enumerate(signs)
    ]
    return np.nan_to_num(np.stack(cols, axis=1))


def linear_refit(
    jac: np.ndarray, shift: np.ndarray, u0: np.ndarray, keep: Sequence[bool] | None = None
) -> np.ndarray:
    """Bounded least squares ``Δ`` (normalised) with ``J Δ ≈ shift`` and ``u0 + Δ`` in ``[-1, 1]``.

    ``keep[d] = False`` holds parameter ``d`` (a value the user knows: ``--fix``).
    """
    from scipy.optimize import lsq_linear

    keep = np.ones(jac.shape[1], bool) if keep is None else np.asarray(keep, bool)
    delta = np.zeros(jac.shape[1])
    if not keep.any() or not np.isfinite(shift).all():
        return delta
    lo, hi = -1.0 - u0[keep], 1.0 - u0[keep]
    # The bounds must be strictly ordered; a parameter exactly on a bound gets a sliver.
    hi = np.maximum(hi, lo + 1e-12)
    delta[keep] = lsq_linear(jac[:, keep], shift, bounds=(lo, hi)).x
    return delta


# ---------------------------------------------------------------------------- one effect


@dataclass
class Ladder:
    """The simulations of one effect's ladder at θ̂ (everything a limit is computed from)."""

    fractions: list[float]
    values: list[dict[str, float]]
    embeddings: list[np.ndarray]  # per rung (n, D_e)
    trajectories: list[list[Any]]


def run_ladder(
    probe: Probe,
    augmented: Pipeline,
    theta: Mapping[str, float],
    effect_space: ParameterSpace,
    fractions: Sequence[float],
    seeds: Sequence[int],
) -> Ladder:
    """Simulate every rung under ``seeds`` in one batch."""
    moved, held = strength_path(effect_space)
    values = [values_at(effect_space, moved, held, f) for f in fractions]
    jobs = [{**theta, **v} for v in values for _ in seeds]
    trajs = probe.trajectories(augmented.simulator, jobs, list(seeds) * len(values))
    n = len(seeds)
    per_rung = [trajs[i * n : (i + 1) * n] for i in range(len(values))]
    return Ladder(list(fractions), values, [probe.embed(t) for t in per_rung], per_rung)


def predicted_refit(
    base_embeddings: np.ndarray,
    rung: np.ndarray,
    jac: np.ndarray,
    u0: np.ndarray,
    keep: Sequence[bool] | None = None,
) -> tuple[float, np.ndarray]:
    """The linear refit's gap to a rung (never above the unrefitted shift) and its step ``Δ``."""
    shift_vec = np.nanmean(rung, axis=0) - np.nanmean(base_embeddings, axis=0)
    delta = linear_refit(jac, shift_vec, u0, keep)
    unmoved = cross_median(rung, base_embeddings)
    return min(unmoved, cross_median(rung, base_embeddings + jac @ delta)), delta


@dataclass
class RefitState:
    """A measured refit's memory, carried from rung to rung (a continuation along the ladder).

    ``jac`` is the Jacobian, updated by Broyden's rank-one rule after every simulated step;
    ``u``/``emb`` the best base point found for the previous rung and its embeddings.
    """

    jac: np.ndarray
    u: np.ndarray
    emb: np.ndarray

    def broyden(self, du: np.ndarray, dm: np.ndarray) -> None:
        """Make ``jac`` reproduce the change ``dm`` seen over the step ``du``."""
        norm = float(du @ du)
        if norm > 1e-12 and np.isfinite(dm).all():
            self.jac = self.jac + np.outer(dm - self.jac @ du, du) / norm


def measured_refit(
    probe: Probe,
    rung: np.ndarray,
    state: RefitState,
    start: tuple[np.ndarray, np.ndarray],
    delta: np.ndarray,
    seeds: Sequence[int],
    *,
    multipliers: Sequence[float],
    polish: int,
    keep: Sequence[bool] | None = None,
) -> tuple[float, np.ndarray]:
    """Refit the baseline to a rung, every point simulated: a line search, then Gauss–Newton.

    The embedding is far from linear in some parameters, and the distance is bumpy (the
    pendulum's decay envelope in its damping: a linear step from θ̂ goes less than half way
    to an exactly mimicking damping, and the distance rises and falls on the way). So the
    linear refit's step ``delta`` from θ̂ is tried at ``multipliers`` of its length (inside
    the box), and the best of those, θ̂ itself and the previous rung's refit is polished by
    ``polish`` Gauss–Newton steps on the Broyden-updated Jacobian.

    Args:
        probe: Simulates and embeds.
        rung: ``(n, D_e)`` the rung's embeddings.
        state: The Jacobian and the previous rung's refit (updated here).
        start: θ̂'s ``(u0, embeddings)``.
        delta: The linear refit's step for this rung.
        seeds: Seeds of every simulated point.
        multipliers: Line-search lengths.
        polish: Gauss–Newton steps.
        keep: Base parameters the refit may move.

    Returns:
        The best gap and its point (normalised).
    """
    space: ParameterSpace = probe.base.simulator.parameter_space
    u0, emb0 = start
    goal = np.nanmean(rung, axis=0)
    points = [(u0, emb0), (state.u, state.emb)]

    def visit(u: np.ndarray, origin: tuple[np.ndarray, np.ndarray]) -> None:
        if any(np.max(np.abs(u - p)) < 1e-3 for p, _ in points):
            return
        params = space.from_unit(u)
        emb = probe.embed(probe.trajectories(probe.base.simulator, [params] * len(seeds), seeds))
        state.broyden(u - origin[0], np.nanmean(emb, axis=0) - np.nanmean(origin[1], axis=0))
        points.append((u, emb))

    for t in multipliers:
        visit(np.clip(u0 + t * delta, -1.0, 1.0), start)
    gaps = [cross_median(rung, e) for _, e in points]
    for _ in range(polish):
        best = points[int(np.nanargmin(gaps))]
        step = linear_refit(state.jac, goal - np.nanmean(best[1], axis=0), best[0], keep)
        before = len(points)
        visit(np.clip(best[0] + step, -1.0, 1.0), best)
        if len(points) == before:
            break
        gaps.append(cross_median(rung, points[-1][1]))
    i = int(np.nanargmin(gaps))
    state.u, state.emb = points[i]
    return gaps[i], points[i][0]


def interpolate_limit(
    fractions: Sequence[float], gaps: Sequence[float], floor_gap: float, threshold: float
) -> float | None:
    """The fraction where the refit gap first clears ``threshold``.

    Between rungs the gap is interpolated as a power law (linear in log–log); below the
    first rung, the excess over the floor grows as the strength squared (a squared distance
    of a shift linear in a small strength).
    """
    prev: tuple[float, float] | None = None
    for f, g in zip(fractions, gaps, strict=True):
        if not math.isfinite(g):
            continue
        if g > threshold:
            if prev is None or prev[1] <= 0.0:
                if threshold <= floor_gap:
                    return 0.0
                return f * math.sqrt((threshold - floor_gap) / (g - floor_gap))
            (pf, pg) = prev
            return math.exp(
                math.log(pf)
                + (math.log(f) - math.log(pf))
                * (math.log(threshold) - math.log(pg))
                / (math.log(g) - math.log(pg))
            )
        prev = (f, g)
    return None


def effect_limit(
    probe: Probe,
    ladder: Ladder,
    theta: Mapping[str, float],
    base_embeddings: np.ndarray,
    jac: np.ndarray,
    threshold: float,
    seeds: Sequence[int],
    *,
    effect_space: ParameterSpace,
    measure: str,
    keep: Sequence[bool] | None = None,
) -> dict[str, Any]:
    """The detection limit of one effect from its ladder.

    Args:
        probe: For the measured refits.
        ladder: The effect's rungs.
        theta: θ̂.
        base_embeddings: ``(K, D_e)`` re-simulations of θ̂.
        jac: The baseline's Jacobian at θ̂.
        threshold: ``τ``.
        seeds: Seeds of the measured refits.
        effect_space: The effect's parameters.
        measure: ``"all"`` rungs' refits measured, ``"key"`` (the top and the limit's), or
            ``"none"`` (predicted only: a what-if).
        keep: Base parameters the refit may move (``None``: all).

    Returns:
        ``detectable_from``, ``fraction``, ``reason``, ``mimicked_by``, ``rungs``.
    """
    space: ParameterSpace = probe.base.simulator.parameter_space
    u0 = space.to_unit(space.complete(theta))
    floor_gap = pairwise_median(base_embeddings)
    rungs = []
    for f, values, emb in zip(ladder.fractions, ladder.values, ladder.embeddings, strict=True):
        gap, delta = predicted_refit(base_embeddings, emb, jac, u0, keep)
        rungs.append(
            {
                "fraction": f,
                "values": values,
                "shift": cross_median(emb, base_embeddings),
                "refit_gap": gap,
                "measured": False,
                "delta": delta,
            }
        )

    state = RefitState(jac.copy(), u0, base_embeddings)
    # A deterministic rung is one simulation per point: search more (see measured_refit).
    multipliers, polish = ((1.0, 1.5, 2.0, 3.0), 2) if measure == "all" else ((1.0, 2.0), 1)

    def measure_rung(i: int) -> None:
        r = rungs[i]
        if r["measured"] or measure == "none":
            return
        gap, u = measured_refit(
            probe, ladder.embeddings[i], state, (u0, base_embeddings), r["delta"], seeds,
            multipliers=multipliers, polish=polish, keep=keep,
        )  # fmt: skip
        if gap < r["shift"]:
            r.update(refit_gap=gap, delta=u - u0)
        else:
            r.update(refit_gap=r["shift"], delta=np.zeros_like(u0))
        r["measured"] = True

    order = range(len(rungs)) if measure == "all" else [len(rungs) - 1]
    for i in order:
        measure_rung(i)
    fraction = None
    for _ in range(len(rungs)):  # measuring a rung may move the limit up: settle it
        fraction = interpolate_limit(
            ladder.fractions, [r["refit_gap"] for r in rungs], floor_gap, threshold
        )
        if fraction is None:
            break
        i = next(i for i, f in enumerate(ladder.fractions) if f >= fraction - 1e-12)
        if rungs[i]["measured"] or measure == "none":
            break
        measure_rung(i)
    top = rungs[-1]
    reason, mimicked_by = None, []
    if fraction is None:
        if top["shift"] > threshold:
            mimicked_by = _movers(space, top["delta"], jac)
            who = " and ".join(mimicked_by) or "the base parameters"
            reason = f"mimicked by {who}"
        else:
            reason = (
                f"no signature above the noise within its range (strongest shift "
                f"{top['shift']:.3g}, {top['shift'] / threshold:.2f} x the threshold {threshold:.3g})"
            )
    detectable = None if fraction is None else _values_for(effect_space, fraction)
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


def _movers(space: ParameterSpace, delta: np.ndarray, jac: np.ndarray) -> list[str]:
    """Base parameters whose refit step explains a share of the signature, largest first."""
    contrib = np.linalg.norm(jac * delta[None, :], axis=0)
    if not contrib.any():
        return []
    order = np.argsort(-contrib)
    # A parameter moved by less than a twentieth of its range is not what mimics the effect.
    return [
        space.names[d]
        for d in order
        if contrib[d] >= 0.2 * contrib[order[0]] and abs(delta[d]) > 0.1
    ]


# ---------------------------------------------------------------------------- every effect


@dataclass
class LimitInputs:
    """What the ladder needs from the diagnosis.

    Attributes:
        base: The baseline pipeline (its simulator holds ``--fix`` values).
        augmented: Effect name → the baseline with that effect switched in.
        theta: θ̂, the best baseline fit (base parameters).
        base_embeddings: ``(K, D_e)`` θ̂'s re-simulations from the gap measurement (reused).
        render_params: The target's ζ.
        scale: The null scale ``S``.
        rule: The decision rule.
        floor_samples: ``K``.
        seed: The diagnosis seed (the ladder's seeds are derived from it).
        diagnosis_simulations: Simulations the diagnosis cost (for the budget).
        make_longer: ``None``, or a factory that, given the current clip's seconds, returns
            ``(base simulator, {effect: simulator}, embedder)`` recording twice as long (the
            longer-clip what-if); it raises :class:`UserInputError` where the phenomenon
            records a fixed length.
    """

    base: Pipeline
    augmented: Mapping[str, Pipeline]
    theta: Mapping[str, float]
    base_embeddings: np.ndarray
    render_params: Mapping[str, Any]
    scale: float
    rule: DecisionRule
    floor_samples: int
    seed: int
    diagnosis_simulations: int
    make_longer: Callable[[float], tuple[Any, dict[str, Any], Any]] | None = None


def ladder_seeds(seed: int, n: int) -> list[int]:
    """Seeds of the ladder, apart from the diagnosis's trial and re-simulation seeds."""
    from physinfer.noise import noise_seeds

    return noise_seeds(seed + 11, n, salt=0x11D)


def _plan_seeds(inputs: LimitInputs, config: LimitConfig, deterministic: bool) -> int:
    """Seeds per rung: one when deterministic; else the configured number, fewer (≥ 2) to fit the budget."""
    if deterministic:
        return 1
    n_params, rungs, effects = (
        len(inputs.base.simulator.parameter_space),
        len(config.fractions),
        len(inputs.augmented),
    )
    n = config.seeds
    while (
        n > 2
        and n * (n_params + effects * (rungs + 4))
        > config.budget_share * inputs.diagnosis_simulations
    ):
        n -= 1
    return n


def detection_limits(
    inputs: LimitInputs, config: LimitConfig, *, log: Log | None = None
) -> dict[str, Any]:
    """Every candidate's detection limit at θ̂, and what would lower it.

    Returns:
        ``effects`` (name → :func:`effect_limit`'s result with ``threshold`` and ``reveal``),
        ``seeds``, ``simulations`` (the ladder's), ``diagnosis_simulations``, ``share``,
        ``deterministic``.
    """
    say = log or (lambda _msg: None)
    start = time.perf_counter()
    probe = Probe(inputs.base, inputs.render_params)
    base_emb = np.asarray(inputs.base_embeddings, dtype=np.float64)
    deterministic = pairwise_median(base_emb) == 0.0
    n = _plan_seeds(inputs, config, deterministic)
    seeds = ladder_seeds(inputs.seed, n)
    # The baseline's own simulations (Jacobian, refits) never share a seed with a rung: with
    # common seeds a chaotic clip's noise would cancel and the refit look better than it is.
    refit_seeds = ladder_seeds(inputs.seed + 1, n)
    space: ParameterSpace = inputs.base.simulator.parameter_space
    theta = {k: float(v) for k, v in space.complete(inputs.theta).items()}
    jac, jac_trajs = jacobian(probe, theta, base_emb, refit_seeds, config.step)
    seconds = next((t.vertices.shape[0] / t.fps for t in jac_trajs if t is not None), None)
    measure = "all" if deterministic else "key"
    effects: dict[str, Any] = {}
    ladders: dict[str, Ladder] = {}
    for name, pipeline in inputs.augmented.items():
        effect_space = pipeline.effects[0].parameter_space
        threshold = required_gap(
            inputs.scale,
            len(effect_space),
            inputs.rule,
            len(inputs.augmented),
            inputs.floor_samples,
        )
        ladders[name] = run_ladder(probe, pipeline, theta, effect_space, config.fractions, seeds)
        limit = effect_limit(
            probe,
            ladders[name],
            theta,
            base_emb,
            jac,
            threshold,
            refit_seeds,
            effect_space=effect_space,
            measure=measure,
        )
        limit["threshold"] = threshold
        limit["reveal"] = _reveal_by_fixing(
            probe, ladders[name], theta, base_emb, jac, threshold, refit_seeds, limit, effect_space
        )
        effects[name] = limit
        say(f"      {name}: " + summary_phrase(limit))
    if config.reveal and not deterministic:
        _reveal_by_setting(
            probe, inputs, config, effects, ladders, theta, refit_seeds, jac_trajs, say, seeds
        )
    return {
        "effects": effects,
        "seeds": seeds,
        "refit_seeds": refit_seeds,
        "deterministic": deterministic,
        "simulations": probe.simulations,
        "diagnosis_simulations": inputs.diagnosis_simulations,
        "share": probe.simulations / max(inputs.diagnosis_simulations, 1),
        "config": config.to_dict(),
        "clip_seconds": seconds,
        "wall_time_s": time.perf_counter() - start,
    }


def _improvement(before: dict[str, Any], after: dict[str, Any]) -> float | None:
    """How many times lower the limit is after a change (``inf``: it becomes detectable)."""
    if after["fraction"] is None:
        return None
    if before["fraction"] is None or after["fraction"] <= 0:
        return math.inf
    return before["fraction"] / after["fraction"]


def _reveal_by_fixing(
    probe: Probe,
    ladder: Ladder,
    theta: Mapping[str, float],
    base_emb: np.ndarray,
    jac: np.ndarray,
    threshold: float,
    seeds: Sequence[int],
    limit: dict[str, Any],
    effect_space: ParameterSpace,
) -> list[dict[str, Any]]:
    """``--fix P``: the refit may not move P (a value the user knows); from the same ladder, no simulation.

    The factor compares the linear refit's limits with and without P (predicted both ways,
    like with like); the limit under ``--fix`` is the measured one divided by it.
    """
    space: ParameterSpace = probe.base.simulator.parameter_space
    out: list[dict[str, Any]] = []
    if len(space) < 2:
        return out
    now = effect_limit(
        probe,
        ladder,
        theta,
        base_emb,
        jac,
        threshold,
        seeds,
        effect_space=effect_space,
        measure="none",
    )
    for d, name in enumerate(space.names):
        keep = [i != d for i in range(len(space))]
        fixed = effect_limit(
            probe,
            ladder,
            theta,
            base_emb,
            jac,
            threshold,
            seeds,
            effect_space=effect_space,
            measure="none",
            keep=keep,
        )
        factor = _improvement(now, fixed)
        if factor is None or factor <= 1.05:
            continue
        detectable = fixed["detectable_from"]
        if limit["fraction"] is None:
            factor = math.inf  # not detectable as measured; detectable as predicted with P held
        elif math.isfinite(factor):
            detectable = _values_for(effect_space, limit["fraction"] / factor)
        out.append(
            {
                "change": f"--fix {name}=<its value>",
                "kind": "fix",
                "parameter": name,
                "detectable_from": detectable,
                "factor": _finite(factor),
                "measured": False,
            }
        )
    return out


def _values_for(effect_space: ParameterSpace, fraction: float) -> dict[str, float]:
    """The moved parameters' values ``fraction`` of the way along the path."""
    moved, held = strength_path(effect_space)
    return {k: v for k, v in values_at(effect_space, moved, held, fraction).items() if k in moved}


def _reveal_by_setting(
    probe: Probe,
    inputs: LimitInputs,
    config: LimitConfig,
    effects: dict[str, Any],
    ladders: Mapping[str, Ladder],
    theta: Mapping[str, float],
    seeds: Sequence[int],
    jac_trajs: list[Any],
    say: Log,
    rung_seeds: Sequence[int] = (),
) -> None:
    """Another view (re-rendered) and a twice longer clip (re-simulated), for effects not yet detectable at half range.

    The null scale there is unknown: the threshold is scaled by the ratio of the noise
    floors (new / current), both measured on ``n`` fresh re-simulations of θ̂; the current
    setting's limit is recomputed on those too, so the factor compares like with like.
    ``seeds`` are the baseline's (the Jacobian's), ``rung_seeds`` the ladder's.
    """
    wanted = [
        name for name, lim in effects.items() if lim["fraction"] is None or lim["fraction"] > 0.5
    ]
    if not wanted:
        return
    space: ParameterSpace = inputs.base.simulator.parameter_space
    signs = [1.0 if u + config.step <= 1.0 else -1.0 for u in space.to_unit(space.complete(theta))]
    base_trajs = probe.trajectories(inputs.base.simulator, [theta] * len(seeds), seeds)
    here = probe.embed(base_trajs)
    jac_here = jacobian_from(probe.embed(jac_trajs), here, signs, len(seeds), config.step)
    zetas = [
        (key, value)
        for key, values in VIEW_CHANGES.items()
        if key in inputs.render_params
        for value in values
        if float(inputs.render_params[key]) != value
    ]

    def limits_in(
        emb_base: np.ndarray,
        jac_new: np.ndarray,
        rung_emb: Mapping[str, list[np.ndarray]],
        change: str,
    ) -> None:
        ratio = pairwise_median(emb_base) / max(pairwise_median(here), 1e-300)
        for name in wanted:
            effect_space = inputs.augmented[name].effects[0].parameter_space
            ladder = ladders[name]
            now = effect_limit(
                probe,
                ladder,
                theta,
                here,
                jac_here,
                effects[name]["threshold"],
                seeds,
                effect_space=effect_space,
                measure="none",
            )
            other = Ladder(ladder.fractions, ladder.values, list(rung_emb[name]), [])
            new = effect_limit(
                probe,
                other,
                theta,
                emb_base,
                jac_new,
                effects[name]["threshold"] * ratio,
                seeds,
                effect_space=effect_space,
                measure="none",
            )
            factor = _improvement(now, new)
            if factor is None or factor <= 1.05:
                continue
            detectable, measured_here = new["detectable_from"], effects[name]["fraction"]
            if measured_here is None:
                factor = math.inf
            elif math.isfinite(factor):
                detectable = _values_for(effect_space, measured_here / factor)
            effects[name]["reveal"].append(
                {
                    "change": change,
                    "kind": "setting",
                    "detectable_from": detectable,
                    "factor": _finite(factor),
                    "measured": False,
                }
            )

    for key, value in zetas:
        zeta = {**inputs.render_params, key: value}
        try:
            emb_base = probe.embed(base_trajs, zeta)
        except Exception as exc:  # noqa: BLE001 - a view the renderer refuses is skipped, said once
            say(f"      (view {key}={value:g} skipped: {exc})")
            continue
        jac_new = jacobian_from(
            probe.embed(jac_trajs, zeta), emb_base, signs, len(seeds), config.step
        )
        rungs = {
            name: [probe.embed(t, zeta) for t in ladders[name].trajectories] for name in wanted
        }
        limits_in(emb_base, jac_new, rungs, f"--render-set {key}={value:g}")
    seconds = next((t.vertices.shape[0] / t.fps for t in base_trajs if t is not None), None)
    if inputs.make_longer is not None and seconds is not None:
        try:
            base_sim, aug_sims, embedder = inputs.make_longer(seconds)
        except UserInputError as exc:
            say(f"      (a longer clip is not tried: {exc})")
            return
        longer_probe = Probe(inputs.base, inputs.render_params)
        emb_base = longer_probe.embed(
            longer_probe.trajectories(base_sim, [theta] * len(seeds), seeds), None, embedder
        )
        u0 = space.to_unit(space.complete(theta))
        jobs = []
        for d in range(len(space)):
            u = u0.copy()
            u[d] += signs[d] * config.step
            jobs += [space.from_unit(u)] * len(seeds)
        jac_emb = longer_probe.embed(
            longer_probe.trajectories(base_sim, jobs, list(seeds) * len(space)), None, embedder
        )
        jac_new = jacobian_from(jac_emb, emb_base, signs, len(seeds), config.step)
        rungs = {}
        for name in wanted:
            values = ladders[name].values
            trajs = longer_probe.trajectories(
                aug_sims[name],
                [{**theta, **v} for v in values for _ in rung_seeds],
                list(rung_seeds) * len(values),
            )
            rungs[name] = [
                longer_probe.embed(trajs[i * len(seeds) : (i + 1) * len(seeds)], None, embedder)
                for i in range(len(values))
            ]
        probe.simulations += longer_probe.simulations
        limits_in(emb_base, jac_new, rungs, "a clip twice as long (--duration, --embedder-frames)")


def _finite(factor: float) -> float | None:
    """JSON has no infinity: ``None`` stands for "from not detectable to detectable"."""
    return None if math.isinf(factor) else float(factor)


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
    return f"{candidate['effect']}: {status}; {clip} {summary_phrase(limit)}{reveal_phrase(limit)}"
