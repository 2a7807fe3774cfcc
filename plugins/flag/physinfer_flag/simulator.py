"""The flag's Simulator role: θ (wind speed, area weight, 15 bending multipliers) → Trajectory.

:class:`FlagSimulator` maps a parameter set onto the cloth solver of
:mod:`physinfer_flag.cloth`: the area weight sets the node masses, the 15 multipliers
scale the camel-ponte-roma bending table entry by entry, and the wind speed is the base
of the wind schedule (which effects may rewrite, see :mod:`physinfer_flag.cloth_wind`).
After a warm-up from rest it records ``n_frames`` frames at ``fps``. Conventions of the
trajectory: metres, z up, the pole vertical along z at x = y = 0 from the ground (z = 0)
to ``pole_height``, the hoist edge on the pole, wind along +x by default, so the flag
streams towards +x. ``extras`` hold ``uv`` ``(V, 2)`` texture coordinates (u hoist 0 →
fly 1, v bottom 0 → top 1), ``pole`` ``(2, 3)`` (bottom and top point) and
``grid_shape`` ``(2,)`` = ``(nv, nu)`` (vertex ``j * nu + i`` is row ``j``, column ``i``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any, Literal, Protocol

import numpy as np

from physinfer.errors import SimulationFailed, UserInputError
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.roles import Effect, Params, Simulator
from physinfer.settings import require
from physinfer.types import Trajectory
from physinfer_flag.cloth import ClothPhysics, ClothSolver, FlagRun
from physinfer_flag.cloth_mesh import FlagMesh, build_flag_mesh
from physinfer_flag.cloth_wind import WindState, sample_wind
from physinfer_flag.material import (
    BEND_DIRECTIONS_DEG,
    HALF_CURVATURE_SAMPLES,
    ClothMaterial,
    bending_multipliers,
    load_material,
    scaled_bending,
)

#: Gap between the flag's top hoist corner and the top of the pole, metres.
POLE_CAP = 0.05
#: Automatic time step: ``REFERENCE_DT`` at ``REFERENCE_SPACING``, proportional to the grid
#: spacing (the explicit limit of the membrane waves). 1/1200 s at 5 cm keeps a margin of
#: about 1.4 over the smallest step that blew up across the parameter space (docs).
REFERENCE_DT = 1.0 / 1200.0
REFERENCE_SPACING = 0.05


class ClipTiming:
    """Mixin of cloth simulator settings: step, warm-up and duration from the frame timing.

    The settings dataclass provides ``n_frames``, ``fps``, ``warmup_s``, ``substeps``
    (``int | None``) and :attr:`steps_per_frame`; the hanging cloth's settings use it too.
    """

    n_frames: int
    fps: float
    warmup_s: float
    substeps: int | None

    @property
    def steps_per_frame(self) -> int:
        """Integration steps per output frame (the settings class decides)."""
        raise NotImplementedError

    def steps_for(self, dt_max: float) -> int:
        """``substeps``, or the fewest steps per frame that keep ``dt`` ≤ ``dt_max`` seconds."""
        if self.substeps is not None:
            return int(self.substeps)
        return max(1, math.ceil(1.0 / (self.fps * dt_max) - 1e-9))

    @property
    def dt(self) -> float:
        """Integration step in seconds."""
        return 1.0 / (self.fps * self.steps_per_frame)

    @property
    def warmup_frames(self) -> int:
        """Warm-up length in whole output frames."""
        return int(round(self.warmup_s * self.fps))

    @property
    def duration(self) -> float:
        """Simulated seconds per clip, warm-up included."""
        return (self.warmup_frames + self.n_frames) / self.fps

    def timing_checks(self) -> list[tuple[bool, str]]:
        """``(ok, message)`` checks of ``n_frames``, ``fps``, ``warmup_s`` and ``substeps``."""
        return [
            (1 <= self.n_frames <= 100_000, f"n_frames must be in [1, 100000], got {self.n_frames}"),
            (0 < self.fps <= 1000, f"fps must be in (0, 1000], got {self.fps}"),
            (0 <= self.warmup_s <= 600, f"warmup_s must be in [0, 600] s, got {self.warmup_s}"),
            (self.substeps is None or 1 <= self.substeps <= 100_000,
             f"substeps must be None (automatic) or in [1, 100000], got {self.substeps}"),
        ]

    def check_step(self) -> None:
        """Refuse a step the explicit solver cannot take.

        Raises:
            UserInputError: ``dt`` above 10 ms.
        """
        if self.dt > 0.01:
            raise UserInputError(f"the step 1/(fps*substeps) = {self.dt:g} s is too large; raise substeps")


class ClothSolverSettings(Protocol):
    """What :func:`cloth_solver` reads from a cloth simulator's settings."""

    dt: float
    steps_per_frame: int
    gravity: float
    rho_air: float
    c_drag: float
    damping: float
    strain_limit: float
    perturbation_m: float


def damping_checks(damping: float, strain_limit: float) -> list[tuple[bool, str]]:
    """``(ok, message)`` checks of the stretching damping time and the strain limit."""
    return [
        (0 <= damping <= 0.01, f"damping must be in [0, 0.01] s, got {damping}"),
        (0 <= strain_limit < 1, f"strain_limit must be in [0, 1), got {strain_limit}"),
    ]


def cloth_solver(
    settings: ClothSolverSettings, mesh: FlagMesh, material: ClothMaterial, *, strain_limit_sweeps: int
) -> ClothSolver:
    """The cloth solver of ``mesh`` and ``material`` with the physics of ``settings``."""
    physics = ClothPhysics(
        dt=settings.dt, gravity=settings.gravity, rho_air=settings.rho_air, c_drag=settings.c_drag,
        damping=settings.damping, strain_limit=settings.strain_limit, strain_limit_sweeps=strain_limit_sweeps,
    )
    return ClothSolver(
        mesh=mesh, material=material, physics=physics, substeps=settings.steps_per_frame,
        perturbation=settings.perturbation_m,
    )


def cloth_trajectory(
    vertices: np.ndarray, mesh: FlagMesh, fps: float, extras: dict[str, np.ndarray], offset: np.ndarray | None = None
) -> Trajectory:
    """A trajectory of the solver's ``vertices`` ``(T, V, 3)``, moved by ``offset`` ``(3,)``.

    ``extras`` are copied, so trajectories never share arrays.

    Raises:
        SimulationFailed: ``vertices`` hold NaN or infinity.
    """
    if not np.isfinite(vertices).all():
        raise SimulationFailed("cloth simulation produced NaN")
    positions = vertices if offset is None else vertices + offset
    return Trajectory(positions, mesh.faces.copy(), float(fps), {k: v.copy() for k, v in extras.items()})


def check_setting_names(config_class: type, names: Any, owner: str) -> None:
    """Refuse setting names that are not fields of the settings dataclass ``config_class``.

    Raises:
        UserInputError: ``"unknown <owner> simulator setting(s) [...]; known: [...]"``.
    """
    known = set(config_class.__dataclass_fields__)
    unknown = sorted(set(names) - known)
    if unknown:
        raise UserInputError(f"unknown {owner} simulator setting(s) {unknown}; known: {sorted(known)}")


def flag_parameter_space() -> ParameterSpace:
    """θ of the flag (the paper's Table 1), 17 parameters in this order.

    ``wind_speed`` [0, 10] m/s, ``area_weight`` [0.10, 0.17] kg/m², then the 15 bending
    multipliers [0.1, 10] (log scale) of the camel-ponte-roma table, direction-major:
    ``bend_0deg_c00`` … ``bend_0deg_c20``, ``bend_45deg_c00`` …, ``bend_90deg_c20``.
    """
    specs = [
        ParameterSpec("wind_speed", (0.0, 10.0), "m/s", "linear",
                      "wind speed at the flag's mid-height, blowing along +x"),
        ParameterSpec("area_weight", (0.10, 0.17), "kg/m^2", "linear", "area density of the fabric"),
    ]
    for d in BEND_DIRECTIONS_DEG:
        for c in HALF_CURVATURE_SAMPLES:
            specs.append(
                ParameterSpec(
                    f"bend_{d}deg_c{c:02d}", (0.1, 10.0), "", "log",
                    f"multiplier of the bending stiffness at {d} deg to the warp, half-curvature {c} 1/m",
                )
            )
    return ParameterSpace(specs)


@dataclass(frozen=True)
class FlagSimConfig(ClipTiming):
    """Settings of :class:`FlagSimulator` (everything but θ).

    Attributes:
        width: Hoist-to-fly length in metres (aspect 3:2 by default: a 1.5 m × 1 m flag, a
            common size on poles; its grid resolves the fabric's bending, see docs).
        height: Hoist length in metres.
        grid_u: Nodes from hoist to fly.
        grid_v: Nodes from bottom to top. Square cells (``width/(grid_u-1)`` =
            ``height/(grid_v-1)``) put every hinge exactly on a table direction.
        pin_mode: ``"edge"``: the whole hoist edge is held on the pole; ``"corners"``: only
            the two hoist corners (ArcSim's flag scene; use with ``strain_limit``).
        n_frames: Recorded frames.
        fps: Output frame rate in Hz.
        warmup_s: Simulated seconds from rest before recording starts (rounded to frames).
        substeps: Integration steps per output frame, ``dt = 1 / (fps · substeps)``;
            ``None`` chooses them from the grid spacing (48 at the default 5 cm grid and
            25 fps, proportionally more on finer grids), see :attr:`steps_per_frame`.
        rho_air: Air density in kg/m³ (normal pressure ``ρ A |v_n| v_n n``).
        c_drag: Tangential drag coefficient in kg/(m²·s) (``c A v_t``).
        gravity: Gravitational acceleration in m/s².
        damping: Kelvin–Voigt damping time of the stretching stress, seconds.
        strain_limit: Largest edge stretch kept by strain limiting (0 turns it off); 5 %
            as in ArcSim's flag scene.
        strain_limit_sweeps: Strain-limiting sweeps per step; ``None``: 1 with the edge
            pinned, 4 with only the corners pinned (the cloth next to a pinned corner
            otherwise still stretches 30–40 % at 10 m/s).
        wind_direction_deg: Base wind direction, degrees from +x towards +y.
        perturbation_m: Largest out-of-plane offset of the seeded initial shape, metres.
        pole_height: Height of the pole's top above the ground (z = 0), metres; the flag's
            top hoist corner is 5 cm below it.
        material_path: Material JSON; ``None`` uses the shipped camel-ponte-roma.
    """

    width: float = 1.5
    height: float = 1.0
    grid_u: int = 31
    grid_v: int = 21
    pin_mode: Literal["edge", "corners"] = "edge"
    n_frames: int = 60
    fps: float = 25.0
    warmup_s: float = 2.0
    substeps: int | None = None
    rho_air: float = 1.2
    c_drag: float = 0.05
    gravity: float = 9.81
    damping: float = 1e-4
    strain_limit: float = 0.05
    strain_limit_sweeps: int | None = None
    wind_direction_deg: float = 0.0
    perturbation_m: float = 0.01
    pole_height: float = 3.0
    material_path: str | None = None

    def validate(self) -> None:
        """Raise :class:`UserInputError` naming the first bad setting and its valid range."""
        checks = [
            (self.width > 0 and self.height > 0, f"flag size must be positive, got {self.width} x {self.height} m"),
            (3 <= self.grid_u <= 1000 and 3 <= self.grid_v <= 1000,
             f"grid_u and grid_v must be in [3, 1000], got {self.grid_u} x {self.grid_v}"),
            (self.pin_mode in ("edge", "corners"), f"pin_mode must be 'edge' or 'corners', got {self.pin_mode!r}"),
            *self.timing_checks(),
            (self.rho_air >= 0, f"rho_air must be >= 0 kg/m^3, got {self.rho_air}"),
            (self.c_drag >= 0, f"c_drag must be >= 0, got {self.c_drag}"),
            (self.gravity >= 0, f"gravity must be >= 0, got {self.gravity}"),
            *damping_checks(self.damping, self.strain_limit),
            (self.strain_limit_sweeps is None or 1 <= self.strain_limit_sweeps <= 100,
             f"strain_limit_sweeps must be None or in [1, 100], got {self.strain_limit_sweeps}"),
            (math.isfinite(self.wind_direction_deg), "wind_direction_deg must be finite"),
            (0 <= self.perturbation_m <= 0.5 * self.width, f"perturbation_m must be in [0, width/2], got {self.perturbation_m}"),
            (self.pole_height >= self.height + POLE_CAP,
             f"pole_height must be at least height + {POLE_CAP} m = {self.height + POLE_CAP} m, got {self.pole_height}"),
        ]
        require(checks)
        self.check_step()

    @property
    def spacing(self) -> float:
        """Largest grid spacing in metres."""
        return max(self.width / (self.grid_u - 1), self.height / (self.grid_v - 1))

    @property
    def steps_per_frame(self) -> int:
        """``substeps``, or the automatic choice: ``dt`` ≤ 1/1200 s × spacing / 5 cm."""
        return self.steps_for(REFERENCE_DT * min(self.spacing, REFERENCE_SPACING) / REFERENCE_SPACING)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings (rebuild with ``FlagSimConfig(**d)``)."""
        return asdict(self)


class FlagSimulator(Simulator):
    """Simulates a flag on a pole in the wind (Wang bending, camel-ponte-roma stretching).

    Args:
        config: Settings; ``None`` uses the defaults.
        effects: Effects switched into the wind; each must understand the flag's
            :class:`~physinfer_flag.cloth_wind.WindState` in ``term(state, params, t)``
            and return a new one. Their parameters are appended to θ.

    Raises:
        UserInputError: on bad settings or an effect of another phenomenon.
    """

    def __init__(self, *, config: FlagSimConfig | None = None, effects: Sequence[Effect] = ()) -> None:
        self.config = config or FlagSimConfig()
        self.config.validate()
        self.effects = tuple(effects)
        space = flag_parameter_space()
        for effect in self.effects:
            if getattr(effect, "phenomenon", "flag") != "flag":
                raise UserInputError(
                    f"effect {getattr(effect, 'name', effect)!r} belongs to {effect.phenomenon!r}, not to 'flag'"
                )
            space = space.merged(effect.parameter_space)
        self.parameter_space = space
        c = self.config
        self.material: ClothMaterial = load_material(c.material_path)
        self.mesh: FlagMesh = build_flag_mesh(
            width=c.width, height=c.height, nu=c.grid_u, nv=c.grid_v, pin_mode=c.pin_mode,
            top_z=c.pole_height - POLE_CAP,
        )
        self.solver = cloth_solver(
            c, self.mesh, self.material,
            strain_limit_sweeps=c.strain_limit_sweeps or (4 if c.pin_mode == "corners" else 1),
        )
        self._extras = {
            "uv": self.mesh.uv.astype(np.float32),
            "pole": np.array([[0.0, 0.0, 0.0], [0.0, 0.0, c.pole_height]], dtype=np.float32),
            "grid_shape": np.array([c.grid_v, c.grid_u], dtype=np.int32),
        }

    @property
    def flag_centre_height(self) -> float:
        """Height of the flag's middle above the ground, metres (the wind's reference height)."""
        return self.config.pole_height - POLE_CAP - 0.5 * self.config.height

    def flag_run(self, params: Params, *, seed: int = 0) -> FlagRun:
        """The solver inputs of one parameter set (validated and completed with defaults).

        Raises:
            UserInputError: for unknown names or values out of bounds.
        """
        full = self.parameter_space.complete(params)
        bending = scaled_bending(self.material, bending_multipliers(full))
        base = WindState(speed=full["wind_speed"], z_ref=self.flag_centre_height, seed=int(seed))
        wind = sample_wind(
            base, duration=self.config.duration, direction=math.radians(self.config.wind_direction_deg),
            effects=self.effects, params=full,
        )
        return FlagRun(area_weight=full["area_weight"], bending=bending, wind=wind, seed=int(seed))

    def simulate(self, params: Params, *, seed: int = 0) -> Trajectory:
        """Simulate one flag; ``vertices`` ``(n_frames, V, 3)`` after the warm-up.

        Raises:
            SimulationFailed: on NaN or blow-up.
            UserInputError: for bad parameters.
        """
        run = self.flag_run(params, seed=seed)
        vertices = self.solver.run(run, warmup_frames=self.config.warmup_frames, n_frames=self.config.n_frames)
        return self._trajectory(vertices)

    def simulate_batch(self, params: Sequence[Params], *, seeds: Sequence[int]) -> list[Trajectory]:
        """Simulate ``B`` flags in parallel compiled threads (numba); same results as :meth:`simulate`.

        Raises:
            SimulationFailed: if any flag fails; the message lists the failed indices
                (:meth:`simulate_batch_partial` returns the others instead).
        """
        trajs, failures = self._run_batch(params, seeds)
        if failures:
            details = "; ".join(f"#{b}: {msg}" for b, msg in failures)
            raise SimulationFailed(f"{len(failures)} of {len(trajs)} flags failed: {details}")
        return [t for t in trajs if t is not None]

    def simulate_batch_partial(self, params: Sequence[Params], *, seeds: Sequence[int]) -> list[Trajectory | None]:
        """Like :meth:`simulate_batch`, but a failed flag gives ``None`` instead of an exception.

        For dataset generation: one blow-up does not cost the rest of the batch.
        """
        return self._run_batch(params, seeds)[0]

    def _run_batch(
        self, params: Sequence[Params], seeds: Sequence[int]
    ) -> tuple[list[Trajectory | None], list[tuple[int, str]]]:
        if len(params) != len(seeds):
            raise UserInputError(f"got {len(params)} parameter sets but {len(seeds)} seeds")
        if not params:
            return [], []
        runs = [self.flag_run(p, seed=s) for p, s in zip(params, seeds, strict=True)]
        vertices, status = self.solver.run_batch(
            runs, warmup_frames=self.config.warmup_frames, n_frames=self.config.n_frames
        )
        trajs: list[Trajectory | None] = []
        failures: list[tuple[int, str]] = []
        for b in range(len(runs)):
            code, frame = int(status[b, 0]), int(status[b, 1])
            if code == 0 and np.isfinite(vertices[b]).all():
                trajs.append(self._trajectory(vertices[b]))
            else:
                trajs.append(None)
                failures.append((b, self.solver.failure_message(code, frame) if code else "produced NaN"))
        return trajs, failures

    def _trajectory(self, vertices: np.ndarray) -> Trajectory:
        return cloth_trajectory(vertices, self.mesh, self.config.fps, self._extras)


def make_simulator(effects: Sequence[Effect] = (), **config: Any) -> FlagSimulator:
    """Factory of the phenomenon record: ``make_simulator(effects, grid_u=46, ...)``.

    Args:
        effects: Effects to switch in (see :class:`FlagSimulator`).
        **config: Any :class:`FlagSimConfig` field.

    Raises:
        UserInputError: on an unknown setting name or a bad value.
    """
    check_setting_names(FlagSimConfig, config, "flag")
    return FlagSimulator(config=FlagSimConfig(**config), effects=effects)

