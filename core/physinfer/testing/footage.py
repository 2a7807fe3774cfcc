"""Footage-like test material: a static, photo-like background to composite a subject into,
for testing framing (``physinfer prepare``) on videos whose answer is known."""

from __future__ import annotations

import functools

import numpy as np


@functools.cache
def textured_background(height: int, width: int, seed: int) -> np.ndarray:
    """A static, photo-like ``(height, width, 3)`` uint8 image: noise at several scales,
    gray levels 40-220 (the same for the same arguments; cached and read-only)."""
    from PIL import Image

    rng = np.random.default_rng(seed)
    image = np.zeros((height, width, 3), np.float32)
    for scale in (1, 4, 16, 48):  # coarse noise fields, upsampled smoothly
        field = rng.normal(size=(height // scale + 2, width // scale + 2, 3)).astype(np.float32)
        image += scale**0.5 * np.stack(
            [np.asarray(Image.fromarray(field[..., c]).resize((width, height), Image.Resampling.BICUBIC))
             for c in range(3)], axis=-1,
        )  # fmt: skip
    image = (image - image.min()) / np.ptp(image)
    out = (40 + 180 * image).astype(np.uint8)
    out.setflags(write=False)  # shared by the cache: callers copy before drawing on it
    return out
