"""Detection limits: the weakest strength of each effect that this target's setting could name.

A diagnosis that names nothing cannot tell "no effect is there" from "an effect may be there
and this video could not show it". A measuring instrument states its detection limit; so
does ``diagnose``. For each candidate effect, at the best baseline fit θ̂:

1. **Ladder** (:mod:`physinfer.discrepancy.ladder`). The augmented model is simulated at θ̂
   with the effect switched on at a few strengths (fractions of the way from *off* to the
   far end of its range, in normalised coordinates) under ``n`` fresh seeds each (one for a
   deterministic phenomenon). The *shift* of a rung is the median squared distance from its
   clips' embeddings to those of θ̂'s own re-simulations (the ``K`` clips of the noise
   floor, reused, not redone): the gap the baseline would leave against that target if it
   could not adapt. Its *own floor* is the median distance among its ``n`` clips.
2. **Mimicry** (:mod:`physinfer.discrepancy.refit`: the base parameters' reply). The baseline
   refit to a rung cannot do worse than θ̂, and may do much better when its parameters
   reproduce the effect's signature. One Jacobian of the baseline's embedding at θ̂ (a
   forward difference per base parameter, ``n`` seeds each, shared by every effect) gives
   the linear refit of each rung and its predicted gap. The refit is then *measured* (a
   line search along the linear step, Gauss–Newton from there) at the strongest rung and at
   the rung where the limit falls (at every rung for a deterministic phenomenon, where a
   rung is one simulation).
3. **The rule's threshold** (:mod:`physinfer.discrepancy.limit_rule`). An effect is named when
   the baseline's gap ``G`` beats what the augmented model leaves, ``A``, by more than the
   null scale ``S``, pays for its ``k`` parameters (``A ≤ per_parameter_factor^k · G``) and
   the model is found misspecified — by the gap test (``G > misspecified_factor · S``) or by
   the effect test, when ``K`` against ``K`` re-simulations can reach its Bonferroni level at
   all. ``A = S`` plus the rung's own floor's excess over θ̂'s: a random forcing (gusts)
   leaves its own seed-to-seed noise, which no refit of the base parameters removes.
4. **Limit.** The smallest strength whose refit gap clears its rung's threshold,
   interpolated between rungs: ``detectable_from`` gives the value of each moved parameter
   there. ``None`` with a reason when even the strongest rung does not: the base parameters
   mimic it (the shift clears the threshold but the refit does not — the reason names the
   parameters that moved), its own randomness hides it (the shift clears the threshold of a
   deterministic effect but not its own), or it leaves no signature above the null scale.

**What would reveal it** (:mod:`physinfer.discrepancy.reveal`): ``--fix`` of a base parameter
(free), another camera view and a twice longer clip (measured only when asked). The printed
line is :func:`physinfer.discrepancy.limit_text.limit_line`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.discrepancy.clip_jobs import concurrently
from physinfer.discrepancy.ladder import Ladder, Probe, ladder_seeds, pairwise_median, run_ladder
from physinfer.discrepancy.limit_rule import RefitLog, Threshold, effect_limit
from physinfer.discrepancy.limit_text import summary_phrase
from physinfer.discrepancy.refit import POLISH_JACOBIAN_STEP, jacobian
from physinfer.discrepancy.reveal import reveal_by_fixing, reveal_by_setting
from physinfer.evaluation import Pipeline
from physinfer.moved import moved_names
from physinfer.parameters import ParameterSpace

if TYPE_CHECKING:
    from physinfer.discrepancy.ladder import LimitInputs, ProbeFactory
    from physinfer.discrepancy.settings import LimitConfig

__all__ = ["detection_limits"]

#: The ladder's, the rule's and the printed line's names, which moved out of this module, still
#: found here with a warning (:data:`physinfer.moved.MOVED`).
__getattr__ = moved_names(__name__)

Log = Callable[[str], None]


def _plan_seeds(inputs: LimitInputs, config: LimitConfig, deterministic: bool) -> int:
    """Seeds per rung: one when deterministic; else the configured number, fewer (≥ 2) to fit the budget."""
    if deterministic:
        return 1
    n_params, rungs, effects = (
        len(inputs.base.simulator.parameter_space),
        len(config.fractions),
        inputs.candidates,
    )
    n = config.seeds
    while (
        n > 2
        and n * (n_params + effects * (rungs + 4))
        > config.budget_share * inputs.diagnosis_simulations
    ):
        n -= 1
    return n


@dataclass(frozen=True)
class EffectTask:
    """One effect's share of the ladder — its rungs, limit and ``--fix`` what-ifs — as plain
    data (:func:`effect_ladder` runs it; each in a thread of its own with pooled probes).

    Attributes:
        name: The effect.
        theta: θ̂, complete.
        base_embeddings: θ̂'s re-simulations' embeddings.
        jac: The shared Jacobian at θ̂.
        threshold: The rule's threshold for this effect.
        fractions: The rungs.
        seeds: Each rung's seeds.
        refit_seeds: The baseline's seeds (Jacobian, refits).
        deterministic: One clip per rung, every rung's refit measured.
        threshold_low: The threshold at the lower end of the null scale's range, where the
            diagnosis knows its null scale only as a range (``None``: it knows it).
        fine_jac: A deterministic baseline's Jacobian at the polish's finer step (``None``: none).
        encoded: Each rung through the video encoder and back (:attr:`LimitInputs.encoded`).
    """

    name: str
    theta: dict[str, float]
    base_embeddings: np.ndarray
    jac: np.ndarray
    threshold: Threshold
    fractions: tuple[float, ...]
    seeds: tuple[int, ...]
    refit_seeds: tuple[int, ...]
    deterministic: bool
    threshold_low: Threshold | None = None
    fine_jac: np.ndarray | None = None
    encoded: bool = False


def effect_ladder(probe: Probe, augmented: Pipeline, task: EffectTask) -> tuple[dict[str, Any], Ladder]:
    """Run ``task`` with ``probe`` and the effect's ``augmented`` pipeline: its limit record and ladder."""
    effect_space = augmented.effects[0].parameter_space
    ladder = run_ladder(probe, augmented, task.theta, effect_space, task.fractions, task.seeds, task.encoded)
    common = (probe, ladder, task.theta, task.base_embeddings, task.jac, task.threshold, list(task.refit_seeds))
    measure = "all" if task.deterministic else "key"
    refits = RefitLog()
    limit = effect_limit(*common, effect_space=effect_space, measure=measure, refits=refits, fine_jac=task.fine_jac)
    limit["threshold"] = task.threshold.at()
    if task.threshold_low is not None and task.threshold_low != task.threshold:
        # The same rungs read at the range's lower end: the limit with every run refined lies
        # between. The refits both readings measure in the same order are measured once.
        low = effect_limit(*common[:5], task.threshold_low, *common[6:], effect_space=effect_space, measure=measure,
                           refits=refits, fine_jac=task.fine_jac)  # fmt: skip
        limit["at_lower_scale"] = {
            "detectable_from": low["detectable_from"], "reason": low["reason"], "threshold": task.threshold_low.at(),
        }  # fmt: skip
    limit["reveal"] = reveal_by_fixing(*common, limit, effect_space)
    return limit, ladder


def detection_limits(
    inputs: LimitInputs, config: LimitConfig, *, log: Log | None = None, pooled: ProbeFactory | None = None
) -> dict[str, Any]:
    """Every candidate's detection limit at θ̂, and what would lower it.

    ``pooled``: the Jacobian and every effect's ladder run at once, each in a thread whose
    clips go to the workers (the limits are the same: every clip's seed is its own); what
    fails there runs here after. ``None``: one after another here.

    Returns:
        ``effects`` (name → :func:`~physinfer.discrepancy.limit_rule.effect_limit`'s result with
        ``threshold`` — the rule's ``τ`` for a model leaving ``S`` — and ``reveal``),
        ``seeds``, ``refit_seeds``, ``deterministic``, ``simulations`` (the ladder's),
        ``diagnosis_simulations``, ``share``, ``config``, ``clip_seconds``, ``wall_time_s``.
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
    keep = config.reveal  # another view's what-if re-renders the clips
    jac, jac_trajs, seconds = _shared_jacobian(probe, pooled, keep, theta, base_emb, refit_seeds, config.step, say)
    # A deterministic baseline's searches are polished with a finer step (refit.polished_start):
    # refits from that Jacobian too, or the limits promise what no search names; and its gaps
    # are the codec's distance when nothing else is, so its rungs are encoded as the target was
    # (a chaotic one's floor dwarfs the codec's: its rungs stay in memory). docs/benchmarks.md.
    fine_jac = None
    if deterministic:
        fine_jac = _shared_jacobian(probe, pooled, False, theta, base_emb, refit_seeds, POLISH_JACOBIAN_STEP, say)[0]
    thresholds = _thresholds_at(inputs, inputs.scale)
    low = _thresholds_at(inputs, inputs.scale_low) if inputs.scale_low is not None else {}
    tasks = [
        EffectTask(name, theta, base_emb, jac, thresholds[name], tuple(config.fractions), tuple(seeds),
                   tuple(refit_seeds), deterministic, low.get(name), fine_jac, deterministic and inputs.encoded)  # fmt: skip
        for name in inputs.augmented
    ]
    results = _run_ladders(probe, inputs, tasks, pooled, keep, say)
    effects = {task.name: limit for task, (limit, _) in zip(tasks, results, strict=True)}
    ladders = {task.name: ladder for task, (_, ladder) in zip(tasks, results, strict=True)}
    if config.reveal and not deterministic:
        reveal_by_setting(
            probe, inputs, config.step, thresholds, effects, ladders, theta, refit_seeds,
            jac_trajs, say, seeds,
        )  # fmt: skip
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


def _shared_jacobian(
    probe: Probe,
    pooled: ProbeFactory | None,
    keep: bool,
    theta: dict[str, float],
    base_emb: np.ndarray,
    refit_seeds: list[int],
    step: float,
    say: Log,
) -> tuple[np.ndarray, list[Any], float | None]:
    """The baseline's Jacobian at θ̂, on the workers when ``pooled`` (here if that fails);
    its simulations are counted on ``probe``.

    Returns:
        The Jacobian, its clips' trajectories (kept when ``keep``) and the clip's length in seconds.
    """
    def jacobian_with(p: Probe) -> tuple[np.ndarray, list[Any], Probe]:
        return (*jacobian(p, theta, base_emb, refit_seeds, step), p)

    found = concurrently(jacobian_with, [pooled(keep)], ["the Jacobian"], say)[0] if pooled else None
    jac, jac_trajs, jac_probe = found or jacobian_with(probe)
    if jac_probe is not probe:
        probe.simulations += jac_probe.simulations
    return jac, jac_trajs, jac_probe.clip_seconds


def _thresholds_at(inputs: LimitInputs, scale: float) -> dict[str, Threshold]:
    """The rule's threshold for each effect at the null scale ``scale``."""
    return {
        name: Threshold.of(
            scale, len(pipeline.effects[0].parameter_space), inputs.rule, inputs.candidates,
            inputs.floor_samples,
        )  # fmt: skip
        for name, pipeline in inputs.augmented.items()
    }


def _run_ladders(
    probe: Probe,
    inputs: LimitInputs,
    tasks: list[EffectTask],
    pooled: ProbeFactory | None,
    keep: bool,
    say: Log,
) -> list[tuple[dict[str, Any], Ladder]]:
    """Each task's limit record and ladder, in order; every ladder's simulations counted on ``probe``.

    The ladders run on the workers at once when ``pooled``; the rest (or one that failed
    there) run here, one after another.
    """
    def on_workers(task: EffectTask) -> tuple[dict[str, Any], Ladder, int]:
        p = pooled(keep)  # type: ignore[misc] - only called with a factory
        return (*effect_ladder(p, inputs.augmented[task.name], task), p.simulations)

    labels = [f"{task.name}'s ladder" for task in tasks]
    results = concurrently(on_workers, tasks, labels, say) if pooled else [None] * len(tasks)
    for i, task in enumerate(tasks):
        if results[i] is None:
            before = probe.simulations
            limit, ladder = effect_ladder(probe, inputs.augmented[task.name], task)
            results[i] = (limit, ladder, probe.simulations - before)
        else:
            probe.simulations += results[i][2]
        say(f"      {task.name}: " + summary_phrase(results[i][0]))
    return [(limit, ladder) for limit, ladder, _ in results]
