"""Procedural national-flag textures for the flag renderer.

Every design is a simple geometric pattern (stripes, Nordic crosses, discs, a triangle,
a canton) drawn with numpy on a 2:3 canvas, the aspect ratio the paper fixes for FlagSim;
nothing is downloaded. Designs whose official ratio differs (Denmark, Norway, Belgium...)
are stretched proportionally onto 2:3, as a printed 2:3 flag of that country would be.
Images follow the usual picture convention: row 0 is the top of the flag, column 0 the
hoist (pole side), so texture coordinate ``u`` runs along columns and ``v`` up the rows.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np

from physinfer.errors import UserInputError

Colour = tuple[int, int, int]
# A drawing function paints into a float canvas (H, W, 3) given pixel-centre
# coordinates x (fraction of the length from the hoist) and y (fraction of the height
# from the top), both (H, W) arrays in [0, 1].
Painter = Callable[[np.ndarray, np.ndarray, np.ndarray], None]

RED: Colour = (200, 16, 46)
WHITE: Colour = (255, 255, 255)
BLUE: Colour = (0, 56, 147)
BLACK: Colour = (0, 0, 0)
GOLD: Colour = (255, 206, 0)


def _horizontal(*colours: Colour, weights: tuple[float, ...] | None = None) -> Painter:
    """Horizontal stripes from top to bottom with relative heights ``weights``."""
    w = np.asarray(weights if weights is not None else [1.0] * len(colours), dtype=float)
    edges = np.concatenate([[0.0], np.cumsum(w) / w.sum()])

    def paint(canvas: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        for colour, top, bottom in zip(colours, edges[:-1], edges[1:], strict=True):
            canvas[(y >= top) & (y < bottom)] = colour

    return paint


def _vertical(*colours: Colour) -> Painter:
    """Equal vertical stripes from hoist to fly."""
    edges = np.linspace(0.0, 1.0, len(colours) + 1)

    def paint(canvas: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        for colour, left, right in zip(colours, edges[:-1], edges[1:], strict=True):
            canvas[(x >= left) & (x < right)] = colour

    return paint


def _nordic(field: Colour, cross: Colour, xs: tuple[float, ...], ys: tuple[float, ...],
            inner: Colour | None = None, inner_xs: tuple[float, ...] = (),
            inner_ys: tuple[float, ...] = ()) -> Painter:
    """Off-centre Nordic cross; ``xs``/``ys`` are the official segment lengths.

    ``xs = (hoist field, cross, fly field)`` along the length and ``ys = (top, cross,
    bottom)`` along the height. ``inner`` draws a narrower cross inside (Norway).
    """

    def band(lengths: tuple[float, ...]) -> tuple[float, float]:
        total = sum(lengths)
        return lengths[0] / total, (lengths[0] + lengths[1]) / total

    def paint(canvas: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        canvas[...] = field
        (x0, x1), (y0, y1) = band(xs), band(ys)
        canvas[((x >= x0) & (x < x1)) | ((y >= y0) & (y < y1))] = cross
        if inner is not None:
            (x0, x1), (y0, y1) = band(inner_xs), band(inner_ys)
            canvas[((x >= x0) & (x < x1)) | ((y >= y0) & (y < y1))] = inner

    return paint


def _disc(field: Colour, disc: Colour, centre_x: float, diameter_of_height: float) -> Painter:
    """A disc on a plain field; the disc is round on a 2:3 canvas."""

    def paint(canvas: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
        canvas[...] = field
        radius = diameter_of_height / 2.0
        # x is a fraction of the length (1.5 heights); measure both in heights.
        inside = ((x - centre_x) * 1.5) ** 2 + (y - 0.5) ** 2 < radius**2
        canvas[inside] = disc

    return paint


def _czechia(canvas: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    canvas[...] = WHITE
    canvas[y >= 0.5] = (215, 20, 26)
    canvas[x < 0.5 * (1.0 - np.abs(2.0 * y - 1.0))] = (17, 69, 126)


def _greece(canvas: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    blue = (13, 94, 175)
    _horizontal(*([blue, WHITE] * 4 + [blue]))(canvas, x, y)
    # The canton is a square five stripes tall; the white cross is one stripe wide.
    side_y, side_x = 5.0 / 9.0, (5.0 / 9.0) / 1.5
    canton = (x < side_x) & (y < side_y)
    canvas[canton] = blue
    cross_y = (y >= 2.0 / 9.0) & (y < 3.0 / 9.0)
    cross_x = (x >= 2.0 / 9.0 / 1.5) & (x < 3.0 / 9.0 / 1.5)
    canvas[canton & (cross_x | cross_y)] = WHITE


FLAG_DESIGNS: dict[str, Painter] = {
    "netherlands": _horizontal((174, 28, 40), WHITE, (33, 70, 139)),
    "germany": _horizontal(BLACK, (221, 0, 0), GOLD),
    "russia": _horizontal(WHITE, (0, 57, 166), (213, 43, 30)),
    "austria": _horizontal((237, 41, 57), WHITE, (237, 41, 57)),
    "poland": _horizontal(WHITE, (220, 20, 60)),
    "ukraine": _horizontal((0, 87, 183), (255, 215, 0)),
    "colombia": _horizontal((252, 209, 22), (0, 56, 147), (206, 17, 38), weights=(2, 1, 1)),
    "thailand": _horizontal((165, 25, 49), WHITE, (45, 42, 74), WHITE, (165, 25, 49),
                            weights=(1, 1, 2, 1, 1)),
    "france": _vertical((0, 35, 149), WHITE, (237, 41, 57)),
    "italy": _vertical((0, 146, 70), WHITE, (206, 43, 55)),
    "ireland": _vertical((22, 155, 98), WHITE, (255, 136, 62)),
    "belgium": _vertical(BLACK, (253, 218, 36), (239, 51, 64)),
    "japan": _disc(WHITE, (188, 0, 45), centre_x=0.5, diameter_of_height=0.6),
    "bangladesh": _disc((0, 106, 78), (244, 42, 65), centre_x=0.45, diameter_of_height=0.6),
    "sweden": _nordic((0, 106, 167), (254, 204, 0), xs=(5, 2, 9), ys=(4, 2, 4)),
    "denmark": _nordic((200, 16, 46), WHITE, xs=(12, 4, 21), ys=(12, 4, 12)),
    "finland": _nordic(WHITE, (0, 47, 108), xs=(5, 3, 10), ys=(4, 3, 4)),
    "norway": _nordic((186, 12, 47), WHITE, xs=(6, 4, 12), ys=(6, 4, 6),
                      inner=(0, 32, 91), inner_xs=(7, 2, 13), inner_ys=(7, 2, 7)),
    "czechia": _czechia,
    "greece": _greece,
}

FLAG_NAMES: tuple[str, ...] = tuple(sorted(FLAG_DESIGNS))
"""Names accepted by :func:`flag_texture`, sorted."""

_SUPERSAMPLE = 3


def flag_texture(name: str, height: int = 256) -> np.ndarray:
    """Draw a national flag at aspect ratio 2:3.

    Edges of discs, triangles and stripes are anti-aliased by supersampling, so the
    texture does not shimmer when the cloth moves.

    Args:
        name: One of :data:`FLAG_NAMES` (case-insensitive).
        height: Image height in pixels; the width is ``round(1.5 * height)``.

    Returns:
        ``(height, round(1.5 * height), 3)`` uint8 RGB, row 0 the top edge, column 0
        the hoist. The array is read-only and shared between calls.

    Raises:
        UserInputError: unknown name or a height below 2 pixels.
    """
    key = name.lower().strip()
    if key not in FLAG_DESIGNS:
        raise UserInputError(f"unknown flag texture {name!r}; choose one of: {', '.join(FLAG_NAMES)}")
    if int(height) < 2:
        raise UserInputError(f"flag texture height must be at least 2 pixels, got {height}")
    return _draw(key, int(height))


@lru_cache(maxsize=64)
def _draw(name: str, height: int) -> np.ndarray:
    width = int(round(1.5 * height))
    s = _SUPERSAMPLE
    ys = (np.arange(height * s) + 0.5) / (height * s)
    xs = (np.arange(width * s) + 0.5) / (width * s)
    x, y = np.meshgrid(xs, ys)
    canvas = np.zeros((height * s, width * s, 3), dtype=np.float32)
    FLAG_DESIGNS[name](canvas, x, y)
    image = canvas.reshape(height, s, width, s, 3).mean(axis=(1, 3))
    out = np.clip(np.round(image), 0, 255).astype(np.uint8)
    out.setflags(write=False)
    return out
