"""The hanging cloth's Simulator role: θ (bending multiplier, area weight) → Trajectory.

A rectangle of fabric hangs from a horizontal rod (its whole top edge pinned, gathered to
a fraction of the fabric's width) and a fan in front of it blows face-on
(:mod:`physinfer_hanging_cloth.fan`). The cloth physics is
the flag plugin's solver, reused as is: the flag mesh builder lays the sheet in the x–z
plane and this module pins its top row instead of the hoist column and starts the sheet
gathered towards the rod (:func:`hanging_mesh`); the fan's wind is a
:class:`~physinfer_flag.cloth_wind.WindSchedule` along +y. θ scales the whole
camel-ponte-roma bending table by one multiplier and sets the area weight; the fan level
(W1–W3) and the seed are properties of a video, not of the fabric, so they are a setting
and an argument rather than parameters to infer.

Conventions of the trajectory: metres, z up, the rod along x at height ``rod_height``,
the cloth centred on x = 0 hanging in the x–z plane, the fan blowing along +y (the
camera looks along +y from the fan's side). ``extras`` hold ``uv`` ``(V, 2)`` (u left 0 →
right 1, v bottom 0 → top 1), ``rod`` ``(2, 3)`` (its two ends) and ``grid_shape``
``(2,)`` = ``(nv, nu)``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from physinfer.errors import SimulationFailed, UserInputError
from physinfer.parameters import ParameterSpace, ParameterSpec
from physinfer.roles import Effect, Params, Simulator
from physinfer.settings import require
from physinfer.types import Trajectory
from physinfer_flag.cloth import FlagRun
from physinfer_flag.cloth_mesh import FlagMesh, build_flag_mesh
from physinfer_flag.material import ClothMaterial, load_material
from physinfer_flag.simulator import (
    ClipTiming,
    check_setting_names,
    cloth_solver,
    cloth_trajectory,
    damping_checks,
)
from physinfer_hanging_cloth.fan import FanSettings, fan_level_index, fan_schedule

#: Bounds of θ: they cover the real fabrics' range (units.py: multipliers 1.6–22, area
#: weights 0.058–0.57 kg/m²) with a margin.
BENDING_MULTIPLIER_BOUNDS = (1.0, 40.0)
AREA_WEIGHT_BOUNDS = (0.05, 0.6)

#: Explicit-step reference of the flag solver: 1/1200 s at 5 cm for area weights ≥ 0.10
#: kg/m². The step scales with the grid spacing and with sqrt(area weight) (membrane wave
#: speed ∝ sqrt(stiffness / area weight)); :attr:`HangingClothConfig.steps_per_frame`.
REFERENCE_DT = 1.0 / 1200.0
REFERENCE_SPACING = 0.05
REFERENCE_AREA_WEIGHT = 0.10


def hanging_cloth_parameter_space() -> ParameterSpace:
    """θ of the hanging cloth: ``bending_multiplier`` and ``area_weight``, both log scale."""
    return ParameterSpace(
        [
            ParameterSpec(
                "bending_multiplier", BENDING_MULTIPLIER_BOUNDS, "", "log",
                "multiplier of the whole camel-ponte-roma bending table (1: the base fabric; "
                "see physinfer_hanging_cloth.units for lbf*in^2)",
            ),
            ParameterSpec("area_weight", AREA_WEIGHT_BOUNDS, "kg/m^2", "log", "area density of the fabric"),
        ]
    )


@dataclass(frozen=True)
class HangingClothConfig(ClipTiming):
    """Settings of :class:`HangingClothSimulator` (everything but θ).

    Attributes:
        width: Width of the fabric along the rod, metres.
        height: Hanging length of the fabric, metres.
        spacing: Target grid spacing in metres (rounded so the nodes fit the sheet).
        rod_height: Height of the rod (the fabric's top edge) above the ground, metres.
        gather: Length of rod the top edge is held on, as a fraction of the fabric's
            width. A fabric gathered on a rod hangs in folds whose size and sharpness
            follow its bending stiffness (drape) — the visual cue of stiffness; on a flat
            sheet in a uniform wind bending barely shows at this grid spacing (docs).
        fan_level: Fan setting of the video, ``"W1"``, ``"W2"`` or ``"W3"``.
        fan: How the fan blows (speeds of the levels, gusts).
        n_frames: Recorded frames (32 at 25 fps: the 30 the SDN front end reads, and a margin).
        fps: Output frame rate in Hz.
        warmup_s: Seconds simulated from rest, fan on, before recording.
        substeps: Integration steps per frame; ``None`` chooses them from the grid spacing
            and the lightest area weight of θ's range (see :attr:`steps_per_frame`).
        rho_air: Air density in kg/m³.
        c_drag: Tangential drag coefficient in kg/(m²·s).
        gravity: Gravitational acceleration in m/s².
        damping: Kelvin–Voigt damping time of the stretching stress, seconds.
        strain_limit: Largest edge stretch kept by strain limiting (heavy fabrics would
            otherwise sag on the base material's stretching table).
        perturbation_m: Largest out-of-plane offset of the seeded initial shape, metres.
        material_path: Material JSON; ``None``: the flag plugin's camel-ponte-roma.
    """

    width: float = 0.6
    height: float = 0.8
    spacing: float = 0.04
    rod_height: float = 1.5
    gather: float = 0.8
    fan_level: str = "W2"
    fan: FanSettings = field(default_factory=FanSettings)
    n_frames: int = 32
    fps: float = 25.0
    warmup_s: float = 1.0
    substeps: int | None = None
    rho_air: float = 1.2
    c_drag: float = 0.05
    gravity: float = 9.81
    damping: float = 1e-4
    strain_limit: float = 0.05
    perturbation_m: float = 0.005
    material_path: str | None = None

    def validate(self) -> None:
        """Raise :class:`UserInputError` naming the first bad setting and its valid range."""
        checks = [
            (0.05 <= self.width <= 5 and 0.05 <= self.height <= 5,
             f"fabric size must be 0.05 to 5 m per side, got {self.width} x {self.height} m"),
            (0.005 <= self.spacing <= min(self.width, self.height) / 2,
             f"spacing must be in [0.005, half the smaller side] m, got {self.spacing}"),
            (self.rod_height >= self.height, f"rod_height must be at least height = {self.height} m"),
            (0.3 <= self.gather <= 1.0, f"gather must be in [0.3, 1] (1: a flat top edge), got {self.gather}"),
            *self.timing_checks(),
            (self.rho_air >= 0 and self.c_drag >= 0 and self.gravity >= 0,
             "rho_air, c_drag and gravity must be >= 0"),
            *damping_checks(self.damping, self.strain_limit),
            (0 <= self.perturbation_m <= 0.1, f"perturbation_m must be in [0, 0.1] m, got {self.perturbation_m}"),
        ]
        require(checks)
        fan_level_index(self.fan_level)
        self.fan.validate()
        self.check_step()

    @property
    def grid(self) -> tuple[int, int]:
        """``(nu, nv)`` nodes along the width and the height."""
        return (max(3, round(self.width / self.spacing) + 1), max(3, round(self.height / self.spacing) + 1))

    @property
    def steps_per_frame(self) -> int:
        """``substeps``, or the automatic choice from the grid spacing and lightest fabric."""
        nu, nv = self.grid
        actual = max(self.width / (nu - 1), self.height / (nv - 1))
        lightest = AREA_WEIGHT_BOUNDS[0]
        return self.steps_for(
            REFERENCE_DT
            * min(actual, REFERENCE_SPACING) / REFERENCE_SPACING
            * min(1.0, math.sqrt(lightest / REFERENCE_AREA_WEIGHT))
        )


def hanging_mesh(config: HangingClothConfig) -> FlagMesh:
    """The flag solver's sheet mesh in the x–z plane, top row pinned and gathered on the rod.

    The flag builder puts u (its warp) along +x from x = 0 and v upwards with the top row
    at ``rod_height``; a hanging fabric holds that top row instead of the hoist column.
    Only the starting shape changes (the material coordinates keep the flat fabric): it is
    squeezed along x towards the middle by ``gather`` at the top, easing linearly to no
    squeeze at the hem, so the cloth starts near its drape and buckles into folds.
    """
    nu, nv = config.grid
    mesh = build_flag_mesh(
        width=config.width, height=config.height, nu=nu, nv=nv, pin_mode="edge", top_z=config.rod_height
    )
    top_row = np.arange(mesh.n_vertices) >= (nv - 1) * nu
    squeeze = 1.0 - (1.0 - config.gather) * mesh.uv[:, 1].astype(np.float64)
    start = mesh.rest.copy()
    start[:, 0] = 0.5 * config.width + (start[:, 0] - 0.5 * config.width) * squeeze
    return dataclasses.replace(mesh, rest=start, pinned=top_row)


class HangingClothSimulator(Simulator):
    """Simulates a fabric hanging from a rod in front of a fan.

    Args:
        config: Settings (fan level included); ``None`` uses the defaults.
        effects: Must be empty: the hanging cloth registers no effects.

    Raises:
        UserInputError: on bad settings or any effect.
    """

    def __init__(self, *, config: HangingClothConfig | None = None, effects: Sequence[Effect] = ()) -> None:
        if effects:
            names = ", ".join(str(getattr(e, "name", e)) for e in effects)
            raise UserInputError(f"the hanging_cloth phenomenon has no effects; drop --effect ({names})")
        self.config = config or HangingClothConfig()
        self.config.validate()
        self.parameter_space = hanging_cloth_parameter_space()
        c = self.config
        self.material: ClothMaterial = load_material(c.material_path)
        self.mesh = hanging_mesh(c)
        self.solver = cloth_solver(c, self.mesh, self.material, strain_limit_sweeps=1)
        self._offset = np.array([-0.5 * c.width, 0.0, 0.0], dtype=np.float32)
        nu, nv = c.grid
        self._extras = {
            "uv": self.mesh.uv.astype(np.float32),
            "rod": np.array([[-0.5 * c.width, 0.0, c.rod_height], [0.5 * c.width, 0.0, c.rod_height]], np.float32)
            * np.array([c.gather, 1.0, 1.0], np.float32),
            "grid_shape": np.array([nv, nu], dtype=np.int32),
        }

    def cloth_run(self, params: Params, *, seed: int = 0, fan_level: str | None = None) -> FlagRun:
        """Solver inputs of one video: θ (checked, completed), the fan's gusts for ``seed``.

        Args:
            params: θ by name.
            seed: Seed of the initial perturbation and the fan's turbulence.
            fan_level: Fan setting; ``None`` uses the configured one.

        Raises:
            UserInputError: for unknown names, values out of bounds or a bad fan level.
        """
        full = self.parameter_space.complete(params)
        c = self.config
        wind = fan_schedule(
            c.fan, level=fan_level or c.fan_level, seed=int(seed), duration=c.duration,
            z_ref=c.rod_height - 0.5 * c.height,
        )
        bending = self.material.bending * full["bending_multiplier"]
        return FlagRun(area_weight=full["area_weight"], bending=bending, wind=wind, seed=int(seed))

    def simulate(self, params: Params, *, seed: int = 0) -> Trajectory:
        """Simulate one video at the configured fan level; ``vertices`` ``(n_frames, V, 3)``.

        Raises:
            SimulationFailed: on NaN or blow-up.
            UserInputError: for bad parameters.
        """
        run = self.cloth_run(params, seed=seed)
        vertices = self.solver.run(run, warmup_frames=self.config.warmup_frames, n_frames=self.config.n_frames)
        return self._trajectory(vertices)

    def simulate_batch(self, params: Sequence[Params], *, seeds: Sequence[int]) -> list[Trajectory]:
        """Simulate ``B`` videos in parallel compiled threads; same results as :meth:`simulate`."""
        return self.simulate_videos(params, seeds=seeds, fan_levels=[self.config.fan_level] * len(params))

    def simulate_videos(
        self, params: Sequence[Params], *, seeds: Sequence[int], fan_levels: Sequence[str]
    ) -> list[Trajectory]:
        """Simulate ``B`` videos, each with its own θ, seed and fan level, in parallel threads.

        Raises:
            SimulationFailed: if any fails; the message lists the failed indices.
            UserInputError: for mismatched lengths or bad inputs.
        """
        if not len(params) == len(seeds) == len(fan_levels):
            raise UserInputError(
                f"got {len(params)} parameter sets, {len(seeds)} seeds and {len(fan_levels)} fan levels"
            )
        if not params:
            return []
        runs = [
            self.cloth_run(p, seed=s, fan_level=level) for p, s, level in zip(params, seeds, fan_levels, strict=True)
        ]
        vertices, status = self.solver.run_batch(
            runs, warmup_frames=self.config.warmup_frames, n_frames=self.config.n_frames
        )
        failures = [
            f"#{b}: {self.solver.failure_message(int(status[b, 0]), int(status[b, 1]))}"
            for b in range(len(runs))
            if int(status[b, 0]) != 0
        ]
        if failures:
            raise SimulationFailed(f"{len(failures)} of {len(runs)} cloths failed: {'; '.join(failures)}")
        return [self._trajectory(v) for v in vertices]

    def _trajectory(self, vertices: np.ndarray) -> Trajectory:
        return cloth_trajectory(vertices, self.mesh, self.config.fps, self._extras, self._offset)


def make_simulator(effects: Sequence[Effect] = (), **config: Any) -> HangingClothSimulator:
    """Factory of the phenomenon record: ``make_simulator((), fan_level="W3", n_frames=60)``.

    Raises:
        UserInputError: on an unknown setting name, a bad value, or any effect.
    """
    check_setting_names(HangingClothConfig, config, "hanging-cloth")
    return HangingClothSimulator(config=HangingClothConfig(**config), effects=effects)
