"""Ridge starts: where an effect's model should begin its search, found from the video.

An augmented model is warm-started at the baseline's best θ with the effect off. When the
effect trades off with a base parameter — drag and restitution both take height off a
ball's bounces, drag and damping both shorten a swing — the baseline's fit sits at one end of
a ridge of near-equal distances, and the effect's true strength may lie far along it, with
the base parameters moved to make up for the effect. A budget-limited search started at the
baseline fit then keeps to the baseline's basin: on a bouncing ball with drag (restitution
0.8, drag 0.8 1/m) the drag model's 20 trials ended at drag 0 with the baseline's gap.

So before the effects are refined, each effect is switched on at a few strengths along its
path (the detection ladder's path, :func:`physinfer.discrepancy.ladder.strength_path`, and
for a signed effect — an interior *off* such as a yaw of 0° — both directions) at θ̂, and at
each strength the base parameters are refit to the **target** (not to the baseline): a
Gauss–Newton step on a forward-difference Jacobian of the baseline's embedding at θ̂ (shared
by every effect), a line search along it and Gauss–Newton polish on the Jacobian updated by
Broyden's rule, continued from one strength to the next. Each strength's refit is a point
on the ridge where the video points; the effect's search then starts at the best of them
or at θ̂ (whichever is closer to the target) and has the others as its first trials, so
that the optimizer's model of the distance sees the ridge from the start
(:class:`physinfer.discrepancy.warmstart.WarmStartOptimizer`, ``extra``). The budget is the
same: the starts replace some of the optimizer's own initial draws (Ax's Sobol points).

Written to ``ridge.json`` in the diagnosis folder (keyed by θ̂, the effects and the seeds) by
the main process, and read there by every effect stage wherever it runs, so a resumed or
parallel diagnosis starts each search from the same points.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.discrepancy.candidates import augmented_pipeline
from physinfer.discrepancy.clip_jobs import pooled_probes
from physinfer.discrepancy.ladder import Probe, strength_path, values_at
from physinfer.discrepancy.refit import (
    MULTIPLIERS,
    POLISH,
    RefitState,
    distance_to,
    jacobian,
    refit_to_target,
)
from physinfer.discrepancy.starts import RIDGE_FILE
from physinfer.evaluation import fixed_by_user, noise_seeds
from physinfer.io import atomic_write_json, read_keyed_json
from physinfer.parameters import ParameterSpace

if TYPE_CHECKING:
    from physinfer.discrepancy.parallel import WorkerPool
    from physinfer.discrepancy.settings import DiagnoseSettings
    from physinfer.evaluation import Pipeline

Log = Callable[[str], None]

#: Strengths along the effect's path (fractions from off to the far end of its range); a
#: signed effect, probed both ways, has two each way.
FRACTIONS = (0.125, 0.25, 0.5, 1.0)
SIGNED_FRACTIONS = (0.5, 1.0)
#: Rounds that halve the bracket of strengths around the closest point found (a weak
#: effect's ridge point lies between θ̂ and the first rung: on the ball a drag of 0.1 1/m
#: against rungs from 0.19), for a deterministic phenomenon only: a chaotic one's single
#: clips are too noisy to tell neighbouring strengths apart, and its clips cost more.
REFINE_ROUNDS = 2
#: Jacobian step in normalised units (the detection ladder's).
JACOBIAN_STEP = 0.4


def effect_paths(space: ParameterSpace) -> list[tuple[dict[str, tuple[float, float]], dict[str, float]]]:
    """The paths a ridge probe follows: the ladder's, and for a signed effect (a moved
    parameter whose *off* lies inside its range) the mirrored one too."""
    moved, held = strength_path(space)
    paths = [(moved, held)]
    if any(abs(abs(off) - 1.0) > 1e-9 for off, _ in moved.values()):
        paths.append(({n: (off, -on) for n, (off, on) in moved.items()}, held))
    return paths


def probe_seeds(seed: int, n: int) -> list[int]:
    """Seeds of the ridge probe, apart from the trials', the gaps' and the ladder's."""
    return noise_seeds(seed + 13, n, salt=0x21D6E)


def _probe_path(
    probe: Probe,
    model: Pipeline,
    space: ParameterSpace,
    effect_space: ParameterSpace,
    path: tuple[dict[str, tuple[float, float]], dict[str, float]],
    fractions: Sequence[float],
    rounds: int,
    goal: np.ndarray,
    state: RefitState,
    start: tuple[np.ndarray, float],
    seeds: Sequence[int],
    keep: np.ndarray,
) -> list[dict[str, Any]]:
    """The refit at each of ``fractions`` along one path, then ``rounds`` halvings of the
    bracket around the closest point; every point's record (θ, distance, strength, direction)."""
    moved, held = path
    u0, d0 = start
    found = {0.0: (u0, d0)}  # fraction → the refit's best (normalised base θ, distance)
    points: list[dict[str, Any]] = []

    def at(fraction: float) -> None:
        values = values_at(effect_space, moved, held, fraction)
        visited = refit_to_target(probe, model, space, values, goal, state, u0, seeds, keep)
        u, d = min(visited, key=lambda v: v[1])
        found[fraction] = (u, d)
        points.append({"params": {**space.from_unit(u), **values}, "distance": d, "fraction": fraction,
                       "direction": {n: on for n, (_, on) in moved.items()}})  # fmt: skip

    for fraction in fractions:
        at(fraction)
    for _ in range(rounds):
        known = sorted(found)
        i = min(range(len(known)), key=lambda j: found[known[j]][1])
        for j in (i - 1, i + 1):
            if 0 <= j < len(known):
                state.u = found[known[i]][0]  # continue from the closest point's refit
                at(0.5 * (known[i] + known[j]))
    return points


def _probe_all(
    settings: DiagnoseSettings,
    base: Pipeline,
    theta: dict[str, float],
    target_embedding: np.ndarray,
    rounds: int,
    effect_objs: Mapping[str, Any],
    seeds: list[int],
    probe: Probe,
    say: Log,
) -> dict[str, dict[str, Any]]:
    """Every effect's ridge points with ``probe`` (see :func:`ridge_starts`)."""
    space = base.simulator.parameter_space
    goal = np.asarray(target_embedding, dtype=np.float64)
    emb0, _ = probe.clips(base, [theta] * len(seeds), seeds)
    jac, _ = jacobian(probe, theta, emb0, seeds, JACOBIAN_STEP)
    d0 = distance_to(goal, emb0)
    u0 = space.to_unit(theta)
    fixed = fixed_by_user(base, settings.fixed)
    keep = np.array([name not in fixed for name in space.names])
    result: dict[str, dict[str, Any]] = {}
    for name, effect in effect_objs.items():
        model = augmented_pipeline(base, [effect], settings.duration_s, fixed)
        points: list[dict[str, Any]] = []
        paths = effect_paths(effect.parameter_space)
        for moved, held in paths:
            fractions = FRACTIONS if len(paths) == 1 else SIGNED_FRACTIONS
            points += _probe_path(probe, model, space, effect.parameter_space, (moved, held), fractions, rounds,
                                  goal, RefitState(jac.copy(), u0.copy(), emb0), (u0, d0), seeds, keep)  # fmt: skip
        points.sort(key=lambda p: p["distance"])
        result[name] = {"starts": points, "baseline_distance": d0}
        best = points[0] if points else None
        if best is not None:
            shown = ", ".join(f"{k} {v:.3g}" for k, v in best["params"].items())
            say(f"      {name}: closest ridge point {shown} (distance {best['distance']:.4g}; θ̂ {d0:.4g})")
    return result


def ridge_starts(
    settings: DiagnoseSettings,
    base: Pipeline,
    render_params: Mapping[str, Any],
    theta: Mapping[str, float],
    target_embedding: np.ndarray,
    floor: float,
    effect_objs: Mapping[str, Any],
    say: Log,
    pool: WorkerPool | None = None,
) -> dict[str, dict[str, Any]]:
    """Each effect's ridge probe at θ̂ (cached in ``ridge.json``): effect name → ``starts``
    (physical θ of the augmented model, best first, each with its ``distance`` to the
    target) and ``baseline_distance`` (θ̂'s, under the same seeds).

    Args:
        settings: The diagnosis settings (``out``, ``seed``, ``fixed``, ``duration_s``).
        base: The baseline model.
        render_params: The target's ζ.
        theta: θ̂, the baseline's best fit.
        target_embedding: The target's embedding.
        floor: The noise floor at θ̂ (every point is one clip under one seed, deterministic
            or not: a start needs no error bar, the search measures it again; where it is 0
            the strengths are refined around the closest point, :data:`REFINE_ROUNDS`).
        effect_objs: The effects to probe.
        say: Progress lines.
        pool: The diagnosis' workers (each clip a job when it has two or more).
    """
    if not effect_objs:
        return {}
    space = base.simulator.parameter_space
    theta = {k: float(v) for k, v in space.complete(theta).items()}
    seeds = probe_seeds(settings.seed, 1)
    rounds = REFINE_ROUNDS if floor <= 0 else 0
    key = {"theta": theta, "effects": sorted(effect_objs), "seeds": seeds, "fractions": list(FRACTIONS),
           "signed_fractions": list(SIGNED_FRACTIONS), "multipliers": list(MULTIPLIERS), "polish": POLISH,
           "rounds": rounds}  # fmt: skip
    path = settings.out / RIDGE_FILE
    if (stored := read_keyed_json(path, key)) is not None:
        return stored["effects"]
    say(f"      ridge starts: {len(effect_objs)} effect(s) switched on along their range, the base refit to the video")
    pooled = pooled_probes(pool, base, render_params)
    probe: Probe = Probe(base, render_params)
    try:
        result = _probe_all(settings, base, theta, target_embedding, rounds, effect_objs, seeds, pooled(False)
                            if pooled is not None else probe, say)  # fmt: skip
    except Exception as exc:  # noqa: BLE001 - a worker that cannot run a clip: the same clips here
        if pooled is None:
            raise
        say(f"      the ridge probe failed on a worker ({type(exc).__name__}: {exc}); running it here")
        result = _probe_all(settings, base, theta, target_embedding, rounds, effect_objs, seeds, probe, say)
    atomic_write_json(path, {"key": key, "effects": result, "floor": floor})
    return json.loads(path.read_text())["effects"]
