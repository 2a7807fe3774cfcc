"""The flag renderer: a cloth trajectory and render parameters ζ → a video clip, with pyrender.

The scene is a textured, double-sided flag on a pole, lit by a directional "sun" and an
ambient term (diffuse shading, see :data:`MESH_SHADERS`), seen by a perspective camera and
composited over a static background. It is
built once per trajectory; each frame only the flag's vertex positions and normals are
re-uploaded (:meth:`physinfer.rendering.OffscreenContext.update_vertices`). Rendering is
headless through EGL (Mesa's llvmpipe on CPU machines) and deterministic for fixed ζ.
This module holds ζ (:class:`FlagRenderParams`, its checks and its sampling) and the
renderer; the flag's scene (size and pole measured from the trajectory, pole mesh,
framing) is :mod:`physinfer_flag.flag_scene`, the helpers any cloth renderer shares
:mod:`physinfer_flag.sheet_render`; their public names are re-exported here.

Coordinates follow the cloth simulator's contract: metres, z up, wind along +x, the pole
vertical along z at x = y = 0 with the flag's hoist on it. ``Trajectory.extras`` may hold
``"uv"`` ``(V, 2)`` (u from hoist 0 to fly 1, v from bottom 0 to top 1) and ``"pole"``
``(2, 3)`` (bottom and top points); both are derived from the first frame when absent.

About the paper's "at most 15° between the wind direction and the camera axis": a camera
looking along the wind sees the flag edge-on, which matches neither the paper's renders
nor its footage (filmed from the side). The constraint is applied to the camera's
horizontal image axis: azimuth 0 looks at the flag face-on along +y with the wind blowing
left to right in the image, and ``|camera_azimuth_deg| <= 15`` keeps the wind within 15°
of that axis (and of the image plane, whatever the elevation).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from physinfer.errors import UserInputError
from physinfer.rendering import OffscreenContext
from physinfer.roles import Renderer
from physinfer.types import Clip, Trajectory
from physinfer_flag.backgrounds import BACKGROUND_NAMES, background_image, list_background_images
from physinfer_flag.flag_scene import (
    FlagGeometry,
    flag_camera,
    measure_flag,
    pole_mesh,
    waving_sheet,
)
from physinfer_flag.sheet_render import (
    MESH_SHADERS,
    DoubleSidedSheet,
    SheetView,
    SheetViewParams,
    add_camera_and_sun,
    check_renderable,
    check_view,
    composite_over,
    context_of_size,
    fabric_material,
    fitting_distance,
    frame_size,
    orbit_camera,
    render_sheet,
    sheet_scene,
    texture_coordinates,
)
from physinfer_flag.textures import FLAG_NAMES, flag_texture

__all__ = [
    "MAX_WIND_CAMERA_ANGLE_DEG", "MESH_SHADERS", "TEXTURE_HEIGHT", "DoubleSidedSheet", "FlagGeometry",
    "FlagRenderParams", "FlagRenderer", "SheetView", "SheetViewParams", "add_camera_and_sun", "check_renderable",
    "check_view", "composite_over", "context_of_size", "fabric_material", "fitting_distance", "frame_size",
    "measure_flag", "orbit_camera", "render_sheet", "sheet_scene", "texture_coordinates", "waving_sheet",
]

MAX_WIND_CAMERA_ANGLE_DEG = 15.0
"""The paper's limit on the angle between the wind direction and the camera axis."""

TEXTURE_HEIGHT = 256
"""Texture resolution (rows); 256×384 is sharper than a 224-pixel render needs."""


@dataclass(frozen=True)
class FlagRenderParams(SheetViewParams):
    """Render parameters ζ of :class:`FlagRenderer`; every field is a key of the ζ dict.

    Attributes:
        image_size: Output size in pixels: one int for a square image or ``(H, W)``.
        camera_distance: Distance in metres from the camera to the look-at target, or
            None to frame the flag automatically: a square of 1.36 fly lengths from
            0.18 lengths above the hoist top down to 1.18 below, so the flag stays in
            view flying straight or drooping in a light wind.
        framing: Multiplier of the automatic distance (> 1 shows more surroundings);
            ignored when ``camera_distance`` is given.
        camera_azimuth_deg: Horizontal angle of the camera around the look-at target;
            0 looks at the flag face-on along +y (wind blowing left to right), positive
            values move the camera downwind. Must satisfy ``|azimuth| <= 15``.
        camera_elevation_deg: Angle of the camera above the target's horizontal plane;
            negative looks up at the flag, as from the ground. In ``[-45, 45]``.
        fov_deg: Vertical field of view in degrees, in ``(5, 120)``.
        light_direction: ``(3,)`` direction the sunlight travels in world coordinates
            (the default comes from above, behind the camera and from the left).
        light_intensity: Directional light intensity (pyrender units, ``>= 0``).
        ambient_intensity: Ambient light in ``[0, 1]``, keeps shaded folds from going black.
        texture: Flag design, one of :data:`physinfer_flag.textures.FLAG_NAMES`.
        background: A procedural background name
            (:data:`physinfer_flag.backgrounds.BACKGROUND_NAMES`) or an image path.
        pole: Draw the flag pole.
    """

    settings_owner: ClassVar[str] = "flag"

    image_size: int | tuple[int, int] = 224
    camera_distance: float | None = None
    framing: float = 1.0
    camera_azimuth_deg: float = 0.0
    camera_elevation_deg: float = -5.0
    fov_deg: float = 40.0
    light_direction: tuple[float, float, float] = (0.35, 0.8, -0.5)
    light_intensity: float = 2.5
    ambient_intensity: float = 0.3
    texture: str = "netherlands"
    background: str = "sky_cloudy"
    pole: bool = True

    def validate(self) -> None:
        """Check every value; raises :class:`UserInputError` naming the offending key."""
        check_view(self)
        if self.camera_distance is not None and not (0 < self.camera_distance < 1e4):
            raise UserInputError(f"camera_distance={self.camera_distance}: give a positive distance in metres or None")
        if abs(self.camera_azimuth_deg) > MAX_WIND_CAMERA_ANGLE_DEG:
            raise UserInputError(
                f"camera_azimuth_deg={self.camera_azimuth_deg:g}: the angle between the wind direction "
                f"and the camera axis must be at most {MAX_WIND_CAMERA_ANGLE_DEG:g}° (as in the paper); "
                f"choose camera_azimuth_deg in [-{MAX_WIND_CAMERA_ANGLE_DEG:g}, {MAX_WIND_CAMERA_ANGLE_DEG:g}]"
            )
        if self.texture.lower() not in FLAG_NAMES:
            raise UserInputError(f"texture={self.texture!r} is unknown; choose one of: {', '.join(FLAG_NAMES)}")
        if self.background not in BACKGROUND_NAMES and not Path(self.background).expanduser().is_file():
            raise UserInputError(
                f"background={self.background!r} is neither a procedural background "
                f"({', '.join(BACKGROUND_NAMES)}) nor an existing image file"
            )


class FlagRenderer(Renderer):
    """pyrender renderer of flag trajectories (see :class:`FlagRenderParams` for ζ).

    One EGL context is created on first use and kept for the renderer's lifetime (a new
    one only if ζ asks for another image size); call :meth:`close` to release it.

    Args:
        background_dir: A folder of images added to the procedural backgrounds that
            :meth:`sample_render_params` draws from.
        textures: Flag designs :meth:`sample_render_params` draws from (default: all).
        pole_height: Height of the pole's top above the ground for trajectories that carry
            no pole of their own (``--scene-set pole_height``); ``None``: 3 fly lengths.
    """

    default_render_params: Mapping[str, Any] = MappingProxyType(FlagRenderParams().to_dict())

    def __init__(
        self,
        *,
        background_dir: str | Path | None = None,
        textures: Sequence[str] | None = None,
        pole_height: float | None = None,
    ) -> None:
        self.pole_height = pole_height
        self.background_dir = None if background_dir is None else Path(background_dir)
        self.backgrounds: tuple[str, ...] = BACKGROUND_NAMES + tuple(
            list_background_images(background_dir) if background_dir is not None else ()
        )
        self.textures: tuple[str, ...] = tuple(textures) if textures is not None else FLAG_NAMES
        for name in self.textures:
            flag_texture(name, 2)  # raises UserInputError for an unknown name
        self._context: OffscreenContext | None = None
        self._materials: dict[str, Any] = {}

    def render(self, trajectory: Trajectory, render_params: Mapping[str, Any] | None = None) -> Clip:
        """Render every frame of ``trajectory``.

        Args:
            trajectory: Cloth trajectory following the flag contract (module docstring).
            render_params: ζ; missing keys take :attr:`default_render_params`.

        Returns:
            Clip of ``(T, H, W, 3)`` uint8 frames at ``trajectory.fps``.

        Raises:
            UserInputError: invalid ζ (the message names the key), malformed extras, or a
                trajectory without frames or with non-finite positions.
        """
        params = FlagRenderParams.from_mapping(render_params)
        check_renderable(trajectory)
        height, width = params.size
        geometry = measure_flag(trajectory, pole_height=self.pole_height)
        sheet = DoubleSidedSheet(trajectory.faces, trajectory.vertices.shape[1])
        scene, flag = self._build_scene(trajectory, geometry, sheet, params)
        background = background_image(params.background, (height, width))
        return render_sheet(self._context_for(width, height), scene, flag, sheet, trajectory, background)

    def check_render_params(self, render_params: Mapping[str, Any] | None) -> dict[str, Any]:
        """Validate ζ without rendering (e.g. before a long simulation).

        Returns:
            The complete ζ with defaults filled in and values converted to their types.

        Raises:
            UserInputError: as :meth:`render` would, naming the offending key.
        """
        return FlagRenderParams.from_mapping(render_params).to_dict()

    def sample_render_params(self, rng: np.random.Generator) -> dict[str, Any]:
        """A random ζ for dataset variety: texture, background, camera and light.

        The camera stays within the paper's 15° of the wind; the sun comes from the
        camera's side of the flag and 20–70° above the horizon.

        Args:
            rng: Source of randomness (the result is a function of its state only).

        Returns:
            A complete ζ dict (JSON-friendly).
        """
        sun_azimuth = np.radians(rng.uniform(-70.0, 70.0))
        sun_elevation = np.radians(rng.uniform(20.0, 70.0))
        light = (
            math.cos(sun_elevation) * math.sin(sun_azimuth),
            math.cos(sun_elevation) * math.cos(sun_azimuth),
            -math.sin(sun_elevation),
        )
        params = FlagRenderParams(
            framing=float(rng.uniform(0.9, 1.35)),
            camera_azimuth_deg=float(rng.uniform(-MAX_WIND_CAMERA_ANGLE_DEG, MAX_WIND_CAMERA_ANGLE_DEG)),
            camera_elevation_deg=float(rng.uniform(-15.0, 10.0)),
            fov_deg=float(rng.uniform(30.0, 50.0)),
            light_direction=tuple(float(v) for v in light),
            light_intensity=float(rng.uniform(1.8, 3.5)),
            ambient_intensity=float(rng.uniform(0.2, 0.45)),
            texture=str(self.textures[int(rng.integers(len(self.textures)))]),
            background=str(self.backgrounds[int(rng.integers(len(self.backgrounds)))]),
        )
        return params.to_dict()

    def close(self) -> None:
        """Release the EGL context and cached GL textures."""
        if self._context is not None:
            self._context.close()
            self._context = None
        self._materials.clear()

    def _context_for(self, width: int, height: int) -> OffscreenContext:
        # This module's MESH_SHADERS, read at call time: bench_render.py --pyrender-shader sets it.
        context = context_of_size(self._context, width, height, mesh_shaders=MESH_SHADERS)
        if self._context is not None and context is not self._context:
            self._materials.clear()  # their GL textures died with the old context
        self._context = context
        return context

    def _flag_material(self, texture: str) -> Any:
        # One material (and GL texture) per design, reused across trajectories so the
        # texture is uploaded once per context rather than once per render.
        key = texture.lower()
        if key not in self._materials:
            self._materials[key] = fabric_material(np.array(flag_texture(key, TEXTURE_HEIGHT)), roughness=0.85)
        return self._materials[key]

    def _build_scene(
        self, trajectory: Trajectory, geometry: FlagGeometry, sheet: DoubleSidedSheet, params: FlagRenderParams
    ) -> tuple[Any, Any]:
        """The scene for one trajectory and the flag primitive whose vertices move."""
        scene, flag = sheet_scene(
            sheet, trajectory.vertices[0], geometry.uv, self._flag_material(params.texture), params
        )
        if params.pole:
            # pyrender draws solid meshes sorted by the distance of their node's origin from
            # the camera, ties in set order (object ids, so varying between runs). Where the
            # flag passes into the pole a sample can have equal depths for both, and draw
            # order then decides it: an origin at the pole's top (not the flag's (0, 0, 0))
            # keeps the order, hence the pixels, the same in every run.
            pose = np.eye(4)
            pose[:3, 3] = geometry.pole[1]
            scene.add(pole_mesh(geometry), pose=pose)
        add_camera_and_sun(scene, *flag_camera(geometry, params), params)
        return scene, flag
