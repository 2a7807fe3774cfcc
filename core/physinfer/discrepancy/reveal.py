"""What would reveal an effect: the detection limit under ``--fix``, another camera view, a longer clip.

Part of :mod:`physinfer.discrepancy.limits` (the method is described there). Holding a base
parameter at a known value (``--fix``) removes its column from the refit — free, from the
same simulations (:func:`reveal_by_fixing`). Another camera view (the target's
``camera_elevation_deg`` / ``camera_azimuth_deg``, where its ζ has them) re-renders the
same trajectories; a longer clip (``--duration`` twice the current one, the embedder reading
twice the frames) re-simulates the ladder (:func:`reveal_by_setting`). For those two the null
scale is not known (no self-consistency runs there): it is taken as the same multiple of the
noise floor as here, so they are measured only for a chaotic phenomenon, and only when asked.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from physinfer.discrepancy.ladder import Ladder, LimitInputs, Probe, moved_values, pairwise_median
from physinfer.discrepancy.limit_rule import Threshold, effect_limit
from physinfer.discrepancy.refit import jacobian_from
from physinfer.errors import UserInputError
from physinfer.parameters import ParameterSpace

Log = Callable[[str], None]

#: ζ keys of a camera view and the values a "what would reveal it" check tries.
VIEW_CHANGES: dict[str, tuple[float, ...]] = {
    "camera_elevation_deg": (30.0,),
    "camera_azimuth_deg": (15.0,),
}


def _improvement(before: dict[str, Any], after: dict[str, Any]) -> float | None:
    """How many times lower the limit is after a change (``inf``: it becomes detectable)."""
    if after["fraction"] is None:
        return None
    if before["fraction"] is None or after["fraction"] <= 0:
        return math.inf
    return before["fraction"] / after["fraction"]


def reveal_by_fixing(
    probe: Probe,
    ladder: Ladder,
    theta: Mapping[str, float],
    base_emb: np.ndarray,
    jac: np.ndarray,
    threshold: Threshold,
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
    predicted = functools.partial(
        effect_limit, probe, ladder, theta, base_emb, jac, threshold, seeds,
        effect_space=effect_space, measure="none",
    )  # fmt: skip
    now = predicted()
    for d, name in enumerate(space.names):
        fixed = predicted(keep=[i != d for i in range(len(space))])
        factor = _improvement(now, fixed)
        if factor is None or factor <= 1.05:
            continue
        detectable = fixed["detectable_from"]
        if limit["fraction"] is None:
            factor = math.inf  # not detectable as measured; detectable as predicted with P held
        elif math.isfinite(factor):
            detectable = moved_values(effect_space, limit["fraction"] / factor)
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


@dataclass(frozen=True)
class _SettingCheck:
    """What every "another setting" what-if of :func:`reveal_by_setting` compares against.

    Attributes:
        probe: The diagnosis' probe (the Jacobian's and the ladders' clips).
        thresholds: The rule's threshold per effect, at the current setting.
        effects: Each effect's limit record; a what-if that lowers it is added to its ``reveal``.
        ladders: Each effect's rungs at the current setting.
        augmented: Each effect's augmented pipeline.
        theta: θ̂.
        seeds: The baseline's seeds (the Jacobian's).
        wanted: The effects not yet detectable at half range.
        here: ``(n, D_e)`` θ̂'s re-simulations' embeddings at the current setting.
        jac_here: The Jacobian at θ̂ from them.
    """

    probe: Probe
    thresholds: Mapping[str, Threshold]
    effects: dict[str, Any]
    ladders: Mapping[str, Ladder]
    augmented: Mapping[str, Any]
    theta: Mapping[str, float]
    seeds: Sequence[int]
    wanted: list[str]
    here: np.ndarray
    jac_here: np.ndarray


def reveal_by_setting(
    probe: Probe,
    inputs: LimitInputs,
    step: float,
    thresholds: Mapping[str, Threshold],
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
    signs = [1.0 if u + step <= 1.0 else -1.0 for u in space.to_unit(space.complete(theta))]
    base_trajs = probe.trajectories(inputs.base.simulator, [theta] * len(seeds), seeds)
    here = probe.embed(base_trajs)
    jac_here = jacobian_from(probe.embed(jac_trajs), here, signs, len(seeds), step)
    check = _SettingCheck(probe, thresholds, effects, ladders, inputs.augmented, theta, seeds, wanted, here, jac_here)
    for key, value in _view_changes(inputs.render_params):
        zeta = {**inputs.render_params, key: value}
        try:
            emb_base = probe.embed(base_trajs, zeta)
        except Exception as exc:  # noqa: BLE001 - a view the renderer refuses is skipped, said once
            say(f"      (view {key}={value:g} skipped: {exc})")
            continue
        jac_new = jacobian_from(probe.embed(jac_trajs, zeta), emb_base, signs, len(seeds), step)
        rungs = {
            name: [probe.embed(t, zeta) for t in ladders[name].trajectories] for name in wanted
        }
        _reveal_in(check, emb_base, jac_new, rungs, f"--render-set {key}={value:g}")
    seconds = next((t.vertices.shape[0] / t.fps for t in base_trajs if t is not None), None)
    if inputs.make_longer is not None and seconds is not None:
        try:
            longer = _longer_clip(
                inputs, seconds, step, signs, ladders, wanted, theta, seeds, rung_seeds
            )
        except UserInputError as exc:
            say(f"      (a longer clip is not tried: {exc})")
            return
        probe.simulations += longer[3]
        _reveal_in(check, *longer[:3], "a clip twice as long (--duration, --embedder-frames)")


def _view_changes(render_params: Mapping[str, Any]) -> list[tuple[str, float]]:
    """The camera views to try: each ζ key of :data:`VIEW_CHANGES` the target's ζ has, at another value."""
    return [
        (key, value)
        for key, values in VIEW_CHANGES.items()
        if key in render_params
        for value in values
        if float(render_params[key]) != value
    ]


def _reveal_in(
    check: _SettingCheck,
    emb_base: np.ndarray,
    jac_new: np.ndarray,
    rung_emb: Mapping[str, list[np.ndarray]],
    change: str,
) -> None:
    """Add ``change`` to the ``reveal`` of each wanted effect whose limit it lowers more than 5 %.

    Args:
        check: The current setting's numbers.
        emb_base: θ̂'s re-simulations' embeddings in the other setting.
        jac_new: The Jacobian at θ̂ there.
        rung_emb: Each wanted effect's rung embeddings there.
        change: How the user would make that setting (the what-if's ``change``).
    """
    ratio = pairwise_median(emb_base) / max(pairwise_median(check.here), 1e-300)
    for name in check.wanted:
        effect_space = check.augmented[name].effects[0].parameter_space
        ladder = check.ladders[name]
        now = effect_limit(
            check.probe, ladder, check.theta, check.here, check.jac_here, check.thresholds[name], check.seeds,
            effect_space=effect_space, measure="none",
        )  # fmt: skip
        other = Ladder(ladder.fractions, ladder.values, list(rung_emb[name]), [])
        new = effect_limit(
            check.probe, other, check.theta, emb_base, jac_new, check.thresholds[name].scaled(ratio), check.seeds,
            effect_space=effect_space, measure="none",
        )  # fmt: skip
        factor = _improvement(now, new)
        if factor is None or factor <= 1.05:
            continue
        detectable, measured_here = new["detectable_from"], check.effects[name]["fraction"]
        if measured_here is None:
            factor = math.inf
        elif math.isfinite(factor):
            detectable = moved_values(effect_space, measured_here / factor)
        check.effects[name]["reveal"].append(
            {
                "change": change,
                "kind": "setting",
                "detectable_from": detectable,
                "factor": _finite(factor),
                "measured": False,
            }
        )


def _longer_clip(
    inputs: LimitInputs,
    seconds: float,
    step: float,
    signs: Sequence[float],
    ladders: Mapping[str, Ladder],
    wanted: Sequence[str],
    theta: Mapping[str, float],
    seeds: Sequence[int],
    rung_seeds: Sequence[int],
) -> tuple[np.ndarray, np.ndarray, dict[str, list[np.ndarray]], int]:
    """θ̂'s re-simulations, the Jacobian and the ``wanted`` ladders on a clip twice as long.

    Returns:
        The base embeddings, the Jacobian, each effect's rung embeddings and the simulations
        spent. Raises :class:`UserInputError` where the phenomenon records a fixed length.
    """
    assert inputs.make_longer is not None
    base_sim, aug_sims, embedder = inputs.make_longer(seconds)
    space: ParameterSpace = inputs.base.simulator.parameter_space
    probe = Probe(inputs.base, inputs.render_params)
    emb_base = probe.embed(
        probe.trajectories(base_sim, [theta] * len(seeds), seeds), None, embedder
    )
    u0 = space.to_unit(space.complete(theta))
    jobs = []
    for d in range(len(space)):
        u = u0.copy()
        u[d] += signs[d] * step
        jobs += [space.from_unit(u)] * len(seeds)
    jac_emb = probe.embed(
        probe.trajectories(base_sim, jobs, list(seeds) * len(space)), None, embedder
    )
    jac_new = jacobian_from(jac_emb, emb_base, signs, len(seeds), step)
    rungs = {}
    n = len(rung_seeds)
    for name in wanted:
        values = ladders[name].values
        trajs = probe.trajectories(
            aug_sims[name],
            [{**theta, **v} for v in values for _ in rung_seeds],
            list(rung_seeds) * len(values),
        )
        rungs[name] = [
            probe.embed(trajs[i * n : (i + 1) * n], None, embedder) for i in range(len(values))
        ]
    return emb_base, jac_new, rungs, probe.simulations


def _finite(factor: float) -> float | None:
    """JSON has no infinity: ``None`` stands for "from not detectable to detectable"."""
    return None if math.isinf(factor) else float(factor)
