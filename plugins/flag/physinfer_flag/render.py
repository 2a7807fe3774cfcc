"""The flag renderer: a cloth trajectory and render parameters ζ → a video clip, with pyrender.

The scene is a textured, double-sided flag on a pole, lit by a directional "sun" and an
ambient term (diffuse shading, see :data:`MESH_SHADERS`), seen by a perspective camera and
composited over a static background. It is
built once per trajectory; each frame only the flag's vertex positions and normals are
re-uploaded (:meth:`physinfer.rendering.OffscreenContext.update_vertices`). Rendering is
headless through EGL (Mesa's llvmpipe on CPU machines) and deterministic for fixed ζ.
This module holds the renderer; ζ (:class:`FlagRenderParams` and its checks) is
:mod:`physinfer_flag.render_params`, the flag's scene (size and pole measured from the trajectory, pole mesh,
framing) is :mod:`physinfer_flag.flag_scene`, the helpers any cloth renderer shares
:mod:`physinfer_flag.sheet_render`; the names that moved there are still found here with a
warning (:data:`MOVED`).

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
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from physinfer.moved import moved_names
from physinfer.rendering import OffscreenContext
from physinfer.roles import Renderer
from physinfer.types import Clip, Trajectory
from physinfer_flag.backgrounds import BACKGROUND_NAMES, background_image, list_background_images
from physinfer_flag.flag_scene import flag_camera, measure_flag, pole_mesh
from physinfer_flag.render_params import MAX_WIND_CAMERA_ANGLE_DEG, FlagRenderParams
from physinfer_flag.sheet_render import (
    MESH_SHADERS,
    DoubleSidedSheet,
    add_camera_and_sun,
    check_renderable,
    context_of_size,
    fabric_material,
    render_sheet,
    sheet_scene,
)
from physinfer_flag.textures import FLAG_NAMES, flag_texture

if TYPE_CHECKING:
    from physinfer_flag.flag_scene import FlagGeometry

__all__ = ["TEXTURE_HEIGHT", "FlagRenderer"]


def _moved(new: str, names: str) -> dict[str, str]:
    return {f"{__name__}.{name}": f"{new}.{name}" for name in names.split()}


#: Old path → new path of the names that moved out of this module (the flag's scene and the
#: helpers every cloth renderer shares); :func:`physinfer.moved.moved_names` finds them.
MOVED = MappingProxyType({
    **_moved("physinfer_flag.flag_scene", "FlagGeometry waving_sheet"),
    **_moved("physinfer_flag.sheet_render",
             "SheetView SheetViewParams check_view composite_over fitting_distance frame_size "
             "orbit_camera texture_coordinates"),
})  # fmt: skip
__getattr__ = moved_names(__name__, MOVED)

TEXTURE_HEIGHT = 256
"""Texture resolution (rows); 256×384 is sharper than a 224-pixel render needs."""


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
