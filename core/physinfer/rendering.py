"""Headless pyrender helpers shared by every plugin's renderer.

pyrender picks its OpenGL platform when first imported, from ``PYOPENGL_PLATFORM``:
:func:`use_headless_gl` sets it to ``egl`` (Mesa's llvmpipe on CPU machines, NVIDIA's
EGL on GPU machines) unless the user chose another. Creating an EGL context costs about
half a second, so :class:`OffscreenContext` keeps one per renderer and reuses it.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np


def use_headless_gl() -> None:
    """Select EGL for PyOpenGL unless ``PYOPENGL_PLATFORM`` is already set."""
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = np.array([0.0, 0.0, 1.0])) -> np.ndarray:
    """Camera pose (4, 4) for pyrender (camera looks down its -z axis) at ``eye`` towards ``target``."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:  # looking straight along `up`
        right = np.cross(forward, np.array([1.0, 0.0, 0.0]))
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, true_up, -forward, eye
    return pose


def spherical_camera(
    target: np.ndarray, distance: float, azimuth_deg: float, elevation_deg: float
) -> np.ndarray:
    """Camera pose on a sphere around ``target``; azimuth 0° looks along +x, z is up."""
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    direction = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return look_at(np.asarray(target) - distance * direction, target)


class OffscreenContext:
    """A lazily created, reusable ``pyrender.OffscreenRenderer`` of a fixed size.

    Args:
        width: Viewport width in pixels.
        height: Viewport height in pixels.
    """

    def __init__(self, width: int, height: int) -> None:
        self.width, self.height = width, height
        self._renderer: Any = None

    def render(self, scene: Any) -> np.ndarray:
        """Render ``scene``; returns ``(H, W, 3)`` uint8 RGB."""
        if self._renderer is None:
            use_headless_gl()
            import pyrender

            try:
                self._renderer = pyrender.OffscreenRenderer(self.width, self.height)
            except Exception as exc:
                from physinfer.errors import PhysinferError

                raise PhysinferError(
                    f"cannot create a headless OpenGL context ({type(exc).__name__}: {exc}). "
                    "Install Mesa's EGL (Debian: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri) "
                    "and keep PYOPENGL_PLATFORM=egl."
                ) from None
        color, _depth = self._renderer.render(scene)
        return np.ascontiguousarray(color[..., :3])

    def close(self) -> None:
        """Release the EGL context."""
        if self._renderer is not None:
            self._renderer.delete()
            self._renderer = None

    def __del__(self) -> None:  # pragma: no cover - best effort at interpreter exit
        try:
            self.close()
        except Exception:
            pass
