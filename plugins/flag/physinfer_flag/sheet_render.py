"""Rendering helpers for any cloth sheet, with pyrender: ζ's shared keys, buffers, camera, frames.

What every cloth renderer of this plugin family shares (the flag's and the hanging
cloth's): the ζ keys of the camera, light and size (:class:`SheetView`,
:class:`SheetViewParams`, :func:`check_view`), a double-sided sheet's per-frame buffers
(:class:`DoubleSidedSheet`, :func:`texture_coordinates`), an orbiting camera framing a
square (:func:`orbit_camera`, :func:`fitting_distance`), a textured sheet in a lit scene
(:func:`fabric_material`, :func:`sheet_scene`, :func:`add_camera_and_sun`) and the frame
loop (:func:`render_sheet`, :func:`composite_over`). Nothing here knows of flags or poles.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, ClassVar, Protocol

import numpy as np

from physinfer.errors import UserInputError
from physinfer.rendering import OffscreenContext, look_at, use_headless_gl
from physinfer.settings import MappingSettings, check_range
from physinfer.types import Clip, Trajectory

MESH_SHADERS = (Path(__file__).with_name("shaders") / "lambert.vert", Path(__file__).with_name("shaders") / "lambert.frag")
"""Diffuse (Lambert) shading used instead of pyrender's physically based mesh shader:
fabric is matte, and on Mesa's llvmpipe it renders a frame in about 40% of the time."""


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
        """Area-weighted unit vertex normals ``(V, 3)`` of the front side (``(T, V, 3)`` for
        ``T`` frames at once: the same numbers as frame by frame, to the last bit)."""
        p = positions.astype(np.float64)
        frames = p.reshape((-1, *p.shape[-2:]))
        a, b, c = (frames[:, self.faces[:, i]] for i in range(3))
        face_normals = np.cross(b - a, c - a)  # length = twice the area: area weighting
        corner = np.repeat(face_normals, 3, axis=1).reshape(-1, 3)
        # Each frame's corners sum into its own bins, in the order a single frame's would.
        bins = (np.arange(len(frames))[:, None] * self.n_vertices + self._corner_vertex[None, :]).ravel()
        size = len(frames) * self.n_vertices
        normals = np.stack([np.bincount(bins, corner[:, k], minlength=size) for k in range(3)], axis=1)
        norm = np.linalg.norm(normals, axis=1, keepdims=True)
        return (normals / np.maximum(norm, 1e-12)).reshape(p.shape)

    def buffers(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and normals ``(2V, 3)`` float32 for both sides (``(T, 2V, 3)`` for ``T`` frames)."""
        normals = self.vertex_normals(positions)
        both_positions = np.concatenate([positions, positions], axis=-2).astype(np.float32)
        both_normals = np.concatenate([normals, -normals], axis=-2).astype(np.float32)
        return both_positions, both_normals


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


def context_of_size(
    context: OffscreenContext | None, width: int, height: int, *, mesh_shaders: tuple[Path, Path] | None = MESH_SHADERS
) -> OffscreenContext:
    """``context`` if it renders ``width`` × ``height``, else a new one (closing ``context``)
    that draws meshes with ``mesh_shaders`` (``None``: pyrender's own)."""
    if context is not None and (context.width, context.height) == (width, height):
        return context
    if context is not None:
        context.close()
    return OffscreenContext(width, height, mesh_shaders=mesh_shaders)


#: Frames drawn and composited at once (bounds the buffer of renders awaiting their background).
_COMPOSITE_FRAMES = 32


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
    # Every frame's buffers at once, the frames drawn by blocks (pyrender's per-frame work
    # done once a block, the same pixels: OffscreenContext.render_sequence) and composited
    # by blocks, which bounds the renders awaiting their background.
    positions, normals = sheet.buffers(np.asarray(trajectory.vertices))
    frames = np.empty((trajectory.n_frames, height, width, 3), dtype=np.uint8)
    for start in range(0, trajectory.n_frames, _COMPOSITE_FRAMES):
        block = slice(start, min(start + _COMPOSITE_FRAMES, trajectory.n_frames))
        rgba = context.render_sequence(scene, vertices={primitive: (positions[block], normals[block])}, rgba=True)
        frames[block] = composite_over(rgba, background)
    return Clip(frames, float(trajectory.fps))


def composite_over(rgba: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Put a premultiplied RGBA render over an opaque background.

    Args:
        rgba: ``(..., H, W, 4)`` uint8, colour premultiplied by alpha (how a multisampled
            render cleared to transparent black comes out): one frame or many.
        background: ``(H, W, 3)`` uint8.

    Returns:
        ``(..., H, W, 3)`` uint8.
    """
    alpha = rgba[..., 3:4].astype(np.uint16)
    blended = rgba[..., :3].astype(np.uint16) + (background.astype(np.uint16) * (255 - alpha) + 127) // 255
    return np.minimum(blended, 255).astype(np.uint8)
