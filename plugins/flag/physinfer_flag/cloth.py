"""The flag cloth solver: mesh + material + physics settings → recorded vertex positions.

:class:`ClothSolver` prepares the arrays the compiled kernels of
:mod:`physinfer_flag.cloth_kernels` read (inverse masses from the area weight, each hinge's
stiffness curve from the bending table, the seeded initial state) and runs one flag
(:meth:`ClothSolver.run`) or a batch of flags in parallel threads
(:meth:`ClothSolver.run_batch`). It knows nothing of θ's names; the flag simulator maps
parameters to a :class:`FlagRun`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from physinfer.errors import SimulationFailed, UserInputError
from physinfer_flag.cloth_kernels import (
    N_SCALARS,
    S_BETA,
    S_C_DRAG,
    S_DT,
    S_GRAVITY,
    S_LIMIT_SWEEPS,
    S_LOOKUP_EVERY,
    S_MAX_DIST,
    S_MAX_SPEED,
    S_RHO_AIR,
    S_STRAIN_LIMIT,
    STATUS_DISTANCE,
    STATUS_NAN,
    STATUS_OK,
    STATUS_SPEED,
    run_flag,
    run_flag_batch,
)
from physinfer_flag.cloth_mesh import FlagMesh
from physinfer_flag.cloth_wind import WIND_COLUMNS, WindSchedule
from physinfer_flag.material import ClothMaterial

_STATUS_TEXT = {
    STATUS_NAN: "produced NaN",
    STATUS_SPEED: "blew up (a node exceeded the speed limit)",
    STATUS_DISTANCE: "blew up (a node left the region around the pole)",
}


@dataclass(frozen=True)
class ClothPhysics:
    """Physical and numerical settings of the solver.

    Attributes:
        dt: Integration step in seconds.
        gravity: Gravitational acceleration in m/s² (acts along -z).
        rho_air: Air density in kg/m³ in the normal pressure ``ρ A |v_n| v_n n``.
        c_drag: Tangential drag coefficient in kg/(m²·s) in ``c A v_t``.
        damping: Kelvin–Voigt damping time β in seconds of the stretching stress
            (``S = C : (G + β Ġ)``); damps in-plane ringing, not flapping.
        strain_limit: Largest edge stretch kept by strain limiting (0.1 = 10 %); 0 turns it off.
        strain_limit_sweeps: Gauss–Seidel sweeps of strain limiting per step (more pull
            the edges next to pinned corners closer to the limit).
        max_speed: A node faster than this (m/s) marks the run as blown up.
        max_distance_factor: A node farther from the pole than this many flag diagonals
            marks the run as blown up.
        lookup_interval: Seconds between look-ups of the stretching stiffness from the
            current strain (ArcSim looks them up once per implicit step, 5 ms in its flag
            scene); 0 looks them up every step.
    """

    dt: float = 5e-4
    gravity: float = 9.81
    rho_air: float = 1.2
    c_drag: float = 0.05
    damping: float = 2e-4
    strain_limit: float = 0.0
    strain_limit_sweeps: int = 1
    max_speed: float = 80.0
    max_distance_factor: float = 2.0
    lookup_interval: float = 0.005

    def validate(self) -> None:
        """Raise :class:`UserInputError` naming the first out-of-range setting."""
        checks = [
            (0 < self.dt <= 0.01, f"dt must be in (0, 0.01] s, got {self.dt}"),
            (self.gravity >= 0, f"gravity must be >= 0, got {self.gravity}"),
            (self.rho_air >= 0, f"rho_air must be >= 0, got {self.rho_air}"),
            (self.c_drag >= 0, f"c_drag must be >= 0, got {self.c_drag}"),
            (0 <= self.damping <= 0.01, f"damping must be in [0, 0.01] s, got {self.damping}"),
            (0 <= self.strain_limit < 1, f"strain_limit must be in [0, 1), got {self.strain_limit}"),
            (1 <= self.strain_limit_sweeps <= 100,
             f"strain_limit_sweeps must be in [1, 100], got {self.strain_limit_sweeps}"),
            (self.max_speed > 0, f"max_speed must be positive, got {self.max_speed}"),
            (self.max_distance_factor > 1, f"max_distance_factor must exceed 1, got {self.max_distance_factor}"),
            (0 <= self.lookup_interval <= 0.05, f"lookup_interval must be in [0, 0.05] s, got {self.lookup_interval}"),
        ]
        for ok, message in checks:
            if not ok:
                raise UserInputError(message)


@dataclass(frozen=True)
class FlagRun:
    """The per-flag inputs of one simulation.

    Attributes:
        area_weight: Area density in kg/m².
        bending: ``(3, 5)`` bending table in N·m (already scaled by θ's multipliers).
        wind: The wind schedule.
        seed: Seed of the out-of-plane initial perturbation.
    """

    area_weight: float
    bending: np.ndarray
    wind: WindSchedule
    seed: int = 0


class ClothSolver:
    """Runs flags on one mesh with one material and one set of physics settings.

    Args:
        mesh: The flag mesh.
        material: Supplies the stretching table (the area weight and bending come per run).
        physics: Solver settings.
        substeps: Integration steps per output frame (``dt`` × ``substeps`` is the frame time).
        perturbation: Largest out-of-plane offset (m) of the seeded initial shape; a flag
            that starts exactly in the wind's plane never leaves it.
    """

    def __init__(
        self,
        *,
        mesh: FlagMesh,
        material: ClothMaterial,
        physics: ClothPhysics,
        substeps: int,
        perturbation: float = 0.01,
    ) -> None:
        physics.validate()
        if substeps < 1:
            raise UserInputError(f"substeps must be >= 1, got {substeps}")
        self.mesh = mesh
        self.material = material
        self.physics = physics
        self.substeps = int(substeps)
        self.perturbation = float(perturbation)
        self._samples = np.ascontiguousarray(material.stretching_samples())
        diagonal = float(np.hypot(np.ptp(mesh.material_uv[:, 0]), np.ptp(mesh.material_uv[:, 1])))
        self._scalars = np.zeros(N_SCALARS)
        self._scalars[S_DT] = physics.dt
        self._scalars[S_GRAVITY] = physics.gravity
        self._scalars[S_RHO_AIR] = physics.rho_air
        self._scalars[S_C_DRAG] = physics.c_drag
        self._scalars[S_BETA] = physics.damping
        self._scalars[S_STRAIN_LIMIT] = physics.strain_limit
        self._scalars[S_MAX_SPEED] = physics.max_speed
        self._scalars[S_MAX_DIST] = physics.max_distance_factor * diagonal
        self._scalars[S_LOOKUP_EVERY] = max(1, round(physics.lookup_interval / physics.dt))
        self._scalars[S_LIMIT_SWEEPS] = physics.strain_limit_sweeps
        # Rest-shape factors of the bending kernel (see add_bending_forces).
        self._hinge_curvature = mesh.hinge_length / (10.0 * mesh.hinge_area)
        self._hinge_shape = mesh.hinge_length**2 / (4.0 * mesh.hinge_area)
        direction = mesh.hinge_direction
        self._row = np.minimum(np.floor(direction), 1).astype(np.int64)
        self._row_weight = direction - self._row

    # -- per-run inputs ---------------------------------------------------------------

    def inverse_mass(self, area_weight: float) -> np.ndarray:
        """``(V,)`` inverse lumped node masses for an area weight in kg/m²; 0 on pinned nodes."""
        if not area_weight > 0:
            raise UserInputError(f"area_weight must be positive, got {area_weight}")
        inv = 1.0 / (area_weight * self.mesh.node_area)
        inv[self.mesh.pinned] = 0.0
        return inv

    def hinge_curves(self, bending: np.ndarray) -> np.ndarray:
        """``(H, 5)`` stiffness samples of every hinge, interpolated between direction rows."""
        bending = np.asarray(bending, dtype=np.float64)
        w = self._row_weight[:, None]
        return np.ascontiguousarray((1.0 - w) * bending[self._row] + w * bending[self._row + 1])

    def initial_state(self, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """Rest shape with a smooth seeded out-of-plane offset, and zero velocity.

        The offset is a random mix of four low modes over the cloth, zero on the hoist
        edge, scaled so its largest magnitude is ``perturbation``.

        Returns:
            ``(V, 3)`` positions and ``(V, 3)`` velocities, float64.
        """
        rng = np.random.default_rng(seed)
        s, r = self.mesh.uv[:, 0].astype(np.float64), self.mesh.uv[:, 1].astype(np.float64)
        c = rng.standard_normal(4)
        shape = s * (c[0] + c[1] * (2 * r - 1) + c[2] * np.sin(np.pi * s) + c[3] * np.cos(np.pi * r))
        peak = np.abs(shape).max()
        x = self.mesh.rest.copy()
        if peak > 0:
            x[:, 1] += self.perturbation * shape / peak
        x[self.mesh.pinned] = self.mesh.rest[self.mesh.pinned]
        return x, np.zeros_like(x)

    # -- running ------------------------------------------------------------------------

    def run(self, run: FlagRun, *, warmup_frames: int, n_frames: int) -> np.ndarray:
        """Simulate one flag; returns ``(n_frames, V, 3)`` float32 positions after warm-up.

        Raises:
            SimulationFailed: on NaN or blow-up.
        """
        m = self.mesh
        x, v = self.initial_state(run.seed)
        out = np.empty((n_frames, m.n_vertices, 3), dtype=np.float32)
        status, frame = run_flag(
            x, v, self.inverse_mass(run.area_weight), m.faces, m.face_dm_inv, m.face_area,
            self._samples, m.hinges, m.hinge_faces, self._hinge_curvature, self._hinge_shape, self.hinge_curves(run.bending),
            m.edges, m.edge_length, np.ascontiguousarray(run.wind.table, dtype=np.float64),
            run.wind.scalars(), self._scalars, self.substeps, int(warmup_frames), out,
        )
        self._raise_on_failure(status, frame)
        return out

    def run_batch(
        self, runs: Sequence[FlagRun], *, warmup_frames: int, n_frames: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Simulate ``B`` flags in parallel threads.

        Returns:
            ``(B, n_frames, V, 3)`` float32 positions and ``(B, 2)`` int64 ``(status,
            frame)``; a flag with a non-zero status failed (see :meth:`failure_message`).
        """
        m = self.mesh
        batch = len(runs)
        states = [self.initial_state(r.seed) for r in runs]
        x0 = np.stack([s[0] for s in states])
        v0 = np.stack([s[1] for s in states])
        inv_mass = np.stack([self.inverse_mass(r.area_weight) for r in runs])
        curves = np.stack([self.hinge_curves(r.bending) for r in runs])
        wind_lengths = np.array([r.wind.table.shape[0] for r in runs], dtype=np.int64)
        n_wind = int(wind_lengths.max())
        wind = np.zeros((batch, n_wind, WIND_COLUMNS))
        for b, r in enumerate(runs):  # each flag reads only its own samples: batch = single runs
            wind[b, : wind_lengths[b]] = r.wind.table
        wind_scalars = np.stack([r.wind.scalars() for r in runs])
        if len({r.wind.dt for r in runs}) > 1 and n_wind > 1:
            raise UserInputError("all flags of a batch must sample their wind with the same dt")
        out = np.empty((batch, n_frames, m.n_vertices, 3), dtype=np.float32)
        status = run_flag_batch(
            x0, v0, inv_mass, m.faces, m.face_dm_inv, m.face_area, self._samples, m.hinges,
            m.hinge_faces, self._hinge_curvature, self._hinge_shape, curves, m.edges, m.edge_length, wind, wind_lengths,
            wind_scalars, self._scalars, self.substeps, int(warmup_frames), out,
        )
        return out, status

    def failure_message(self, status: int, frame: int) -> str:
        """Human-readable description of a non-zero kernel status."""
        seconds = (frame + 1) * self.substeps * self.physics.dt
        return f"cloth simulation {_STATUS_TEXT.get(status, 'failed')} at t = {seconds:.2f} s"

    def _raise_on_failure(self, status: int, frame: int) -> None:
        if status != STATUS_OK:
            raise SimulationFailed(self.failure_message(status, frame))
