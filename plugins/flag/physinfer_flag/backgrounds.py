"""Backgrounds behind the rendered flag: procedural skies and scenes, or the user's images.

The paper draws backgrounds from SUN397; physinfer ships none, so it paints a handful of
skies (clear, cloudy, overcast, dusk) and simple scenes (hills, city, sea, trees) with
seeded numpy noise: the same name and size always give the same picture. A background
may also be any image file, and :func:`list_background_images` turns a folder of the
user's photographs into more choices for dataset generation. Backgrounds are static
images composited behind the 3D scene, like a distant backdrop seen by a fixed camera.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

import numpy as np

from physinfer.errors import UserInputError
from physinfer.video import IMAGE_SUFFIXES

# A painter returns a float (H, W, 3) image in [0, 255] given its size and a seeded RNG.
ScenePainter = Callable[[int, int, np.random.Generator], np.ndarray]


def _vertical_gradient(height: int, width: int, top: tuple[float, ...], bottom: tuple[float, ...],
                       power: float = 1.0) -> np.ndarray:
    t = (np.linspace(0.0, 1.0, height) ** power)[:, None, None]
    image = (1.0 - t) * np.asarray(top, dtype=np.float32) + t * np.asarray(bottom, dtype=np.float32)
    return np.broadcast_to(image, (height, width, 3)).astype(np.float32)


def _fractal_noise(height: int, width: int, rng: np.random.Generator, base_cells: int = 3,
                   octaves: int = 5, stretch_x: float = 1.0) -> np.ndarray:
    """Smooth value noise in [0, 1], ``(H, W)``: octaves of bilinearly upsampled grids."""
    from PIL import Image

    noise = np.zeros((height, width), dtype=np.float32)
    amplitude, total = 1.0, 0.0
    for octave in range(octaves):
        cells_y = base_cells * 2**octave
        cells_x = max(1, int(round(cells_y * width / height / stretch_x)))
        grid = rng.random((cells_y + 1, cells_x + 1)).astype(np.float32)
        layer = np.asarray(Image.fromarray(grid).resize((width, height), Image.Resampling.BICUBIC))
        noise += amplitude * layer
        total += amplitude
        amplitude *= 0.5
    noise /= total
    lo, hi = float(noise.min()), float(noise.max())
    return (noise - lo) / max(hi - lo, 1e-6)


def _clouds(sky: np.ndarray, rng: np.random.Generator, cover: float, grey: float) -> np.ndarray:
    """Blend white-grey clouds into ``sky`` where the noise exceeds ``1 - cover``."""
    h, w = sky.shape[:2]
    noise = _fractal_noise(h, w, rng, base_cells=2, stretch_x=2.0)
    alpha = np.clip((noise - (1.0 - cover)) / 0.25, 0.0, 1.0)[..., None]
    shade = 255.0 * grey - 40.0 * noise[..., None]
    return sky * (1.0 - alpha) + shade * alpha


def _sky_clear(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    return _vertical_gradient(h, w, (52, 112, 196), (170, 205, 235), power=0.8)


def _sky_cloudy(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    return _clouds(_sky_clear(h, w, rng), rng, cover=0.45, grey=0.97)


def _sky_overcast(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    sky = _vertical_gradient(h, w, (150, 155, 165), (200, 203, 208))
    return _clouds(sky, rng, cover=0.8, grey=0.8)


def _sky_dusk(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    sky = _vertical_gradient(h, w, (40, 50, 110), (250, 160, 90), power=1.4)
    return _clouds(sky, rng, cover=0.25, grey=0.75)


def _ridge(h: int, w: int, rng: np.random.Generator, level: float, roughness: float) -> np.ndarray:
    """Heights (in rows) of a skyline: a sum of random sines around ``level`` of the height."""
    x = np.linspace(0.0, 1.0, w)
    profile = np.full(w, level, dtype=np.float64)
    for k in (1, 2, 4, 8):
        profile += roughness / k * np.sin(2 * np.pi * (k * x + rng.random()))
    return profile * h


def _below(h: int, w: int, rows: np.ndarray) -> np.ndarray:
    """Mask ``(H, W)`` of pixels below the skyline ``rows`` (one row index per column)."""
    return np.arange(h)[:, None] >= rows[None, :]


def _hills(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    image = _sky_cloudy(h, w, rng)
    for level, colour in ((0.55, (96, 130, 90)), (0.68, (70, 125, 55)), (0.82, (95, 150, 60))):
        mask = _below(h, w, _ridge(h, w, rng, level, roughness=0.05))
        texture = 0.85 + 0.3 * _fractal_noise(h, w, rng, base_cells=4)
        image[mask] = (np.asarray(colour, dtype=np.float32) * texture[..., None])[mask]
    return image


def _city(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    image = _sky_clear(h, w, rng)
    x = 0
    while x < w:
        width = min(int(rng.integers(max(2, w // 14), max(3, w // 6))), w - x)
        top = int(h * rng.uniform(0.35, 0.7))
        grey = float(rng.uniform(90, 170))
        image[top:, x : x + width] = (grey, grey * 0.98, grey * 0.95)
        # Windows: a lighter grid on the facade.
        rows = np.arange(top + 3, h - 2, max(3, h // 40))
        cols = np.arange(x + 2, x + width - 1, max(3, w // 50))
        for r in rows:
            image[r, cols] = (grey + 50, grey + 50, grey + 35)
        x += width + int(rng.integers(0, max(1, w // 40)))
    image[int(0.9 * h) :] = (80, 80, 84)
    return image


def _sea(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    image = _sky_cloudy(h, w, rng)
    horizon = int(0.62 * h)
    water = _vertical_gradient(h - horizon, w, (40, 90, 130), (20, 60, 95))
    waves = _fractal_noise(h - horizon, w, rng, base_cells=6, stretch_x=6.0)
    image[horizon:] = water * (0.85 + 0.3 * waves[..., None])
    return image


def _trees(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    image = _sky_clear(h, w, rng)
    yy, xx = np.mgrid[0:h, 0:w]
    ground = int(0.78 * h)
    trees = [(rng.uniform(0, w), rng.uniform(0.45 * h, 0.7 * h), rng.uniform(0.07, 0.16) * h,
              rng.uniform(0.75, 1.25)) for _ in range(14)]
    # Trunks first, so no trunk is painted over another tree's crown.
    for cx, cy, _radius, _tone in trees:
        image[(np.abs(xx - cx) < 0.012 * w + 1) & (yy > cy) & (yy < ground)] = (80, 60, 40)
    for cx, cy, radius, tone in trees:
        crown = (xx - cx) ** 2 + ((yy - cy) * 0.8) ** 2 < radius**2
        image[crown] = np.asarray((40, 95, 40), dtype=np.float32) * tone
    grass = 0.85 + 0.3 * _fractal_noise(h - ground, w, rng, base_cells=4)
    image[ground:] = np.asarray((90, 140, 60), dtype=np.float32) * grass[..., None]
    return image


PROCEDURAL_BACKGROUNDS: dict[str, ScenePainter] = {
    "sky_clear": _sky_clear,
    "sky_cloudy": _sky_cloudy,
    "sky_overcast": _sky_overcast,
    "sky_dusk": _sky_dusk,
    "hills": _hills,
    "city": _city,
    "sea": _sea,
    "trees": _trees,
}

BACKGROUND_NAMES: tuple[str, ...] = tuple(PROCEDURAL_BACKGROUNDS)
"""Names of the procedural backgrounds."""


def background_image(spec: str | Path, size: tuple[int, int]) -> np.ndarray:
    """The background picture for a name or an image path, at the render size.

    Args:
        spec: A name from :data:`BACKGROUND_NAMES` or the path of an image file.
        size: ``(H, W)`` in pixels.

    Returns:
        ``(H, W, 3)`` uint8 RGB, read-only (cached and shared between calls).

    Raises:
        UserInputError: neither a known name nor a readable image.
    """
    height, width = int(size[0]), int(size[1])
    key = str(spec)
    if key in PROCEDURAL_BACKGROUNDS:
        return _procedural(key, height, width)
    path = Path(key).expanduser()
    if not path.is_file():
        raise UserInputError(
            f"background {key!r} is neither a procedural background ({', '.join(BACKGROUND_NAMES)}) "
            "nor an existing image file; give one of those names or the path of an image"
        )
    stat = path.stat()
    return _from_file(str(path.resolve()), stat.st_mtime_ns, stat.st_size, height, width)


@lru_cache(maxsize=32)
def _procedural(name: str, height: int, width: int) -> np.ndarray:
    # Seeded by the name only, so a background looks the same in every process.
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    image = np.clip(np.round(PROCEDURAL_BACKGROUNDS[name](height, width, rng)), 0, 255).astype(np.uint8)
    image.setflags(write=False)
    return image


@lru_cache(maxsize=32)
def _from_file(path: str, mtime_ns: int, nbytes: int, height: int, width: int) -> np.ndarray:
    # mtime and size are part of the cache key so an edited file is read again.
    from PIL import Image

    from physinfer.video import center_crop_resize

    try:
        with Image.open(path) as im:
            rgb = np.asarray(im.convert("RGB"))
    except Exception as exc:
        raise UserInputError(f"background {path}: cannot read the image ({type(exc).__name__}: {exc})") from None
    image = center_crop_resize(rgb[None], (height, width))[0]
    image = np.ascontiguousarray(image, dtype=np.uint8)
    image.setflags(write=False)
    return image


def list_background_images(folder: str | Path) -> list[str]:
    """The image files in ``folder`` (not recursive), sorted, as strings usable as ``background``.

    Raises:
        UserInputError: the folder does not exist or holds no images.
    """
    path = Path(folder).expanduser()
    if not path.is_dir():
        raise UserInputError(f"background folder {path} does not exist or is not a folder")
    files = sorted(str(p) for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise UserInputError(
            f"background folder {path} holds no images ({', '.join(sorted(IMAGE_SUFFIXES))})"
        )
    return files
