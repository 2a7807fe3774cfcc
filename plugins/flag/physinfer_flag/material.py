"""The cloth material of the flag: Wang et al. 2011 data-driven tables, as ArcSim reads them.

A :class:`ClothMaterial` holds the three tables of a material file such as the shipped
``data/camel-ponte-roma.json``: area density (kg/m²), the 3×5 bending table (N·m; rows:
bending direction 0°, 45°, 90° to the warp; columns: half-curvature samples 0, 5, 10, 15,
20 m⁻¹) and the 6×4 stretching table (N/m; row 0: the strain-0 sample ``[C11, C12, C22,
shear]`` for every direction; rows 1–5: the samples at principal stretch 1 + 1/6 for
principal directions 0°, 22.5°, 45°, 67.5°, 90°). This module also names the 15 bending
multipliers of θ and turns a parameter set into the scaled bending table the solver uses.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from physinfer.errors import UserInputError

#: Bending directions of the table rows, degrees from the warp.
BEND_DIRECTIONS_DEG: tuple[int, ...] = (0, 45, 90)
#: Half-curvature samples of the table columns, 1/m (ArcSim: "per 0.05 cm⁻¹").
HALF_CURVATURE_SAMPLES: tuple[int, ...] = (0, 5, 10, 15, 20)
#: Principal-direction samples of the stretching rows 1–5, degrees from the warp.
STRETCH_DIRECTIONS_DEG: tuple[float, ...] = (0.0, 22.5, 45.0, 67.5, 90.0)
#: Principal stretch of the stretching rows 1–5 (strain 1/6).
STRETCH_SAMPLE_STRAIN = 1.0 / 6.0

SHIPPED_MATERIAL = "camel-ponte-roma"


def bending_parameter_names() -> list[str]:
    """The 15 bending-multiplier names, direction-major: ``bend_0deg_c00`` … ``bend_90deg_c20``.

    ``{d}deg`` is the bending direction to the warp and ``c{cc}`` the half-curvature sample
    in 1/m, so ``bend_45deg_c10`` scales the stiffness of a 45° fold at half-curvature 10 m⁻¹.
    """
    return [f"bend_{d}deg_c{c:02d}" for d in BEND_DIRECTIONS_DEG for c in HALF_CURVATURE_SAMPLES]


@dataclass(frozen=True)
class ClothMaterial:
    """A Wang et al. 2011 cloth material.

    Attributes:
        name: Identifier, e.g. ``"camel-ponte-roma"``.
        density: Area density in kg/m² (the flag's θ replaces it by ``area_weight``).
        bending: ``(3, 5)`` bending stiffness in N·m, rows = direction, columns = half-curvature.
        stretching: ``(6, 4)`` stretching stiffness in N/m as in the material file.
    """

    name: str
    density: float
    bending: np.ndarray
    stretching: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "bending", np.asarray(self.bending, dtype=np.float64))
        object.__setattr__(self, "stretching", np.asarray(self.stretching, dtype=np.float64))
        self.validate()

    def validate(self) -> None:
        """Raise :class:`UserInputError` if a table has the wrong shape or bad values."""
        if self.bending.shape != (3, 5):
            raise UserInputError(f"material {self.name!r}: bending must be 3x5, got {self.bending.shape}")
        if self.stretching.shape != (6, 4):
            raise UserInputError(f"material {self.name!r}: stretching must be 6x4, got {self.stretching.shape}")
        if not (np.isfinite(self.bending).all() and np.isfinite(self.stretching).all()):
            raise UserInputError(f"material {self.name!r}: tables must be finite numbers")
        if not (np.isfinite(self.density) and self.density > 0):
            raise UserInputError(f"material {self.name!r}: density must be positive, got {self.density}")
        if (self.bending < 0).any():
            raise UserInputError(f"material {self.name!r}: bending stiffness must not be negative")

    def stretching_samples(self) -> np.ndarray:
        """The stretching table as ArcSim samples it: ``(2, 5, 4)`` N/m.

        Index ``[strain, direction, component]``: strain 0 repeats row 0 of the file for
        every direction; strain 1/6 holds rows 1–5.
        """
        out = np.empty((2, 5, 4))
        out[0] = self.stretching[0]
        out[1] = self.stretching[1:]
        return out


def load_material(path: str | Path | None = None) -> ClothMaterial:
    """Read a material file (JSON with ``density``, ``bending``, ``stretching``).

    Args:
        path: A JSON file; ``None`` reads the shipped camel-ponte-roma.

    Raises:
        UserInputError: when the file is missing, not JSON, or its tables are malformed.
    """
    try:
        if path is None:
            text = resources.files("physinfer_flag").joinpath(f"data/{SHIPPED_MATERIAL}.json").read_text()
            name = SHIPPED_MATERIAL
        else:
            text = Path(path).read_text()
            name = Path(path).stem
        data = json.loads(text)
        return ClothMaterial(
            name=str(data.get("name", name)),
            density=float(data["density"]),
            bending=np.asarray(data["bending"], dtype=np.float64),
            stretching=np.asarray(data["stretching"], dtype=np.float64),
        )
    except (OSError, json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, UserInputError):
            raise
        raise UserInputError(
            f"cannot read cloth material {path or SHIPPED_MATERIAL}: {exc}; "
            "expected JSON with 'density', 'bending' (3x5) and 'stretching' (6x4)"
        ) from None


def bending_multipliers(params: Mapping[str, float]) -> np.ndarray:
    """The 15 bending multipliers of a parameter set as a ``(3, 5)`` array.

    Args:
        params: Values by name; must contain every name of :func:`bending_parameter_names`.

    Raises:
        UserInputError: when a multiplier is missing or not positive.
    """
    names = bending_parameter_names()
    missing = [n for n in names if n not in params]
    if missing:
        raise UserInputError(f"missing bending multipliers: {', '.join(missing)}")
    mult = np.array([float(params[n]) for n in names]).reshape(3, 5)
    if not (np.isfinite(mult).all() and (mult > 0).all()):
        raise UserInputError("bending multipliers must be positive finite numbers")
    return mult


def scaled_bending(material: ClothMaterial, multipliers: np.ndarray) -> np.ndarray:
    """Bending table with each of its 15 entries scaled by its own multiplier, ``(3, 5)`` N·m."""
    multipliers = np.asarray(multipliers, dtype=np.float64)
    if multipliers.shape != (3, 5):
        raise UserInputError(f"bending multipliers must be 3x5, got {multipliers.shape}")
    return material.bending * multipliers


def bending_length(material: ClothMaterial, area_weight: float, gravity: float = 9.81) -> float:
    """Bending length ``(B / (ρ_A g))^(1/3)`` in metres from the table's mean stiffness.

    The length below which bending beats gravity; the mesh must resolve it for the bending
    multipliers to matter.
    """
    return float((material.bending.mean() / (area_weight * gravity)) ** (1.0 / 3.0))
