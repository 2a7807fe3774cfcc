"""The flag's scene: its size and placement measured from a trajectory, the pole, the framing.

:func:`measure_flag` reads the flag's rest size, hoist and pole from a trajectory's first
frame (:class:`FlagGeometry`); :func:`pole_mesh` builds the pole and :func:`flag_camera`
the camera that frames the square a flag reaches at any wind. :func:`waving_sheet` is a
synthetic flag trajectory, a stand-in for the simulator when previewing, testing or
benchmarking the renderer. The renderer itself is :mod:`physinfer_flag.render`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.types import Trajectory
from physinfer_flag.sheet_render import fitting_distance, orbit_camera, texture_coordinates

if TYPE_CHECKING:
    from physinfer_flag.render_params import FlagRenderParams

_FRAME_HALF_SIZE = 0.68
"""Half the side of the square the automatic camera frames, in fly lengths."""

_FRAME_CENTRE_DROP = 0.5
"""How far below the hoist top the framed square is centred, in fly lengths: the square
reaches 0.18 lengths above the hoist top and 1.18 below, room for a flag flying straight
or drooping in a light wind."""


@dataclass(frozen=True)
class FlagGeometry:
    """Where the flag is, measured from a trajectory's first frame.

    Attributes:
        length: Fly length in metres (hoist to fly, along u).
        height: Hoist height in metres (along v).
        hoist_top: ``(3,)`` position of the top hoist corner.
        pole: ``(2, 3)`` bottom and top points of the pole.
        uv: ``(V, 2)`` float32 texture coordinates.
    """

    length: float
    height: float
    hoist_top: np.ndarray
    pole: np.ndarray
    uv: np.ndarray

    @property
    def look_at_target(self) -> np.ndarray:
        """``(3,)`` centre of the square the camera frames: the flag's reach at any wind."""
        return self.hoist_top + np.array([0.5, 0.0, -_FRAME_CENTRE_DROP]) * self.length


def measure_flag(trajectory: Trajectory, *, pole_height: float | None = None) -> FlagGeometry:
    """Measure the flag's rest size and placement from the first frame.

    ``pole_height`` (metres above the ground, z = 0) places the pole of a trajectory that
    carries no ``extras["pole"]``; without it such a pole reaches 3 fly lengths down.

    The size comes from edges that run mostly along u (for the length) or along v (for
    the height): the median of ``|p_i - p_j| / |Δu|`` and ``|p_i - p_j| / |Δv|``, which
    holds for a nearly unstretched sheet in any pose. Meshes without such edges fall back
    to a least-squares fit of ``|p_i - p_j|² ≈ (L·Δu)² + (H·Δv)²``.

    Raises:
        UserInputError: ``extras["uv"]`` or ``extras["pole"]`` has the wrong shape.
    """
    first = trajectory.vertices[0].astype(np.float64)
    uv = texture_coordinates(trajectory).astype(np.float64)
    length, height = _sheet_size(first, uv, trajectory.faces)
    hoist = np.flatnonzero(uv[:, 0] <= uv[:, 0].min() + 1e-3)
    hoist_top = first[hoist[np.argmax(uv[hoist, 1])]]
    pole = _pole(trajectory, hoist_top, length, pole_height)
    return FlagGeometry(length, height, hoist_top, pole, uv.astype(np.float32))


def _sheet_size(positions: np.ndarray, uv: np.ndarray, faces: np.ndarray) -> tuple[float, float]:
    """Rest length and height ``(L, H)`` in metres of a sheet from its edges (see :func:`measure_flag`)."""
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    span = np.linalg.norm(positions[edges[:, 0]] - positions[edges[:, 1]], axis=1)
    du, dv = np.abs(uv[edges[:, 0]] - uv[edges[:, 1]]).T
    along_u, along_v = du > 4.0 * dv, dv > 4.0 * du
    if along_u.sum() >= 3 and along_v.sum() >= 3:
        return float(np.median(span[along_u] / du[along_u])), float(np.median(span[along_v] / dv[along_v]))
    (l2, h2), *_ = np.linalg.lstsq(np.stack([du**2, dv**2], axis=1), span**2, rcond=None)
    extent = np.ptp(positions, axis=0)
    length = math.sqrt(l2) if l2 > 0 else float(max(extent[0], extent[2]))
    height = math.sqrt(h2) if h2 > 0 else float(extent[2])
    return length, height


def _pole(trajectory: Trajectory, hoist_top: np.ndarray, length: float, height: float | None = None) -> np.ndarray:
    if "pole" in trajectory.extras:
        pole = np.asarray(trajectory.extras["pole"], dtype=np.float64)
        if pole.shape != (2, 3):
            raise UserInputError(f"trajectory extras['pole'] must be (2, 3) bottom/top points, got {pole.shape}")
        return pole
    top = hoist_top + np.array([0.0, 0.0, 0.03 * length])
    if height is not None:  # the scene's pole, from the ground; never below the flag's top
        top[2] = max(float(height), top[2])
        return np.stack([np.array([top[0], top[1], 0.0]), top])
    bottom = np.array([top[0], top[1], min(0.0, top[2] - 3.0 * length)])
    return np.stack([bottom, top])


def pole_mesh(geometry: FlagGeometry) -> Any:
    """Shaft and ball finial, in coordinates relative to the pole's top point."""
    import pyrender
    import trimesh

    radius = 0.01 + 0.012 * geometry.length
    bottom, top = geometry.pole - geometry.pole[1]
    shaft = trimesh.creation.cylinder(radius=radius, segment=np.stack([bottom, top]), sections=16)
    finial = trimesh.creation.icosphere(subdivisions=1, radius=1.8 * radius)
    material = pyrender.MetallicRoughnessMaterial(
        baseColorFactor=[0.82, 0.82, 0.8, 1.0], metallicFactor=0.4, roughnessFactor=0.45
    )
    # One primitive, one draw call: on llvmpipe each draw costs about a millisecond.
    return pyrender.Mesh.from_trimesh(trimesh.util.concatenate([shaft, finial]), material=material)


def flag_camera(geometry: FlagGeometry, params: FlagRenderParams) -> tuple[Any, np.ndarray]:
    """Perspective camera and its pose ``(4, 4)`` for ζ around the flag's look-at target."""
    distance = params.camera_distance
    if distance is None:
        distance = fitting_distance(params.framing * _FRAME_HALF_SIZE * geometry.length, params)
    reach = distance + 3.0 * geometry.length + float(np.ptp(geometry.pole[:, 2]))
    return orbit_camera(geometry.look_at_target, distance, params, znear=max(1e-3, 0.02 * distance), zfar=2.0 * reach)


def waving_sheet(
    *,
    length: float = 1.5,
    height: float = 1.0,
    hoist_top: float = 3.0,
    n_frames: int = 30,
    fps: float = 25.0,
    amplitude: float = 0.15,
    wavelength: float = 1.0,
    frequency: float = 2.0,
    resolution: int = 20,
) -> Trajectory:
    """A synthetic flag trajectory: a travelling wave along a 2:3 sheet.

    A stand-in for the cloth simulator when previewing, testing or benchmarking the
    renderer. It follows the trajectory contract (hoist on the pole at x = y = 0, flying
    towards +x, ``extras["uv"]`` and ``extras["pole"]``). The sideways (y) and vertical
    displacement grows with the square of the distance from the hoist, like a real flag's,
    and each row of vertices keeps its length along the flag (x is integrated from the
    remaining arc length), so the sheet does not stretch as it waves.

    Args:
        length: Fly length in metres.
        height: Hoist height in metres.
        hoist_top: Height of the top hoist corner in metres.
        n_frames: Number of frames ``T``.
        fps: Frame rate.
        amplitude: Wave amplitude at the fly end, in metres (0 gives a still sheet).
        wavelength: Wave length along the flag, in metres.
        frequency: Wave frequency in Hz.
        resolution: Vertices along the height; along the length it is scaled by the
            aspect ratio.

    Returns:
        Trajectory with vertices ``(T, V, 3)`` float32 and faces ``(F, 3)`` int32.
    """
    nv = max(2, int(resolution))
    nu = max(2, int(round(resolution * length / height)))
    u, v = np.meshgrid(np.linspace(0.0, 1.0, nu), np.linspace(0.0, 1.0, nv))  # (nv, nu)
    t = np.arange(n_frames)[:, None, None] / fps
    phase = 2.0 * np.pi * (u * length / wavelength - frequency * t)
    growth = u**2
    y = amplitude * growth * np.sin(phase)
    dz = 0.3 * amplitude * growth * np.sin(phase + np.pi * v)
    # Keep each segment along u at its rest length; a steep wave shortens x instead.
    step = length / (nu - 1)
    dx2 = step**2 - np.diff(y, axis=2) ** 2 - np.diff(dz, axis=2) ** 2
    dx = np.sqrt(np.maximum(dx2, 0.1 * step**2))
    x = np.concatenate([np.zeros_like(dx[..., :1]), np.cumsum(dx, axis=2)], axis=2)
    z = hoist_top - (1.0 - v) * height + dz
    vertices = np.stack([x, y, np.broadcast_to(z, x.shape)], axis=-1).reshape(n_frames, nu * nv, 3)
    grid = np.arange(nu * nv).reshape(nv, nu)
    a, b, c, d = grid[:-1, :-1].ravel(), grid[:-1, 1:].ravel(), grid[1:, 1:].ravel(), grid[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int32)
    extras = {
        "uv": np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float32),
        "pole": np.array([[0.0, 0.0, 0.0], [0.0, 0.0, hoist_top + 0.05]], dtype=np.float32),
    }
    return Trajectory(vertices.astype(np.float32), faces, float(fps), extras)
