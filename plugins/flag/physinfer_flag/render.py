"""The flag renderer: a cloth trajectory and render parameters ζ → a video clip, with pyrender.

The scene is a textured, double-sided flag on a pole, lit by a directional "sun" and an
ambient term (diffuse shading, see :data:`MESH_SHADERS`), seen by a perspective camera and
composited over a static background. It is
built once per trajectory; each frame only the flag's vertex positions and normals are
re-uploaded (:meth:`physinfer.rendering.OffscreenContext.update_vertices`). Rendering is
headless through EGL (Mesa's llvmpipe on CPU machines) and deterministic for fixed ζ.

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
from typing import Any, ClassVar, Protocol

import numpy as np

from physinfer.errors import UserInputError
from physinfer.rendering import OffscreenContext, look_at, use_headless_gl
from physinfer.roles import Renderer
from physinfer.settings import MappingSettings, check_range
from physinfer.types import Clip, Trajectory
from physinfer_flag.backgrounds import BACKGROUND_NAMES, background_image, list_background_images
from physinfer_flag.textures import FLAG_NAMES, flag_texture

MAX_WIND_CAMERA_ANGLE_DEG = 15.0
"""The paper's limit on the angle between the wind direction and the camera axis."""

MESH_SHADERS = (Path(__file__).with_name("shaders") / "lambert.vert", Path(__file__).with_name("shaders") / "lambert.frag")
"""Diffuse (Lambert) shading used instead of pyrender's physically based mesh shader:
fabric is matte, and on Mesa's llvmpipe it renders a frame in about 40% of the time."""

TEXTURE_HEIGHT = 256
"""Texture resolution (rows); 256×384 is sharper than a 224-pixel render needs."""

_FRAME_HALF_SIZE = 0.68
"""Half the side of the square the automatic camera frames, in fly lengths."""

_FRAME_CENTRE_DROP = 0.5
"""How far below the hoist top the framed square is centred, in fly lengths: the square
reaches 0.18 lengths above the hoist top and 1.18 below, room for a flag flying straight
or drooping in a light wind."""


class SheetViewParams(MappingSettings):
    """Mixin of cloth render parameters ζ: ``from_mapping``/``to_dict`` and :attr:`size`.

    The dataclass that uses it has the :class:`SheetView` fields and calls
    :func:`check_view` from its ``validate()``.
    """

    settings_noun: ClassVar[str] = "render parameter"
    image_size: int | tuple[int, int]

    @property
    def size(self) -> tuple[int, int]:
        """``(H, W)`` of the output frames."""
        return frame_size(self.image_size)


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



class SheetView(Protocol):
    """The ζ keys every cloth renderer of this plugin family shares (camera, light, size).

    :class:`FlagRenderParams` has them, and so do the render parameters of plugins that
    reuse this renderer's machinery (the hanging cloth's).
    """

    image_size: int | tuple[int, int]
    framing: float
    camera_azimuth_deg: float
    camera_elevation_deg: float
    fov_deg: float
    light_direction: tuple[float, float, float]
    light_intensity: float
    ambient_intensity: float

    @property
    def size(self) -> tuple[int, int]:
        """``(H, W)`` of the output frames."""


def frame_size(image_size: int | tuple[int, int]) -> tuple[int, int]:
    """``(H, W)`` from ζ's ``image_size``: one int for a square, or ``(H, W)``."""
    if isinstance(image_size, int):
        return image_size, image_size
    return int(image_size[0]), int(image_size[1])


def check_view(params: SheetView) -> None:
    """Check the shared ζ keys (all but the azimuth, whose limits differ by scene).

    Raises:
        UserInputError: naming the first offending key and its valid range.
    """
    height, width = params.size
    if not (16 <= height <= 4096 and 16 <= width <= 4096):
        raise UserInputError(f"image_size={params.image_size!r}: each side must be 16 to 4096 pixels")
    check_range("framing", params.framing, 0.2, 10.0)
    check_range("camera_elevation_deg", params.camera_elevation_deg, -45.0, 45.0)
    if not (5.0 < params.fov_deg < 120.0):
        raise UserInputError(f"fov_deg={params.fov_deg:g}: the field of view must lie between 5 and 120 degrees")
    if len(params.light_direction) != 3 or not np.all(np.isfinite(params.light_direction)) or (
        np.linalg.norm(params.light_direction) < 1e-9
    ):
        raise UserInputError(f"light_direction={params.light_direction!r}: give a non-zero 3-vector")
    check_range("light_intensity", params.light_intensity, 0.0, 100.0)
    check_range("ambient_intensity", params.ambient_intensity, 0.0, 1.0)


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


def texture_coordinates(trajectory: Trajectory) -> np.ndarray:
    """``(V, 2)`` float32 uv of a sheet: ``extras["uv"]``, or the first frame projected on x–z.

    Raises:
        UserInputError: ``extras["uv"]`` is not ``(V, 2)``.
    """
    n_vertices = trajectory.vertices.shape[1]
    if "uv" in trajectory.extras:
        uv = np.asarray(trajectory.extras["uv"], dtype=np.float32)
        if uv.shape != (n_vertices, 2):
            raise UserInputError(f"trajectory extras['uv'] must be ({n_vertices}, 2), got {uv.shape}")
        return uv
    # No uv: project the first frame onto the xz plane, min x to max x, bottom to top.
    first = trajectory.vertices[0]
    lo, span = first.min(axis=0), np.maximum(np.ptp(first, axis=0), 1e-9)
    return np.stack([(first[:, 0] - lo[0]) / span[0], (first[:, 2] - lo[2]) / span[2]], axis=1).astype(np.float32)


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


class DoubleSidedSheet:
    """Per-frame vertex buffers of a cloth drawn from both sides.

    Each vertex is stored twice: the front copy with the surface normal and the given
    winding, the back copy with the opposite normal and reversed winding. Back-face
    culling then shows whichever side faces the camera, lit with the normal of that side
    (pyrender's shader does not flip normals of back faces by itself).

    Args:
        faces: ``(F, 3)`` int triangle indices.
        n_vertices: ``V``.
    """

    def __init__(self, faces: np.ndarray, n_vertices: int) -> None:
        self.faces = np.asarray(faces, dtype=np.int64)
        self.n_vertices = n_vertices
        self.indices = np.concatenate([self.faces, self.faces[:, ::-1] + n_vertices]).astype(np.int32)
        self._corner_vertex = self.faces.ravel()

    def vertex_normals(self, positions: np.ndarray) -> np.ndarray:
        """Area-weighted unit vertex normals ``(V, 3)`` of the front side."""
        p = positions.astype(np.float64)
        a, b, c = p[self.faces[:, 0]], p[self.faces[:, 1]], p[self.faces[:, 2]]
        face_normals = np.cross(b - a, c - a)  # length = twice the area: area weighting
        corner = np.repeat(face_normals, 3, axis=0)
        normals = np.stack(
            [np.bincount(self._corner_vertex, corner[:, k], minlength=self.n_vertices) for k in range(3)], axis=1
        )
        norm = np.linalg.norm(normals, axis=1, keepdims=True)
        return normals / np.maximum(norm, 1e-12)

    def buffers(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and normals ``(2V, 3)`` float32 for both sides."""
        normals = self.vertex_normals(positions)
        both_positions = np.concatenate([positions, positions]).astype(np.float32)
        both_normals = np.concatenate([normals, -normals]).astype(np.float32)
        return both_positions, both_normals


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
        context = context_of_size(self._context, width, height)
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
            scene.add(_pole_mesh(geometry), pose=pose)
        add_camera_and_sun(scene, *_camera(geometry, params), params)
        return scene, flag


def _pole_mesh(geometry: FlagGeometry) -> Any:
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


def _camera(geometry: FlagGeometry, params: FlagRenderParams) -> tuple[Any, np.ndarray]:
    """Perspective camera and its pose ``(4, 4)`` for ζ around the flag's look-at target."""
    distance = params.camera_distance
    if distance is None:
        distance = fitting_distance(params.framing * _FRAME_HALF_SIZE * geometry.length, params)
    reach = distance + 3.0 * geometry.length + float(np.ptp(geometry.pole[:, 2]))
    return orbit_camera(geometry.look_at_target, distance, params, znear=max(1e-3, 0.02 * distance), zfar=2.0 * reach)


def fitting_distance(half_extent: float, params: SheetView) -> float:
    """Camera distance in metres at which a square of half side ``half_extent`` (metres)
    just fills the narrower side of ζ's image at ζ's field of view."""
    height, width = params.size
    yfov = math.radians(params.fov_deg)
    half_fov = math.atan(math.tan(yfov / 2) * min(1.0, width / height))
    return half_extent / math.tan(half_fov)


def orbit_camera(
    target: np.ndarray, distance: float, params: SheetView, *, znear: float, zfar: float
) -> tuple[Any, np.ndarray]:
    """A perspective camera looking at ``target`` ``(3,)`` from ``distance`` metres away.

    ζ's azimuth turns it about the vertical from the −y side (0: looking along +y,
    positive towards +x) and its elevation raises it above the target's horizontal plane.

    Returns:
        The ``pyrender.PerspectiveCamera`` and its pose ``(4, 4)``.
    """
    import pyrender

    height, width = params.size
    azimuth, elevation = math.radians(params.camera_azimuth_deg), math.radians(params.camera_elevation_deg)
    offset = np.array(
        [math.sin(azimuth) * math.cos(elevation), -math.cos(azimuth) * math.cos(elevation), math.sin(elevation)]
    )
    pose = look_at(target + distance * offset, target)
    camera = pyrender.PerspectiveCamera(
        yfov=math.radians(params.fov_deg), aspectRatio=width / height, znear=znear, zfar=zfar
    )
    return camera, pose


def fabric_material(image: np.ndarray, *, roughness: float) -> Any:
    """A matte, non-metallic pyrender material textured with ``image`` ``(H, W, 3)`` uint8."""
    use_headless_gl()  # may be the first pyrender import: EGL must be chosen before it
    import pyrender

    sampler = pyrender.Sampler(wrapS=pyrender.GLTF.CLAMP_TO_EDGE, wrapT=pyrender.GLTF.CLAMP_TO_EDGE)
    return pyrender.MetallicRoughnessMaterial(
        baseColorTexture=pyrender.Texture(source=image, source_channels="RGB", sampler=sampler),
        metallicFactor=0.0,
        roughnessFactor=roughness,
    )


def sheet_scene(
    sheet: DoubleSidedSheet, positions: np.ndarray, uv: np.ndarray, material: Any, params: SheetView
) -> tuple[Any, Any]:
    """A transparent scene with ζ's ambient light and the textured sheet in it.

    Args:
        sheet: Buffers of the cloth.
        positions: ``(V, 3)`` vertex positions of the first frame.
        uv: ``(V, 2)`` texture coordinates.
        material: The sheet's material (e.g. :func:`fabric_material`).
        params: ζ.

    Returns:
        The ``pyrender.Scene`` and the sheet's primitive (whose vertices each frame updates).
    """
    use_headless_gl()
    import pyrender

    ambient = params.ambient_intensity
    scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[ambient, ambient, ambient])
    both_positions, normals = sheet.buffers(positions)
    primitive = pyrender.Primitive(
        positions=both_positions, normals=normals, texcoord_0=np.concatenate([uv, uv]),
        indices=sheet.indices, material=material,
    )
    scene.add(pyrender.Mesh([primitive]))
    return scene, primitive


def add_camera_and_sun(scene: Any, camera: Any, camera_pose: np.ndarray, params: SheetView) -> None:
    """Add the camera at ``camera_pose`` ``(4, 4)`` and ζ's directional light to ``scene``."""
    import pyrender

    scene.add(camera, pose=camera_pose)
    light_pose = look_at(np.zeros(3), np.asarray(params.light_direction, dtype=float))
    scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=params.light_intensity), pose=light_pose)


def check_renderable(trajectory: Trajectory) -> None:
    """Refuse a trajectory without frames or with non-finite positions.

    Raises:
        UserInputError: saying which.
    """
    if trajectory.n_frames == 0:
        raise UserInputError("the trajectory has no frames: nothing to render")
    if not trajectory.is_finite():
        raise UserInputError("the trajectory has NaN or infinite vertex positions; it cannot be rendered")


def context_of_size(context: OffscreenContext | None, width: int, height: int) -> OffscreenContext:
    """``context`` if it renders ``width`` × ``height``, else a new one (closing ``context``)."""
    if context is not None and (context.width, context.height) == (width, height):
        return context
    if context is not None:
        context.close()
    return OffscreenContext(width, height, mesh_shaders=MESH_SHADERS)


def render_sheet(
    context: OffscreenContext,
    scene: Any,
    primitive: Any,
    sheet: DoubleSidedSheet,
    trajectory: Trajectory,
    background: np.ndarray,
) -> Clip:
    """Render every frame: upload the frame's sheet vertices, draw, composite over ``background``.

    Args:
        context: Offscreen context of the output size.
        scene: Scene holding ``primitive`` (see :func:`sheet_scene`).
        primitive: The sheet's primitive.
        sheet: Its buffers.
        trajectory: ``vertices`` ``(T, V, 3)``.
        background: ``(H, W, 3)`` uint8.

    Returns:
        Clip of ``(T, H, W, 3)`` uint8 frames at ``trajectory.fps``.
    """
    height, width = background.shape[:2]
    frames = np.empty((trajectory.n_frames, height, width, 3), dtype=np.uint8)
    for index, positions in enumerate(trajectory.vertices):
        context.update_vertices(primitive, *sheet.buffers(positions))
        frames[index] = composite_over(context.render(scene, rgba=True), background)
    return Clip(frames, float(trajectory.fps))


def composite_over(rgba: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Put a premultiplied RGBA render over an opaque background.

    Args:
        rgba: ``(H, W, 4)`` uint8, colour premultiplied by alpha (how a multisampled
            render cleared to transparent black comes out).
        background: ``(H, W, 3)`` uint8.

    Returns:
        ``(H, W, 3)`` uint8.
    """
    alpha = rgba[..., 3:4].astype(np.uint16)
    blended = rgba[..., :3].astype(np.uint16) + (background.astype(np.uint16) * (255 - alpha) + 127) // 255
    return np.minimum(blended, 255).astype(np.uint8)


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
