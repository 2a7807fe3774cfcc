"""Physical effects the flag's model can switch in: gusts, vertical shear, yaw and inclination.

Each effect rewrites the wind samples the solver reads (see
:mod:`physinfer_flag.cloth_wind`): ``term(state, params, t)`` receives the
:class:`~physinfer_flag.cloth_wind.WindState` at sample time ``t`` and returns a new one.
The baseline model blows a steady, uniform wind along the base direction; real wind is
turbulent, grows with height over the ground, and seldom blows exactly where the camera
set-up assumes, nor always horizontally. These are the four discrepancies the discrepancy workflow
(``physinfer diagnose``) can name. Every effect is off at its parameters' defaults, so a
model with an effect switched in reproduces the baseline there (the warm start).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.roles import Effect, Params
from physinfer_flag.cloth_wind import WIND_SAMPLE_DT, WindState

#: Samples of the turbulence path drawn per block; each block has its own seed, so a
#: path's prefix does not depend on how long a simulation asked for.
_GUST_BLOCK = 1024
#: Salt that keeps the gusts' random stream apart from the initial-shape perturbation's.
_GUST_SALT = 0x6057


def unit_ou_path(seed: int, timescale: float, n: int, dt: float = WIND_SAMPLE_DT) -> np.ndarray:
    """A stationary Ornstein–Uhlenbeck path with unit variance, sampled exactly.

    ``x[k+1] = a x[k] + sqrt(1 - a²) ξ[k]`` with ``a = exp(-dt / timescale)`` is the exact
    discretisation of ``dx = -x/τ dt + sqrt(2/τ) dW``; ``x[0]`` is drawn from the
    stationary law, so the fluctuation has no start-up transient.

    Args:
        seed: Seed of the path (the simulation's seed).
        timescale: Correlation time ``τ`` in seconds.
        n: Number of samples.
        dt: Sample spacing in seconds.

    Returns:
        ``(n,)`` float64 path, mean 0, variance 1, autocorrelation ``exp(-|Δt|/τ)``.
    """
    blocks = -(-n // _GUST_BLOCK)
    noise = np.concatenate(
        [
            np.random.default_rng(np.random.SeedSequence([int(seed), _GUST_SALT, b])).standard_normal(_GUST_BLOCK)
            for b in range(blocks)
        ]
    )[:n]
    a = math.exp(-dt / timescale)
    b = math.sqrt(1.0 - a * a)
    out = np.empty(n, dtype=np.float64)
    x = noise[0]
    out[0] = x
    for k in range(1, n):
        x = a * x + b * noise[k]
        out[k] = x
    return out


class WindGusts(Effect):
    """Turbulent gusts: the wind speed fluctuates as an Ornstein–Uhlenbeck process.

    ``speed(t) = max(0, U · (1 + I · x(t)))`` where ``x`` is a unit-variance OU process
    with correlation time ``τ`` seeded from the simulation's seed, ``U`` the base speed
    and ``I`` the turbulence intensity (σ_u / U; 0.05–0.2 over open land, up to 0.3–0.4
    in built-up areas). The path is cached per (seed, τ), since the solver asks for every
    sample of one simulation in turn.
    """

    name = "wind_gusts"
    description = "turbulent fluctuation of the wind speed (gusts)"
    phenomenon = "flag"
    parameter_space = ParameterSpace(
        [
            ParameterSpec(
                "gust_intensity", (0.0, 0.5), "", "linear",
                "turbulence intensity: standard deviation of the speed over its mean", default=0.0,
            ),
            ParameterSpec(
                "gust_timescale", (0.2, 5.0), "s", "log",
                "correlation time of the speed fluctuations", default=1.0,
            ),
        ]
    )

    def __init__(self) -> None:
        self._key: tuple[int, float] | None = None
        self._path = np.zeros(0)

    def fluctuation(self, seed: int, timescale: float, t: float) -> float:
        """The unit OU fluctuation ``x(t)`` of this seed and time scale (linear between samples)."""
        s = max(t, 0.0) / WIND_SAMPLE_DT
        k = int(s)
        needed = k + 2
        if self._key != (seed, timescale) or len(self._path) < needed:
            length = max(needed, 2 * len(self._path) if self._key == (seed, timescale) else 0, 512)
            self._path = unit_ou_path(seed, timescale, length)
            self._key = (seed, timescale)
        w = s - k
        return float((1.0 - w) * self._path[k] + w * self._path[k + 1])

    def term(self, state: WindState, params: Params, t: float) -> WindState:
        """The gusty speed at ``t`` (yaw and shear untouched)."""
        intensity = float(params["gust_intensity"])
        if intensity == 0.0:
            return state
        x = self.fluctuation(state.seed, float(params["gust_timescale"]), t)
        return replace(state, speed=max(0.0, state.speed * (1.0 + intensity * x)))


class WindShear(Effect):
    """Vertical wind shear: the speed follows a power law in height, ``U (z / z_ref)^α``.

    ``z_ref`` is the flag's mid-height, so the base wind speed keeps its meaning (the
    speed at the middle of the flag). ``α`` ≈ 0.1 over open water, 1/7 over open land,
    0.2–0.4 over suburbs and towns.
    """

    name = "wind_shear"
    description = "vertical wind shear: wind speed rising with height (power law)"
    phenomenon = "flag"
    parameter_space = ParameterSpace(
        [
            ParameterSpec(
                "shear_exponent", (0.0, 0.6), "", "linear",
                "power-law exponent of the speed against height", default=0.0,
            )
        ]
    )

    def term(self, state: WindState, params: Params, t: float) -> WindState:
        """The same wind with the shear exponent set."""
        return replace(state, shear_exponent=float(params["shear_exponent"]))


class WindYaw(Effect):
    """A wind direction offset: the wind blows at ``yaw`` from the assumed direction.

    The baseline assumes the wind along the flag's base direction (set up relative to the
    camera); a yawed wind turns the flag about the pole, towards or away from the camera.
    Off at 0; the range is symmetric because both signs are physical.
    """

    name = "wind_yaw"
    description = "wind direction offset (yaw) from the assumed direction"
    phenomenon = "flag"
    parameter_space = ParameterSpace(
        [
            ParameterSpec(
                "wind_yaw_deg", (-60.0, 60.0), "deg", "linear",
                "offset of the wind direction, counter-clockwise seen from above", default=0.0,
            )
        ]
    )

    def term(self, state: WindState, params: Params, t: float) -> WindState:
        """The same wind turned by the yaw offset (added to any yaw already set)."""
        return replace(state, yaw=state.yaw + math.radians(float(params["wind_yaw_deg"])))


class WindInclination(Effect):
    """An inclined wind: the air flows at ``inclination`` above the horizontal.

    Wind meeting a slope, a roof edge or a rising thermal is lifted (an updraft); behind
    an obstacle it is pushed down (a downdraft). Over hills and around buildings the
    mean flow is inclined by 5–20°, so a flag lifts or droops more than a horizontal wind
    of the same speed would make it. ``speed`` stays the speed along the inclined
    direction. Off at 0; both signs are physical.
    """

    name = "wind_inclination"
    description = "vertical inclination of the wind (updraft or downdraft)"
    phenomenon = "flag"
    parameter_space = ParameterSpace(
        [
            ParameterSpec(
                "wind_inclination_deg", (-30.0, 30.0), "deg", "linear",
                "angle of the wind above the horizontal (positive: updraft)", default=0.0,
            )
        ]
    )

    def term(self, state: WindState, params: Params, t: float) -> WindState:
        """The same wind inclined by the angle (added to any inclination already set)."""
        return replace(state, inclination=state.inclination + math.radians(float(params["wind_inclination_deg"])))
