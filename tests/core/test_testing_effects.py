"""physinfer.testing.check_effect and embedding_sensitivity, on the pendulum's real simulator.

The proof that the effect contract can fail: effects that are broken the ways plugin
authors break them (a misspelled factory, not off at the defaults, a term the simulator
never applies, a parameter that clashes) are registered in a fresh registry and refused.
"""

from __future__ import annotations

import pytest

from physinfer import ParameterSpace, ParameterSpec
from physinfer.plugins import load_registry
from physinfer.testing import check_effect, check_phenomenon, embedding_sensitivity


@pytest.fixture
def registry():
    return load_registry()[0]


@pytest.fixture
def pendulum(registry):
    return registry.phenomenon("pendulum_lab")


def _register(registry, name, factory):
    registry.scoped("tests").add_effect(name, factory, phenomenon="pendulum_lab")


def _drag_variant(name, spec=None, *, term=None):
    """A subclass of the pendulum's drag registered under ``name`` (one thing changed)."""
    from pendulum_example.physics import QuadraticDrag

    attrs = {"name": name}
    if spec is not None:
        attrs["parameter_space"] = ParameterSpace([spec])
    if term is not None:
        attrs["term"] = term
    return type(f"Drag_{name}", (QuadraticDrag,), attrs)


def test_the_pendulums_drag_keeps_the_contract(registry, pendulum):
    effect = check_effect(pendulum, "quadratic_drag", registry=registry)
    assert effect.parameter_space.names == ["drag_quadratic"]


def test_a_misspelled_factory_string_is_refused(registry, pendulum):
    _register(registry, "typo_drag", "pendulum_example.physics:QuadratcDrag")
    with pytest.raises(AssertionError, match=r"'typo_drag'.*does not resolve.*QuadratcDrag"):
        check_effect(pendulum, "typo_drag", registry=registry)
    _register(registry, "typo_module", "pendulum_example.physcs:QuadraticDrag")
    with pytest.raises(AssertionError, match="does not resolve"):
        check_effect(pendulum, "typo_module", registry=registry)


def test_an_effect_not_off_at_its_defaults_is_refused(registry, pendulum):
    # No declared default: the centre of the range (c = 1) switches the drag on.
    on_by_default = ParameterSpec("drag_on", (0.0, 2.0), "1/m")

    def term(self, state, params, t):
        return -params["drag_on"] * state[2] * abs(state[1]) * state[1]

    _register(registry, "leaky_drag", _drag_variant("leaky_drag", on_by_default, term=term))
    with pytest.raises(
        AssertionError, match=r"'leaky_drag' is not off at its defaults \(drag_on=1\)"
    ):
        check_effect(pendulum, "leaky_drag", registry=registry)


def test_an_effect_that_changes_nothing_or_clashes_is_refused(registry, pendulum):
    _register(registry, "inert", _drag_variant("inert", term=lambda self, state, params, t: 0.0))
    with pytest.raises(AssertionError, match="changes nothing at drag_quadratic=2"):
        check_effect(pendulum, "inert", registry=registry)
    clash = ParameterSpec("damping", (0.0, 1.0), default=0.0)
    _register(registry, "clashing", _drag_variant("clashing", clash))
    with pytest.raises(AssertionError, match="damping clash with 'pendulum_lab'"):
        check_effect(pendulum, "clashing", registry=registry)
    _register(registry, "misnamed", _drag_variant("quadratic_drag"))
    with pytest.raises(
        AssertionError, match="registered as 'misnamed' calls itself 'quadratic_drag'"
    ):
        check_effect(pendulum, "misnamed", registry=registry)


def test_check_phenomenon_checks_every_registered_effect(registry, pendulum):
    """A typo in an effect's factory string used to pass check_phenomenon."""
    _register(registry, "typo_drag", "pendulum_example.physics:QuadratcDrag")
    embedder = registry.embedder(pendulum.default_embedder)
    with pytest.raises(AssertionError, match="'typo_drag'.*does not resolve"):
        check_phenomenon(pendulum, embedder, registry=registry)


def test_embedding_sensitivity_tells_the_pendulums_parameters_apart(registry, pendulum):
    embedder = registry.embedder(pendulum.default_embedder)
    sensitivity = embedding_sensitivity(pendulum, embedder, seeds=(0,), render_params={"size": 64})
    assert set(sensitivity) == {"length", "damping", "amplitude"}
    for name, row in sensitivity.items():
        assert row["noise"] == 0.0 and row["distance"] > 0 and row["ratio"] == float("inf"), name
    # A smaller move shows less: the measure follows the parameter.
    small = embedding_sensitivity(
        pendulum, embedder, step=0.05, seeds=(0,), render_params={"size": 64}
    )
    assert small["length"]["distance"] < sensitivity["length"]["distance"]
