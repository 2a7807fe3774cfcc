"""A pendulum as real videos show it: the simulator.

A bob on a massless string swings about a pivot: ``φ'' = -(g / L) sin φ - γ φ' + a_effects``,
integrated with scipy's DOP853 (relative tolerance 1e-9) and sampled at the output frame
rate. A real video starts anywhere in a swing, so the phase at the first frame is a nuisance
parameter: the bob is released from rest at ``amplitude`` and the clip starts ``phase``
small-angle periods later. The trajectory is the bob mesh moved rigidly; the pivot and the
length travel in its extras for the renderer (the string, the camera's framing).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from physinfer import ParameterSpace, ParameterSpec, SimulationFailed, Simulator, Trajectory
from physinfer.roles import Effect, Params

G = 9.81
PIVOT = np.array([0.0, 0.0, 0.0])
#: The θ entries that are nuisance parameters (reported apart from the physics).
NUISANCE = ("phase",)


def pendulum_parameter_space() -> ParameterSpace:
    """θ: the physics (length, damping, amplitude) and the phase at the first frame."""
    return ParameterSpace(
        [
            ParameterSpec("length", (0.1, 3.0), "m", scaling="log", description="pivot to the bob's centre"),
            ParameterSpec("damping", (0.0, 0.5), "1/s", description="linear damping rate γ"),
            ParameterSpec("amplitude", (1.0, 60.0), "deg", description="angle of the swing's first turning point"),
            ParameterSpec(
                "phase", (0.0, 1.0), "cycles", description="nuisance: the clip starts this share of a period after release"
            ),
        ]
    )


@dataclass(frozen=True)
class PendulumConfig:
    """Settings of :class:`PendulumSimulator`.

    Attributes:
        duration_s: Seconds recorded.
        fps: Output frame rate in Hz.
    """

    duration_s: float = 10.0
    fps: float = 20.0

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if not 0 < self.duration_s <= 120 or not 1 <= self.fps <= 240:
            raise ValueError("need 0 < duration_s <= 120 and 1 <= fps <= 240")

    @property
    def n_frames(self) -> int:
        """Frames recorded."""
        return max(2, int(round(self.duration_s * self.fps)))


def _template_mesh(subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """A unit icosphere at the origin: ``(V, 3)`` vertices and ``(F, 3)`` faces."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    return np.asarray(sphere.vertices, dtype=np.float32), np.asarray(sphere.faces, dtype=np.int32)


def bob_radius(length: float) -> float:
    """Rendered bob radius (m): a tenth of the length, 1.5-12 cm (looks only)."""
    return float(np.clip(0.1 * length, 0.015, 0.12))


class PendulumSimulator(Simulator):
    """Simulates the pendulum, optionally with effects switched in.

    Args:
        effects: Effects whose ``term(state, params, t)`` returns an extra angular
            acceleration; ``state`` is ``(phi, omega, length)``.
        config: Settings.
    """

    def __init__(self, *, effects: Sequence[Effect] = (), config: PendulumConfig | None = None) -> None:
        self.config = config or PendulumConfig()
        self.config.validate()
        self.effects = tuple(effects)
        space = pendulum_parameter_space()
        for effect in self.effects:
            space = space.merged(effect.parameter_space)
        self.parameter_space = space
        self._verts, self._faces = _template_mesh()

    def angles(self, params: Params) -> np.ndarray:
        """Angle φ (radians) at each output frame, shape ``(T,)``."""
        from scipy.integrate import solve_ivp

        length, gamma = params["length"], params["damping"]
        effects = self.effects

        def rhs(t: float, y: np.ndarray) -> list[float]:
            phi, omega = y
            a = -(G / length) * np.sin(phi) - gamma * omega
            for effect in effects:
                a += effect.term((phi, omega, length), params, t)
            return [omega, a]

        offset = params["phase"] * 2 * np.pi * np.sqrt(length / G)
        times = offset + np.arange(self.config.n_frames) / self.config.fps
        solution = solve_ivp(
            rhs, (0.0, float(times[-1])), [np.radians(params["amplitude"]), 0.0], method="DOP853",
            t_eval=times, rtol=1e-9, atol=1e-11,
        )  # fmt: skip
        if not solution.success or not np.all(np.isfinite(solution.y[0])):
            raise SimulationFailed(f"the pendulum's integration failed: {solution.message}")
        return solution.y[0]

    def simulate(self, params: Params, *, seed: int = 0) -> Trajectory:
        """Simulate; the pendulum is deterministic, ``seed`` is accepted and ignored."""
        params = self.parameter_space.complete(params)
        phi = self.angles(params)
        length = params["length"]
        # The bob swings in the x-z plane below the pivot; the renderer draws the string.
        centres = PIVOT + length * np.stack([np.sin(phi), np.zeros_like(phi), -np.cos(phi)], axis=1)
        vertices = self._verts[None] * bob_radius(length) + centres[:, None]
        return Trajectory(
            vertices.astype(np.float32),
            self._faces,
            self.config.fps,
            extras={"pivot": PIVOT.astype(np.float32), "length": np.array([length], dtype=np.float32)},
        )


class QuadraticDrag(Effect):
    """Air drag quadratic in speed: ``a = -c · L · |φ'| φ'`` (angular form); off at ``c = 0``."""

    name = "air_drag"
    description = "air drag growing with the square of the bob's speed"
    phenomenon = "pendulum"
    parameter_space = ParameterSpace(
        [ParameterSpec("drag_quadratic", (0.0, 2.0), "1/m", description="quadratic drag coefficient c", default=0.0)]
    )

    def term(self, state: tuple[float, float, float], params: Params, t: float) -> float:
        _phi, omega, length = state
        return -params["drag_quadratic"] * length * abs(omega) * omega


def make_simulator(effects: Sequence[Effect] = (), duration_s: float | None = None) -> PendulumSimulator:
    """Factory used by the phenomenon record; ``duration_s``: seconds recorded (default 10, the default target's)."""
    config = PendulumConfig() if duration_s is None else PendulumConfig(duration_s=float(duration_s))
    return PendulumSimulator(effects=effects, config=config)
