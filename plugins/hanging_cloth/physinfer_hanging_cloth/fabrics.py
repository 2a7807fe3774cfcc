"""Procedural fabric textures: plain, striped, checked, dotted and woven-looking cloth.

The fabrics of Bouman et al. are solid colours and simple prints; the renderer needs a
texture whose pattern moves with the cloth (plain colour alone hides the folds' motion
from a spectral embedder except through shading). Each texture is an RGB image drawn
with numpy from a pattern name, two colours and a repeat count; nothing is downloaded.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from physinfer.errors import UserInputError

PATTERNS: tuple[str, ...] = ("plain", "stripes", "check", "dots", "weave")
"""Pattern names :func:`fabric_texture` draws."""


def _stripes(u: np.ndarray, v: np.ndarray, repeats: float) -> np.ndarray:
    return (np.floor(u * repeats * 2) % 2).astype(bool)


def _check(u: np.ndarray, v: np.ndarray, repeats: float) -> np.ndarray:
    return ((np.floor(u * repeats * 2) + np.floor(v * repeats * 2)) % 2).astype(bool)


def _dots(u: np.ndarray, v: np.ndarray, repeats: float) -> np.ndarray:
    du = (u * repeats) % 1.0 - 0.5
    dv = (v * repeats) % 1.0 - 0.5
    return du**2 + dv**2 < 0.09


def _weave(u: np.ndarray, v: np.ndarray, repeats: float) -> np.ndarray:
    # A twill-like diagonal rib: the look of a woven fabric at a distance.
    return (np.floor((u + v) * repeats * 3) % 3 == 0)


_PAINTERS = {"stripes": _stripes, "check": _check, "dots": _dots, "weave": _weave}


def fabric_texture(
    pattern: str,
    colour: tuple[int, int, int],
    accent: tuple[int, int, int],
    repeats: float = 6.0,
    size: int = 256,
) -> np.ndarray:
    """Draw a fabric texture.

    Args:
        pattern: One of :data:`PATTERNS`.
        colour: Base RGB colour, 0–255.
        accent: RGB colour of the pattern's marks (unused by ``"plain"``).
        repeats: Pattern repeats across the texture (both directions).
        size: Side of the square image in pixels.

    Returns:
        ``(size, size, 3)`` uint8 image; row 0 is the top of the fabric (v = 1).

    Raises:
        UserInputError: for an unknown pattern or a bad colour or repeat count.
    """
    key = pattern.lower()
    if key not in PATTERNS:
        raise UserInputError(f"unknown fabric pattern {pattern!r}; choose one of: {', '.join(PATTERNS)}")
    for name, c in (("colour", colour), ("accent", accent)):
        if len(c) != 3 or not all(0 <= int(x) <= 255 for x in c):
            raise UserInputError(f"fabric {name} must be three integers in [0, 255], got {c!r}")
    if not 0.5 <= repeats <= 64:
        raise UserInputError(f"pattern repeats must be in [0.5, 64], got {repeats}")
    return _draw(key, tuple(int(x) for x in colour), tuple(int(x) for x in accent), float(repeats), int(size)).copy()


@lru_cache(maxsize=64)
def _draw(
    pattern: str, colour: tuple[int, ...], accent: tuple[int, ...], repeats: float, size: int
) -> np.ndarray:
    centres = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(centres, 1.0 - centres)
    image = np.empty((size, size, 3), dtype=np.float64)
    image[:] = colour
    if pattern != "plain":
        image[_PAINTERS[pattern](u, v, repeats)] = accent
    # A faint thread texture keeps even plain cloth from being a flat colour.
    grain = 1.0 + 0.04 * np.sin(2 * np.pi * u * size / 4) * np.sin(2 * np.pi * v * size / 4)
    return np.clip(image * grain[..., None], 0, 255).astype(np.uint8)
