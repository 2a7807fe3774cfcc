"""The contract of an :class:`~physinfer.roles.Effect`: ``check_effect``.

An effect is a registered, optional physical term. Its promises, checked here on the
phenomenon's real simulator:

- the ``"module:attr"`` factory it was registered with resolves and builds an
  :class:`~physinfer.roles.Effect` whose ``name`` and ``phenomenon`` match the registration;
- its parameters are new names: none clashes with the phenomenon's parameters;
- the simulator built with the effect switched in (``make_simulator([effect])``) merges
  those parameters into its ``parameter_space``;
- it is *off* at its parameters' defaults: with them, the simulation equals the baseline
  model's for the same θ and seed (what the discrepancy workflow's warm start relies on);
- it does something: with its parameters away from their defaults the simulation changes.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from physinfer.parameters import ParameterSpace
from physinfer.plugins import load_registry
from physinfer.registry import Registry, accepts_keyword, resolve
from physinfer.roles import Effect, Phenomenon
from physinfer.types import Trajectory

__all__ = ["check_effect", "effect_on_values", "effects_of"]


def effects_of(phenomenon: Phenomenon, registry: Registry) -> list[str]:
    """Every effect of ``phenomenon``: those registered for it and those its record names."""
    return sorted(set(registry.effects_of(phenomenon.name)) | set(phenomenon.effects))


def effect_on_values(space: ParameterSpace) -> dict[str, float]:
    """Each parameter at the bound farthest from its default (in normalised coordinates)."""
    values = {}
    for spec in space:
        u = float(spec.to_unit(spec.default_value))
        values[spec.name] = float(spec.bounds[0] if u > 0 else spec.bounds[1])
    return values


def _build(phenomenon: Phenomenon, name: str, registry: Registry) -> Effect:
    """Resolve the registered factory and build the effect, as ``--effect NAME`` does."""
    entry = registry.entries["effects"].get(name)
    assert entry is not None, (
        f"effect {name!r} is named by the phenomenon {phenomenon.name!r} but not registered "
        "(physinfer_register_effects)"
    )
    owner = entry.extra.get("phenomenon")
    assert owner == phenomenon.name, (
        f"effect {name!r} is registered for {owner!r}, not {phenomenon.name!r}"
    )
    try:
        factory = resolve(entry.factory)
    except Exception as exc:  # noqa: BLE001 - any import failure breaks the same promise
        raise AssertionError(
            f"effect {name!r}: its factory {entry.factory!r} does not resolve ({type(exc).__name__}: {exc})"
        ) from exc
    effect = factory()
    assert isinstance(effect, Effect), f"effect {name!r}: the factory must build a physinfer.Effect"
    assert effect.name == name, f"effect registered as {name!r} calls itself {effect.name!r}"
    assert effect.phenomenon == phenomenon.name, (
        f"effect {name!r} says it belongs to {effect.phenomenon!r}, not {phenomenon.name!r}"
    )
    assert isinstance(effect.parameter_space, ParameterSpace) and len(effect.parameter_space) > 0, (
        f"effect {name!r}: parameter_space must be a non-empty ParameterSpace"
    )
    return effect


def _simulator(phenomenon: Phenomenon, effects: list[Effect], duration_s: float | None) -> Any:
    if duration_s is not None and accepts_keyword(phenomenon.make_simulator, "duration_s"):
        return phenomenon.make_simulator(effects, duration_s=duration_s)
    return phenomenon.make_simulator(effects)


def _close(a: Trajectory, b: Trajectory) -> bool:
    if a.vertices.shape != b.vertices.shape:
        return False
    scale = 1.0 + float(np.abs(a.vertices).max())
    return bool(np.allclose(a.vertices, b.vertices, rtol=0.0, atol=1e-6 * scale))


def check_effect(
    phenomenon: Phenomenon,
    name: str,
    *,
    registry: Registry | None = None,
    params: Mapping[str, float] | None = None,
    seed: int = 0,
    duration_s: float | None = None,
    baseline: Trajectory | None = None,
) -> Effect:
    """Check the contract of the effect ``name`` of ``phenomenon``; returns the built effect.

    Args:
        phenomenon: The phenomenon the effect is registered for.
        name: The effect's registered name.
        registry: Where it is registered (default: a freshly loaded registry of every
            installed plugin).
        params: The base θ the simulations run at (default: the phenomenon's defaults).
        seed: Seed of every simulation.
        duration_s: Record this many seconds when the phenomenon's ``make_simulator``
            accepts ``duration_s`` (shorter checks of expensive simulators); ``None``: its
            default length.
        baseline: The baseline model's trajectory at ``params``, ``seed`` and
            ``duration_s`` when the caller has it (saves a simulation).

    Raises:
        AssertionError: naming the broken promise (see the module's docstring).
    """
    if registry is None:
        registry, _ = load_registry()
    effect = _build(phenomenon, name, registry)
    base_space = phenomenon.parameter_space
    clash = sorted(set(effect.parameter_space.names) & set(base_space.names))
    assert not clash, (
        f"effect {name!r}: parameter(s) {', '.join(clash)} clash with {phenomenon.name!r}'s own"
    )
    theta = base_space.complete(params or {})
    if baseline is None:
        baseline = _simulator(phenomenon, [], duration_s).simulate(theta, seed=seed)
    simulator = _simulator(phenomenon, [effect], duration_s)
    missing = [
        n
        for n in (*base_space.names, *effect.parameter_space.names)
        if n not in simulator.parameter_space
    ]
    assert not missing, (
        f"effect {name!r}: the simulator with it switched in lacks {', '.join(missing)} in its parameter_space "
        "(merge the effect's space into the simulator's: ParameterSpace.merged)"
    )
    off = effect.parameter_space.defaults()
    at_default = simulator.simulate({**theta, **off}, seed=seed)
    shown = ", ".join(f"{k}={v:g}" for k, v in off.items())
    assert _close(at_default, baseline), (
        f"effect {name!r} is not off at its defaults ({shown}): the simulation differs from the baseline "
        "model's; declare each parameter's off value as its ParameterSpec default"
    )
    on = effect_on_values(effect.parameter_space)
    switched = simulator.simulate({**theta, **on}, seed=seed)
    shown = ", ".join(f"{k}={v:g}" for k, v in on.items())
    assert not _close(switched, baseline), (
        f"effect {name!r} changes nothing at {shown}: the simulator does not apply its term"
    )
    return effect
