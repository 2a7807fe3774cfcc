"""The fan in front of the hanging fabric: three speed settings with seeded turbulence.

Bouman et al. excite each fabric with a fan at three strengths (W1–W3). The fan here is
a wind along +y, face-on to the fabric, whose speed at each instant is the setting's
mean speed times ``1 + g · n(t)`` (``n`` a smooth seeded turbulence of unit standard
deviation, ``g`` the gust intensity) and whose direction wobbles by a few degrees. The
result is a :class:`~physinfer_flag.cloth_wind.WindSchedule`, the flag solver's wind
input, so the compiled solver is reused unchanged. A fan's jet is narrower than the
fabric in reality; the solver's wind is uniform over the cloth (documented limitation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from physinfer.errors import UserInputError
from physinfer_flag.cloth_wind import WIND_COLUMNS, WIND_SAMPLE_DT, WindSchedule

#: Fan settings of the dataset, W1 (weakest) to W3.
FAN_LEVELS: tuple[str, ...] = ("W1", "W2", "W3")


@dataclass(frozen=True)
class FanSettings:
    """How the fan blows.

    Attributes:
        speeds: Mean wind speed at the fabric in m/s for W1, W2, W3 (increasing).
        gust_intensity: Standard deviation of the speed fluctuation relative to the mean.
        yaw_amplitude_deg: Standard deviation of the direction wobble, degrees.
        f_min: Lowest turbulence frequency in Hz.
        f_max: Highest turbulence frequency in Hz.
        n_modes: Sinusoids summed into the turbulence.
    """

    speeds: tuple[float, float, float] = (0.8, 1.6, 2.4)
    gust_intensity: float = 0.3
    yaw_amplitude_deg: float = 8.0
    f_min: float = 0.3
    f_max: float = 3.0
    n_modes: int = 8

    def validate(self) -> None:
        """Raise :class:`UserInputError` naming the first bad setting."""
        speeds = tuple(float(s) for s in self.speeds)
        if len(speeds) != len(FAN_LEVELS) or not all(0 <= s <= 15 for s in speeds):
            raise UserInputError(f"fan speeds must be three values in [0, 15] m/s, got {self.speeds}")
        if list(speeds) != sorted(speeds):
            raise UserInputError(f"fan speeds must increase from W1 to W3, got {self.speeds}")
        if not 0 <= self.gust_intensity <= 1:
            raise UserInputError(f"gust_intensity must be in [0, 1], got {self.gust_intensity}")
        if not 0 <= self.yaw_amplitude_deg <= 45:
            raise UserInputError(f"yaw_amplitude_deg must be in [0, 45], got {self.yaw_amplitude_deg}")
        if not 0 < self.f_min < self.f_max <= 0.5 / WIND_SAMPLE_DT:
            raise UserInputError(f"need 0 < f_min < f_max <= {0.5 / WIND_SAMPLE_DT:g} Hz")
        if not 1 <= self.n_modes <= 64:
            raise UserInputError(f"n_modes must be in [1, 64], got {self.n_modes}")

    def speed(self, level: str) -> float:
        """Mean speed in m/s of a fan level name (``"W1"``..``"W3"``)."""
        return float(self.speeds[fan_level_index(level)])


def fan_level_index(level: str) -> int:
    """Index 0–2 of a fan level name; accepts ``"W2"``, ``"w2"`` and ``"2"``.

    Raises:
        UserInputError: for anything else.
    """
    text = str(level).strip().upper()
    text = text if text.startswith("W") else "W" + text
    if text not in FAN_LEVELS:
        raise UserInputError(f"unknown fan level {level!r}; use one of {', '.join(FAN_LEVELS)}")
    return FAN_LEVELS.index(text)


def turbulence(seed: int, times: np.ndarray, settings: FanSettings) -> np.ndarray:
    """Smooth seeded noise of zero mean and unit standard deviation, ``(2, K)``.

    Row 0 drives the speed, row 1 the direction. Each is a sum of ``n_modes`` sinusoids
    with log-spaced random frequencies between ``f_min`` and ``f_max``, random phases and
    amplitudes falling as ``f^(-5/6)`` (a Kolmogorov-like spectrum: slow gusts dominate).

    Args:
        seed: Seed of frequencies and phases.
        times: ``(K,)`` sample times in seconds.
        settings: Frequency range and number of modes.
    """
    rng = np.random.default_rng([seed, 7_235_311])
    out = np.empty((2, times.size))
    for row in range(2):
        freqs = np.exp(rng.uniform(math.log(settings.f_min), math.log(settings.f_max), settings.n_modes))
        phases = rng.uniform(0.0, 2.0 * math.pi, settings.n_modes)
        amps = freqs ** (-5.0 / 6.0)
        amps /= math.sqrt(0.5 * float(np.sum(amps**2)))  # unit standard deviation
        out[row] = np.sum(amps[:, None] * np.sin(2.0 * math.pi * freqs[:, None] * times[None] + phases[:, None]), 0)
    return out


def fan_schedule(
    settings: FanSettings, *, level: str, seed: int, duration: float, z_ref: float
) -> WindSchedule:
    """The fan's wind over ``[0, duration]`` for the flag solver.

    Args:
        settings: The fan.
        level: ``"W1"``, ``"W2"`` or ``"W3"``.
        seed: Seed of the turbulence (a fan's gusts differ from video to video).
        duration: Simulated seconds to cover.
        z_ref: Height in metres where the speed holds (no shear: any height will do).

    Returns:
        A schedule blowing along +y (face-on to a fabric hung in the x–z plane).
    """
    mean = settings.speed(level)
    times = np.arange(int(math.ceil(duration / WIND_SAMPLE_DT)) + 2) * WIND_SAMPLE_DT
    noise = turbulence(seed, times, settings)
    table = np.zeros((times.size, WIND_COLUMNS))  # no shear, horizontal
    table[:, 0] = mean * np.maximum(1.0 + settings.gust_intensity * noise[0], 0.0)
    table[:, 1] = math.radians(settings.yaw_amplitude_deg) * noise[1]
    return WindSchedule(dt=WIND_SAMPLE_DT, table=table, z_ref=z_ref, direction=0.5 * math.pi)
