"""Units of the Bouman et al. ground truth and the simulator's stiffness convention.

The hanging-fabric ground truth is imperial: area weight in oz/yd² and bending stiffness
in lbf·in² (two orthogonal measurements per fabric). The simulator works in SI (kg/m²)
and scales the camel-ponte-roma bending table by one multiplier. This module parses the
unit strings of a ground-truth table, converts values to the canonical units (oz/yd²,
lbf·in²), and maps a stiffness to the multiplier and back.

The stiffness ↔ multiplier map is a convention of the synthetic data, not a measured
fact: stiffness is proportional to the multiplier, and the geometric middle of the real
fabrics' range (0.027 lbf·in²) is multiplier :data:`MIDDLE_MULTIPLIER` = 6. On the
solver's mesh the continuum rigidity is about a quarter of the table value (about
9e-6 N·m for the base material, docs/flag-physics.md), so multiplier 6 at the middle
area weight (6.5 oz/yd²) has a bending length ``(B / (ρ_A g))^(1/3)`` of about 3 cm, and
the real range spans about 1.4 cm (limp, heavy) to 7 cm (stiff, light) — the bending
lengths of apparel fabrics. Pearson R on logarithms is unchanged by any proportional
convention.
"""

from __future__ import annotations

import math
import re

from physinfer.errors import UserInputError

#: 1 oz/yd² in g/m² (DESIGN.md).
OZ_PER_YD2_IN_G_PER_M2 = 33.905747
#: 1 lbf·in² in N·m² (DESIGN.md).
LBF_IN2_IN_N_M2 = 2.8698e-3

#: Spread of the 30 real fabrics (DESIGN.md): area weight in oz/yd², stiffness in lbf·in².
REAL_AREA_WEIGHT_OZ_YD2 = (1.7, 16.7)
REAL_STIFFNESS_LBF_IN2 = (0.0075, 0.1)

#: Bending multiplier standing for the geometric middle of the real stiffness range.
MIDDLE_MULTIPLIER = 6.0
#: Stiffness (lbf·in²) that the base material, bending multiplier 1, stands for.
REFERENCE_STIFFNESS_LBF_IN2 = math.sqrt(REAL_STIFFNESS_LBF_IN2[0] * REAL_STIFFNESS_LBF_IN2[1]) / MIDDLE_MULTIPLIER

# Factors to the canonical unit of each quantity; keys are normalised spellings.
_AREA_WEIGHT_UNITS = {
    "oz/yd^2": 1.0,
    "g/m^2": 1.0 / OZ_PER_YD2_IN_G_PER_M2,
    "gsm": 1.0 / OZ_PER_YD2_IN_G_PER_M2,
    "kg/m^2": 1000.0 / OZ_PER_YD2_IN_G_PER_M2,
}
_STIFFNESS_UNITS = {
    "lbf*in^2": 1.0,
    "n*m^2": 1.0 / LBF_IN2_IN_N_M2,
    "mn*m^2": 1e-3 / LBF_IN2_IN_N_M2,
    "un*m^2": 1e-6 / LBF_IN2_IN_N_M2,
}
CANONICAL_UNITS = {"area_weight": "oz/yd^2", "stiffness": "lbf*in^2"}


def normalise_unit(text: str) -> str:
    """A unit string in one spelling: lower case, ``·``/space → ``*``, ``²`` → ``^2``.

    ``"oz/yd²"``, ``"OZ / YD^2"`` → ``"oz/yd^2"``; ``"lbf·in²"``, ``"lbf in^2"`` →
    ``"lbf*in^2"``; ``"µN·m²"`` → ``"un*m^2"``.
    """
    unit = text.strip().lower().replace("²", "^2").replace("µ", "u").replace("μ", "u")
    unit = re.sub(r"\s*([/*·.])\s*", r"\1", unit)
    unit = re.sub(r"[·.\s]+", "*", unit)
    unit = re.sub(r"([a-z])2\b", r"\1^2", unit)  # "g/m2" as often typed in spreadsheets
    return unit.replace("**", "^")


def unit_factor(quantity: str, unit: str) -> float:
    """Factor converting ``unit`` to the canonical unit of ``quantity``.

    Args:
        quantity: ``"area_weight"`` or ``"stiffness"``.
        unit: The table's unit string, any spelling :func:`normalise_unit` understands.

    Raises:
        UserInputError: for a unit that is not a unit of that quantity.
    """
    table = _AREA_WEIGHT_UNITS if quantity == "area_weight" else _STIFFNESS_UNITS
    key = normalise_unit(unit)
    if key not in table:
        raise UserInputError(
            f"unknown {quantity.replace('_', ' ')} unit {unit!r}; use one of: {', '.join(table)}"
        )
    return table[key]


def oz_yd2_to_kg_m2(value: float) -> float:
    """Area weight oz/yd² → kg/m²."""
    return value * OZ_PER_YD2_IN_G_PER_M2 / 1000.0


def kg_m2_to_oz_yd2(value: float) -> float:
    """Area weight kg/m² → oz/yd²."""
    return value * 1000.0 / OZ_PER_YD2_IN_G_PER_M2


def stiffness_to_multiplier(stiffness_lbf_in2: float) -> float:
    """Bending multiplier of the base material that stands for a stiffness in lbf·in²."""
    return stiffness_lbf_in2 / REFERENCE_STIFFNESS_LBF_IN2


def multiplier_to_stiffness(multiplier: float) -> float:
    """Stiffness in lbf·in² that a bending multiplier stands for."""
    return multiplier * REFERENCE_STIFFNESS_LBF_IN2
