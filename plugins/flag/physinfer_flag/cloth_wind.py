"""The wind the flag feels: a base speed and direction, sampled over time, evaluated per face.

The solver never hard-codes a uniform wind. It reads a :class:`WindSchedule` — the wind
speed at a reference height, a yaw offset of its direction, a vertical shear exponent and
an inclination above the horizontal, sampled every ``dt`` seconds — and evaluates, at
every substep and for every face, :func:`wind_at_time` (time → speed, yaw, shear,
inclination) and :func:`shear_factor` (height → speed factor). A constant wind is the
schedule of one repeated sample. Effects switch in gusts (time-varying speed), shear
(speed rising with height), yaw (direction offset) and inclination (an updraft or
downdraft) by rewriting the samples: :func:`sample_wind` calls each effect's
``term(state, params, t)`` with a :class:`WindState` at every sample time and keeps the
state it returns, so no effect needs to touch the compiled solver.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from physinfer.roles import Effect
from physinfer_flag import cloth_numba
from physinfer_flag.cloth_numba import FASTMATH, cache_depends_on  # first: numba's cache directory

#: Default spacing of wind samples in seconds (fine enough for gusts of a few Hz).
WIND_SAMPLE_DT = 0.01
#: Heights below this are treated as this in the shear law (no zero or negative powers).
MIN_SHEAR_HEIGHT = 0.05
#: Columns of a wind table: speed, yaw, shear exponent, inclination.
WIND_COLUMNS = 4


@dataclass(frozen=True)
class WindState:
    """The wind at one instant, as an effect receives and returns it.

    Attributes:
        speed: Wind speed in m/s at ``z_ref``.
        yaw: Offset of the wind direction from the base direction, radians,
            counter-clockwise seen from above.
        shear_exponent: Power-law exponent α; the speed at height ``z`` is
            ``speed · (z / z_ref)^α`` (0: uniform).
        z_ref: Reference height in metres above the ground (z = 0) where ``speed`` holds.
        seed: The simulation's seed, so that random effects are deterministic per seed.
        inclination: Angle of the wind above the horizontal, radians (positive: an
            updraft); ``speed`` is the speed along the inclined direction.
    """

    speed: float
    yaw: float = 0.0
    shear_exponent: float = 0.0
    z_ref: float = 1.0
    seed: int = 0
    inclination: float = 0.0


@dataclass(frozen=True)
class WindSchedule:
    """Wind samples over a simulation, in the layout the compiled solver reads.

    Attributes:
        dt: Sample spacing in seconds.
        table: ``(K, 4)`` float64 samples ``[speed (m/s), yaw (rad), shear exponent,
            inclination (rad)]`` at times ``k * dt``; held constant after the last sample.
        z_ref: Reference height of the speed in metres.
        direction: Base direction in radians from +x, counter-clockwise seen from above.
    """

    dt: float
    table: np.ndarray
    z_ref: float
    direction: float

    def __post_init__(self) -> None:
        # The compiled solver reads WIND_COLUMNS columns without bounds checks: a short
        # table would be read past its end, so it is refused here.
        table = np.asarray(self.table)
        if table.ndim != 2 or table.shape[0] < 1 or table.shape[1] != WIND_COLUMNS:
            raise ValueError(
                f"a wind table must be (K, {WIND_COLUMNS}) [speed, yaw, shear exponent, inclination] "
                f"with K >= 1, got shape {table.shape}"
            )

    def scalars(self) -> np.ndarray:
        """``[dt, z_ref, direction]`` as float64, the solver's scalar wind inputs."""
        return np.array([self.dt, self.z_ref, self.direction], dtype=np.float64)


def sample_wind(
    base: WindState,
    *,
    duration: float,
    direction: float = 0.0,
    effects: Sequence[Effect] = (),
    params: Mapping[str, float] | None = None,
    dt: float = WIND_SAMPLE_DT,
) -> WindSchedule:
    """Sample the wind over ``[0, duration]``, passing every sample through the effects.

    Args:
        base: The wind without effects (speed from θ, no yaw, no shear).
        duration: Simulated time in seconds the schedule must cover.
        direction: Base direction in radians from +x.
        effects: Effects whose ``term(state: WindState, params, t) -> WindState`` rewrite
            the wind; applied in order. None: a single constant sample.
        params: The full parameter set (base plus effect parameters).
        dt: Sample spacing in seconds.

    Returns:
        The schedule; ``z_ref`` is taken from the base state.
    """
    if not effects:
        table = np.array([_row(base)], dtype=np.float64)
        return WindSchedule(dt=dt, table=table, z_ref=base.z_ref, direction=direction)
    params = dict(params or {})
    n = int(math.ceil(duration / dt)) + 2
    table = np.empty((n, WIND_COLUMNS), dtype=np.float64)
    for k in range(n):
        state = replace(base)
        for effect in effects:
            state = effect.term(state, params, k * dt)
        table[k] = _row(state)
    if (table == np.array(_row(base))).all():  # effects off: the baseline's one sample, bit for bit
        table = table[:1]  # (interpolating equal samples rounds; the chaos would amplify it)
    return WindSchedule(dt=dt, table=table, z_ref=base.z_ref, direction=direction)


def _row(state: WindState) -> tuple[float, float, float, float]:  # WIND_COLUMNS values
    """One sample of the solver's wind table."""
    return (state.speed, state.yaw, state.shear_exponent, state.inclination)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def wind_at_time(table: np.ndarray, sample_dt: float, t: float) -> tuple[float, float, float, float]:
    """Speed, yaw, shear exponent and inclination at time ``t``, interpolating ``table`` ``(K, 4)``."""
    n = table.shape[0]
    s = t / sample_dt
    if n == 1 or s <= 0.0:
        return table[0, 0], table[0, 1], table[0, 2], table[0, 3]
    k = int(s)
    if k >= n - 1:
        return table[n - 1, 0], table[n - 1, 1], table[n - 1, 2], table[n - 1, 3]
    w = s - k
    return (
        (1.0 - w) * table[k, 0] + w * table[k + 1, 0],
        (1.0 - w) * table[k, 1] + w * table[k + 1, 1],
        (1.0 - w) * table[k, 2] + w * table[k + 1, 2],
        (1.0 - w) * table[k, 3] + w * table[k + 1, 3],
    )


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def shear_factor(z: float, exponent: float, z_ref: float) -> float:
    """Speed factor ``(z / z_ref)^exponent`` of a power-law profile (1 when the exponent is 0)."""
    if exponent == 0.0:
        return 1.0
    return (max(z, MIN_SHEAR_HEIGHT) / z_ref) ** exponent


cache_depends_on((wind_at_time, shear_factor), cloth_numba)
