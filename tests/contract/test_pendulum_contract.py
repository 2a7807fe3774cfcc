from physinfer.testing import check_phenomenon


def test_pendulum_satisfies_the_contracts(physinfer_registry):
    phenomenon = physinfer_registry.phenomenon("pendulum_lab")
    check_phenomenon(phenomenon, physinfer_registry.embedder(phenomenon.default_embedder))


def test_effect_switches_a_term_in(physinfer_registry):
    phenomenon = physinfer_registry.phenomenon("pendulum_lab")
    drag = physinfer_registry.effect("quadratic_drag", phenomenon="pendulum_lab")
    sim = phenomenon.make_simulator([drag])
    assert "drag_quadratic" in sim.parameter_space
    base = {"length": 1.0, "damping": 0.0, "amplitude": 40.0}
    free = sim.angles({**base, "drag_quadratic": 0.0})
    damped = sim.angles({**base, "drag_quadratic": 1.5})
    assert abs(damped[-20:]).max() < 0.8 * abs(free[-20:]).max()
