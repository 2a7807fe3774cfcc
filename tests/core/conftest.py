"""Fixtures of the core tests that instrument the pendulum example's simulator."""

import pytest

#: Pendulums longer than this (m) fail under ``long_pendulums_blow_up``.
LONG = 1.3


@pytest.fixture
def pendulum_batch_sizes(monkeypatch):
    """Record the size of every ``PendulumSimulator.simulate_batch`` call (a list, in call order)."""
    from pendulum_example import physics

    sizes = []
    real = physics.PendulumSimulator.simulate_batch

    def counting(self, params, *, seeds):
        sizes.append(len(params))
        return real(self, params, seeds=seeds)

    monkeypatch.setattr(physics.PendulumSimulator, "simulate_batch", counting)
    return sizes


@pytest.fixture
def long_pendulums_blow_up(monkeypatch):
    """Make every pendulum longer than 1.3 m fail with ``SimulationFailed("blew up (test)")``.

    The embedded target (1.25 m) stays simulable, whatever test built it first.
    """
    from pendulum_example import physics

    real = physics.PendulumSimulator.simulate

    def flaky(self, params, *, seed=0):
        if params["length"] > LONG:
            raise physics.SimulationFailed("blew up (test)")
        return real(self, params, seed=seed)

    monkeypatch.setattr(physics.PendulumSimulator, "simulate", flaky)
