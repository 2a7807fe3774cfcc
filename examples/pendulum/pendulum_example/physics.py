"""A damped pendulum: the simulator of the worked example.

A bob of radius 10 cm on a massless rod swings about a pivot 1.8 m above the ground:
``φ'' = -(g / L) sin φ - γ φ' + a_effects``, integrated with a fixed-step RK4 at
1 kHz and sampled at 25 fps. The trajectory is the bob-and-rod mesh moved rigidly,
so the generic renderer can draw it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from physinfer import ParameterSpace, ParameterSpec, SimulationFailed, Simulator, Trajectory
from physinfer.roles import Effect, Params

G = 9.81
PIVOT = np.array([0.0, 0.0, 1.8])


def pendulum_parameter_space() -> ParameterSpace:
    """θ of the pendulum: rod length, linear damping rate, initial angle."""
    return ParameterSpace(
        [
            ParameterSpec("length", (0.4, 1.6), "m", description="pivot-to-bob distance"),
            ParameterSpec("damping", (0.0, 0.6), "1/s", description="linear damping rate γ"),
            ParameterSpec("amplitude", (10.0, 60.0), "deg", description="initial angle from vertical"),
        ]
    )


@dataclass(frozen=True)
class PendulumConfig:
    """Settings of :class:`PendulumSimulator`.

    Attributes:
        n_frames: Output frames.
        fps: Output frame rate in Hz.
        dt: Integration step in seconds.
        bob_radius: Bob radius in metres (rendered size only).
    """

    n_frames: int = 100
    fps: float = 25.0
    dt: float = 1e-3
    bob_radius: float = 0.1

    def validate(self) -> None:
        """Raise :class:`ValueError` on inconsistent settings."""
        if self.n_frames < 2 or self.fps <= 0 or not 0 < self.dt < 1 / self.fps:
            raise ValueError("need n_frames >= 2, fps > 0 and 0 < dt < 1/fps")


def _template_mesh(radius: float, segments: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A low-poly sphere at the origin: ``(V, 3)`` vertices and ``(F, 3)`` faces."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    return np.asarray(sphere.vertices, dtype=np.float32), np.asarray(sphere.faces, dtype=np.int32)


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
        self._verts, self._faces = _template_mesh(self.config.bob_radius)

    def _accel(self, phi: float, omega: float, params: Params, t: float) -> float:
        length = params["length"]
        a = -(G / length) * np.sin(phi) - params["damping"] * omega
        for effect in self.effects:
            a += effect.term((phi, omega, length), params, t)
        return a

    def angles(self, params: Params) -> np.ndarray:
        """Angle φ (radians) at each output frame, shape ``(T,)``."""
        c = self.config
        phi, omega = np.radians(params["amplitude"]), 0.0
        per_frame = int(round(1.0 / (c.fps * c.dt)))
        h = 1.0 / (c.fps * per_frame)
        out = np.empty(c.n_frames)
        t = 0.0
        for i in range(c.n_frames):
            out[i] = phi
            for _ in range(per_frame):
                k1p, k1w = omega, self._accel(phi, omega, params, t)
                k2p, k2w = omega + 0.5 * h * k1w, self._accel(phi + 0.5 * h * k1p, omega + 0.5 * h * k1w, params, t)
                k3p, k3w = omega + 0.5 * h * k2w, self._accel(phi + 0.5 * h * k2p, omega + 0.5 * h * k2w, params, t)
                k4p, k4w = omega + h * k3w, self._accel(phi + h * k3p, omega + h * k3w, params, t + h)
                phi += h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p)
                omega += h / 6 * (k1w + 2 * k2w + 2 * k3w + k4w)
                t += h
            if not (np.isfinite(phi) and abs(omega) < 1e3):
                raise SimulationFailed(f"pendulum blew up at t={t:.2f} s")
        return out

    def simulate(self, params: Params, *, seed: int = 0) -> Trajectory:
        """Simulate; the pendulum is deterministic, ``seed`` is accepted and ignored."""
        params = self.parameter_space.complete(params)
        phi = self.angles(params)
        length = params["length"]
        # The bob swings in the x-z plane; the rod is drawn by the renderer from the pivot.
        centres = PIVOT + length * np.stack([np.sin(phi), np.zeros_like(phi), -np.cos(phi)], axis=1)
        vertices = (self._verts[None] + centres[:, None].astype(np.float32)).astype(np.float32)
        return Trajectory(
            vertices, self._faces, self.config.fps, extras={"pivot": PIVOT.astype(np.float32)}
        )


class QuadraticDrag(Effect):
    """Air drag quadratic in speed: ``a = -c · L · |φ'| φ'`` (angular form); off at ``c = 0``."""

    name = "quadratic_drag"
    description = "air drag growing with the square of the bob's speed"
    phenomenon = "pendulum_lab"
    parameter_space = ParameterSpace(
        [
            ParameterSpec(
                "drag_quadratic", (0.0, 2.0), "1/m", description="quadratic drag coefficient c", default=0.0
            )
        ]
    )

    def term(self, state: tuple[float, float, float], params: Params, t: float) -> float:
        _phi, omega, length = state
        return -params["drag_quadratic"] * length * abs(omega) * omega


def make_simulator(effects: Sequence[Effect] = ()) -> PendulumSimulator:
    """Factory used by the phenomenon record."""
    return PendulumSimulator(effects=effects)
