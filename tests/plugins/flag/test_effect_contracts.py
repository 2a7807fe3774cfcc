"""The flag's four registered effects keep the effect contract (physinfer.testing.check_effect).

Short recordings (``duration_s``) keep it fast: the warm-up dominates a flag simulation.
The chaotic flag amplifies any rounding, so "off at the defaults" must hold bit for bit.
"""

from __future__ import annotations

import pytest

from physinfer.plugins import load_registry
from physinfer.testing import check_effect


@pytest.fixture(scope="module")
def flag():
    registry, _ = load_registry()
    phenomenon = registry.phenomenon("flag")
    theta = {**phenomenon.parameter_space.defaults(), "wind_speed": 5.3}
    baseline = phenomenon.make_simulator((), duration_s=0.2).simulate(theta, seed=0)
    return registry, phenomenon, theta, baseline


def test_every_flag_effect_is_registered_off_at_its_defaults_and_acts(flag):
    registry, phenomenon, theta, baseline = flag
    names = registry.effects_of("flag")
    assert names == ["wind_gusts", "wind_inclination", "wind_shear", "wind_yaw"]
    for name in names:
        check_effect(
            phenomenon, name, registry=registry, params=theta, duration_s=0.2, baseline=baseline
        )
