"""The hanging-cloth renderer: a trajectory and render parameters ζ → a video clip (pyrender).

In the style of Bouman et al.'s videos: the fabric, textured and lit from the front, in
front of a plain backdrop, seen by a fixed camera; a thin rod holds its top edge. The
flag renderer's machinery is reused — its double-sided sheet buffers, its diffuse
(Lambert) mesh shaders and its compositing over a background image — and each frame
only re-uploads the cloth's vertices. Headless through EGL and deterministic for fixed ζ.

Coordinates follow :mod:`physinfer_hanging_cloth.simulator`: metres, z up, the rod along
x, the fan blowing along +y. Azimuth 0 looks at the fabric face-on along +y from the
fan's side; the default looks from 30° to the side so that the fabric's blow-back shows
in the image.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from physinfer.errors import UserInputError
from physinfer.rendering import OffscreenContext
from physinfer.roles import Renderer
from physinfer.settings import check_range
from physinfer.types import Clip, Trajectory
from physinfer_flag.sheet_render import (
    DoubleSidedSheet,
    SheetViewParams,
    add_camera_and_sun,
    check_renderable,
    check_view,
    context_of_size,
    fabric_material,
    fitting_distance,
    orbit_camera,
    render_sheet,
    sheet_scene,
    texture_coordinates,
)
from physinfer_hanging_cloth.fabrics import PATTERNS, fabric_texture

TEXTURE_SIZE = 256
"""Texture side in pixels."""

Colour = tuple[int, int, int]


@dataclass(frozen=True)
class HangingRenderParams(SheetViewParams):
    """Render parameters ζ of :class:`HangingClothRenderer`; every field is a ζ key.

    Attributes:
        image_size: Output size in pixels: one int (square) or ``(H, W)``.
        framing: Multiplier of the automatic camera distance (> 1 shows more backdrop).
        camera_azimuth_deg: Horizontal angle of the camera around the fabric; 0 is
            face-on from the fan's side, positive moves it towards +x. In ``[-75, 75]``.
        camera_elevation_deg: Angle of the camera above the fabric's middle, ``[-45, 45]``.
        fov_deg: Vertical field of view in degrees, in ``(5, 120)``.
        light_direction: ``(3,)`` direction the key light travels (default: from above,
            behind the camera, slightly from the left).
        light_intensity: Directional light intensity (pyrender units, ``>= 0``).
        ambient_intensity: Ambient light in ``[0, 1]``.
        pattern: Fabric print, one of :data:`physinfer_hanging_cloth.fabrics.PATTERNS`.
        fabric_colour: Base RGB colour of the fabric, 0–255.
        accent_colour: RGB colour of the print's marks.
        pattern_repeats: Print repeats across the fabric.
        backdrop_colour: RGB colour of the plain backdrop.
        rod: Draw the rod.
    """

    settings_owner: ClassVar[str] = "hanging-cloth"

    image_size: int | tuple[int, int] = 224
    framing: float = 1.0
    camera_azimuth_deg: float = 30.0
    camera_elevation_deg: float = 0.0
    fov_deg: float = 40.0
    light_direction: tuple[float, float, float] = (0.3, 0.8, -0.5)
    light_intensity: float = 2.5
    ambient_intensity: float = 0.35
    pattern: str = "check"
    fabric_colour: Colour = (70, 90, 160)
    accent_colour: Colour = (225, 220, 205)
    pattern_repeats: float = 5.0
    backdrop_colour: Colour = (232, 232, 226)
    rod: bool = True

    def validate(self) -> None:
        """Check every value; raises :class:`UserInputError` naming the offending key."""
        check_view(self)
        check_range("camera_azimuth_deg", self.camera_azimuth_deg, -75.0, 75.0)
        if self.pattern.lower() not in PATTERNS:
            raise UserInputError(f"pattern={self.pattern!r} is unknown; choose one of: {', '.join(PATTERNS)}")
        for key in ("fabric_colour", "accent_colour", "backdrop_colour"):
            colour = getattr(self, key)
            if len(colour) != 3 or not all(0 <= c <= 255 for c in colour):
                raise UserInputError(f"{key}={colour!r}: give three integers in [0, 255]")
        check_range("pattern_repeats", self.pattern_repeats, 0.5, 64.0)


def sample_fabric_look(rng: np.random.Generator) -> dict[str, Any]:
    """A random print and colours for one fabric (same for all its videos).

    Returns:
        ζ keys ``pattern``, ``fabric_colour``, ``accent_colour``, ``pattern_repeats``.
    """
    hue_colour = rng.integers(30, 220, size=3)
    accent = np.clip(255 - hue_colour + rng.integers(-30, 30, size=3), 0, 255)
    return {
        "pattern": str(PATTERNS[int(rng.integers(len(PATTERNS)))]),
        "fabric_colour": [int(c) for c in hue_colour],
        "accent_colour": [int(c) for c in accent],
        "pattern_repeats": float(rng.uniform(3.0, 9.0)),
    }


class HangingClothRenderer(Renderer):
    """pyrender renderer of hanging-cloth trajectories (ζ: :class:`HangingRenderParams`).

    One EGL context is created on first use and kept (a new one only when ζ asks for
    another image size); call :meth:`close` to release it.
    """

    default_render_params: Mapping[str, Any] = MappingProxyType(HangingRenderParams().to_dict())

    def __init__(self) -> None:
        self._context: OffscreenContext | None = None

    def render(self, trajectory: Trajectory, render_params: Mapping[str, Any] | None = None) -> Clip:
        """Render every frame of ``trajectory``.

        Args:
            trajectory: Cloth trajectory (see :mod:`physinfer_hanging_cloth.simulator`);
                ``extras["uv"]`` ``(V, 2)`` is used when present, ``extras["rod"]`` ``(2, 3)``
                for the rod.
            render_params: ζ; missing keys take :attr:`default_render_params`.

        Returns:
            Clip of ``(T, H, W, 3)`` uint8 frames at ``trajectory.fps``.

        Raises:
            UserInputError: invalid ζ, a trajectory without frames or with NaN, bad extras.
        """
        params = HangingRenderParams.from_mapping(render_params)
        check_renderable(trajectory)
        height, width = params.size
        uv = texture_coordinates(trajectory)
        sheet = DoubleSidedSheet(trajectory.faces, trajectory.vertices.shape[1])
        scene, cloth = self._build_scene(trajectory, uv, sheet, params)
        backdrop = _backdrop(params.backdrop_colour, (height, width))
        return render_sheet(self._context_for(width, height), scene, cloth, sheet, trajectory, backdrop)

    def sample_render_params(self, rng: np.random.Generator) -> dict[str, Any]:
        """A random ζ: the fabric's look, the camera angle and the light."""
        params = {
            **self.default_render_params,
            **sample_fabric_look(rng),
            "camera_azimuth_deg": float(rng.uniform(15.0, 45.0)),
            "camera_elevation_deg": float(rng.uniform(-10.0, 10.0)),
            "light_intensity": float(rng.uniform(2.0, 3.2)),
        }
        return HangingRenderParams.from_mapping(params).to_dict()

    def close(self) -> None:
        """Release the EGL context."""
        if self._context is not None:
            self._context.close()
            self._context = None

    def _context_for(self, width: int, height: int) -> OffscreenContext:
        self._context = context_of_size(self._context, width, height)
        return self._context

    def _build_scene(
        self, trajectory: Trajectory, uv: np.ndarray, sheet: DoubleSidedSheet, params: HangingRenderParams
    ) -> tuple[Any, Any]:
        """The scene of one trajectory and the cloth primitive whose vertices move."""
        image = fabric_texture(
            params.pattern, params.fabric_colour, params.accent_colour, params.pattern_repeats, TEXTURE_SIZE
        )
        material = fabric_material(image, roughness=0.9)
        scene, cloth = sheet_scene(sheet, trajectory.vertices[0], uv, material, params)
        rod = _rod_points(trajectory)
        if params.rod:
            pose = np.eye(4)
            pose[:3, 3] = rod.mean(axis=0)  # a fixed node origin keeps pyrender's draw order stable
            scene.add(_rod_mesh(rod), pose=pose)
        add_camera_and_sun(scene, *_camera(trajectory, rod, params), params)
        return scene, cloth


def _rod_points(trajectory: Trajectory) -> np.ndarray:
    """``(2, 3)`` rod ends from extras, or the top of the first frame."""
    if "rod" in trajectory.extras:
        rod = np.asarray(trajectory.extras["rod"], dtype=np.float64)
        if rod.shape != (2, 3):
            raise UserInputError(f"trajectory extras['rod'] must be (2, 3) end points, got {rod.shape}")
        return rod
    first = trajectory.vertices[0].astype(np.float64)
    top = first[:, 2].max()
    return np.array([[first[:, 0].min(), first[:, 1].mean(), top], [first[:, 0].max(), first[:, 1].mean(), top]])


def _rod_mesh(rod: np.ndarray) -> Any:
    """A thin metal cylinder around the origin (the node pose places it), a little longer
    than the gathered top edge."""
    import pyrender
    import trimesh

    half = 0.5 * (rod[1] - rod[0]) * 1.15
    shaft = trimesh.creation.cylinder(radius=0.008, segment=np.stack([-half, half]), sections=12)
    material = pyrender.MetallicRoughnessMaterial(
        baseColorFactor=[0.55, 0.55, 0.55, 1.0], metallicFactor=0.3, roughnessFactor=0.5
    )
    return pyrender.Mesh.from_trimesh(shaft, material=material)


def hanging_length(trajectory: Trajectory) -> float:
    """The fabric's rest length from rod to hem, in metres, whatever its pose.

    With ``extras["uv"]``: the median over mesh edges running along v (the hanging
    direction) of ``|p_i - p_j| / |Δv|`` in the first frame — a nearly inextensible sheet
    keeps it in any pose, so the camera, framed from it, does not move with the motion.
    Without uv: the first frame's vertical extent.
    """
    first = trajectory.vertices[0].astype(np.float64)
    if "uv" in trajectory.extras:
        uv = texture_coordinates(trajectory).astype(np.float64)
        faces = trajectory.faces
        edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        du, dv = np.abs(uv[edges[:, 0]] - uv[edges[:, 1]]).T
        along_v = dv > 4.0 * du
        if along_v.any():
            span = np.linalg.norm(first[edges[along_v, 0]] - first[edges[along_v, 1]], axis=1)
            return float(np.median(span / dv[along_v]))
    return max(float(np.ptp(first[:, 2])), 1e-3)


def _camera(trajectory: Trajectory, rod: np.ndarray, params: HangingRenderParams) -> tuple[Any, np.ndarray]:
    """Perspective camera and its pose ``(4, 4)``: frames the fabric's reach at any fan speed.

    The framed square is centred below the rod's middle by half the fabric's hanging
    length and a quarter of it downwind (+y), with a half side of 0.72 hanging lengths:
    room for the rod and for a light fabric blown up at the strongest fan.
    """
    length = hanging_length(trajectory)
    target = rod.mean(axis=0) + np.array([0.0, 0.25 * length, -0.5 * length])
    distance = fitting_distance(params.framing * 0.72 * length, params)
    return orbit_camera(
        target, distance, params, znear=max(1e-3, 0.05 * distance), zfar=4.0 * distance + 4.0 * length
    )


def _backdrop(colour: Colour, size: tuple[int, int]) -> np.ndarray:
    """``(H, W, 3)`` uint8 plain backdrop, a touch darker at the bottom as a lit wall is."""
    height, width = size
    shade = np.linspace(1.0, 0.9, height)[:, None, None]
    image = np.broadcast_to(np.asarray(colour, dtype=np.float64) * shade, (height, width, 3))
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)
