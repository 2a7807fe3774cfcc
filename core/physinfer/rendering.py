"""Headless pyrender helpers shared by every plugin's renderer.

pyrender picks its OpenGL platform when first imported, from ``PYOPENGL_PLATFORM``:
:func:`use_headless_gl` sets it to ``egl`` (Mesa's llvmpipe on CPU machines, NVIDIA's
EGL on GPU machines) unless the user chose another, and ``PYGLET_HEADLESS=1`` (pyrender
imports pyglet, which otherwise looks for an X display). Creating an EGL context costs about
half a second, so :class:`OffscreenContext` keeps one per renderer and reuses it.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import PhysinferError
from physinfer.render_replay import program_cache, replay_frames


def use_headless_gl() -> None:
    """Select EGL for PyOpenGL and a headless pyglet, unless the user chose otherwise.

    Sets ``PYOPENGL_PLATFORM=egl`` and ``PYGLET_HEADLESS=1`` where they are not set: pyrender
    imports pyglet, which without it wants an X display, so ``import pyrender`` fails on a
    machine without one. Call before pyrender is first imported.
    """
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    os.environ.setdefault("PYGLET_HEADLESS", "1")


_Z_UP = np.array([0.0, 0.0, 1.0])
_Z_UP.setflags(write=False)


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = _Z_UP) -> np.ndarray:
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


def segment_pose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose ``(4, 4)`` that maps a unit-height cylinder along z (trimesh's, centred) onto the
    segment ``a``–``b``: a rod or a string between a pivot and a bob."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    axis = b - a
    length = float(np.linalg.norm(axis))
    z = axis / max(length, 1e-9)
    x = np.cross([0.0, 1.0, 0.0], z)
    x = x / max(np.linalg.norm(x), 1e-9)
    y = np.cross(z, x)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = x, y, z * length
    pose[:3, 3] = (a + b) / 2
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
        mesh_shaders: Optional ``(vertex, fragment)`` shader files used instead of
            pyrender's ``mesh.vert``/``mesh.frag`` for every mesh. They receive pyrender's
            attribute-location defines and uniforms (uniforms they do not declare are
            skipped), so a plugin can trade pyrender's physically based shading for a
            cheaper model.
    """

    def __init__(self, width: int, height: int, *, mesh_shaders: tuple[str | Path, str | Path] | None = None) -> None:
        self.width, self.height = width, height
        self.mesh_shaders = None if mesh_shaders is None else tuple(str(Path(f).resolve()) for f in mesh_shaders)
        if self.mesh_shaders is not None:
            missing = [f for f in self.mesh_shaders if not Path(f).is_file()]
            if missing:
                raise FileNotFoundError(f"shader file(s) not found: {', '.join(missing)}")
        self._renderer: Any = None

    _open = 0
    """Contexts created and not yet closed, across the process (see :meth:`close`)."""

    def render(self, scene: Any, *, rgba: bool = False) -> np.ndarray:
        """Render ``scene``.

        Args:
            scene: A ``pyrender.Scene``.
            rgba: Also return coverage as alpha (clear the scene with ``bg_color`` alpha
                0): anti-aliased edges then come out premultiplied, ready to composite
                over a background image.

        Returns:
            ``(H, W, 3)`` uint8 RGB, or ``(H, W, 4)`` uint8 RGBA when ``rgba``.
        """
        self._ensure_renderer()
        if rgba:
            import pyrender

            color, _depth = self._renderer.render(scene, flags=pyrender.RenderFlags.RGBA)
            return np.ascontiguousarray(color)
        color, _depth = self._renderer.render(scene)
        return np.ascontiguousarray(color[..., :3])

    def update_vertices(self, primitive: Any, positions: np.ndarray, normals: np.ndarray | None = None) -> None:
        """Move the vertices of a ``pyrender.Primitive`` that is already in a scene.

        pyrender 0.1.45 uploads a primitive's vertex buffer once, when the primitive is
        first rendered; its ``positions``/``normals`` setters change only the CPU copy. This
        sets them and re-uploads the interleaved vertex data into the same GL buffer, so a
        deforming mesh is animated without rebuilding the scene or its GL objects.

        Args:
            primitive: The primitive to update (same vertex count as before).
            positions: ``(N, 3)`` float vertex positions.
            normals: ``(N, 3)`` vertex normals, or None to keep the current ones.
        """
        primitive.positions = positions
        if normals is not None:
            primitive.normals = normals
        if self._renderer is None or not primitive._in_context():
            return  # first render uploads everything
        platform = self._renderer._platform
        platform.make_current()
        try:
            _upload_vertices(primitive)
        finally:
            platform.make_uncurrent()

    def render_sequence(
        self,
        scene: Any,
        *,
        poses: Mapping[Any, np.ndarray] | None = None,
        vertices: Mapping[Any, tuple[np.ndarray, np.ndarray | None]] | None = None,
        rgba: bool = False,
    ) -> np.ndarray:
        """Render ``scene`` once per frame of an animation that moves nodes and vertices.

        The same pixels as, for every frame, ``scene.set_pose`` of each node,
        :meth:`update_vertices` of each primitive and :meth:`render`; about twice as fast
        on small images, where pyrender's per-frame Python work outweighs the drawing
        (:mod:`physinfer.render_replay`). Nothing else of the scene may change, and
        nothing else does: the animation is all in the arguments.

        Args:
            scene: A ``pyrender.Scene``.
            poses: ``(T, 4, 4)`` poses of scene nodes, by node.
            vertices: ``(positions (T, N, 3), normals (T, N, 3) or None)`` of primitives
                in the scene, by primitive.
            rgba: As in :meth:`render`.

        Returns:
            ``(T, H, W, 3)`` or ``(T, H, W, 4)`` uint8. The nodes and primitives are left
            in the last frame.

        Raises:
            ValueError: no frames, arguments of different frame counts, a node or
                primitive that is not in ``scene``, or a moved node that is or carries the
                camera or a light.
        """
        poses, vertices = dict(poses or {}), dict(vertices or {})
        _check_in_scene(scene, poses, vertices)
        counts = {len(p) for p in poses.values()} | {len(v[0]) for v in vertices.values()}
        counts |= {len(v[1]) for v in vertices.values() if v[1] is not None}
        if len(counts) != 1 or 0 in counts:
            raise ValueError(f"render_sequence needs one frame count >= 1 for every pose and vertex array, got {sorted(counts)}")
        out = np.empty((counts.pop(), self.height, self.width, 4 if rgba else 3), dtype=np.uint8)

        def set_frame(index: int, *, current: bool = True) -> None:
            for node, frames in poses.items():
                scene.set_pose(node, frames[index])
            for primitive, (positions, normals) in vertices.items():
                if current:  # the replay holds the context
                    primitive.positions = positions[index]
                    if normals is not None:
                        primitive.normals = normals[index]
                    _upload_vertices(primitive)
                else:
                    self.update_vertices(primitive, positions[index], None if normals is None else normals[index])

        set_frame(0, current=False)
        out[0] = self.render(scene, rgba=rgba)
        if len(out) > 1:
            replay_frames(self._renderer, scene, out, set_frame, rgba=rgba)
        return out

    def _ensure_renderer(self) -> None:
        if self._renderer is None:
            use_headless_gl()
            import pyrender

            try:
                self._renderer = pyrender.OffscreenRenderer(self.width, self.height)
                OffscreenContext._open += 1
                _read_colour_only(self._renderer._renderer)
                # Programs that skip uploading a uniform they hold, and the plugin's shaders.
                self._renderer._renderer._program_cache = program_cache(self.mesh_shaders)
            except Exception as exc:
                raise PhysinferError(
                    f"cannot create a headless OpenGL context ({type(exc).__name__}: {exc}). "
                    "Install Mesa's EGL (Debian: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri "
                    "libgl1 libglx0) "
                    "and keep PYOPENGL_PLATFORM=egl."
                ) from None

    def close(self) -> None:
        """Release the EGL context (other contexts of the process stay usable)."""
        if self._renderer is None:
            return
        renderer, self._renderer = self._renderer, None
        OffscreenContext._open -= 1
        platform = renderer._platform
        if OffscreenContext._open > 0 and getattr(platform, "_egl_context", None) is not None:
            _release_egl_context_only(renderer)
        else:
            renderer.delete()

    def __del__(self) -> None:  # pragma: no cover - best effort at interpreter exit
        try:
            self.close()
        except Exception:
            pass


def _read_colour_only(renderer: Any) -> None:
    """Make a pyrender ``Renderer`` read back only the colour of each frame.

    pyrender resolves and reads the depth buffer of every frame too, and converts it to
    metres: about 8 % of a 112-px flag clip's render time on llvmpipe (0.78 → 0.71 s for
    200 frames, one measurement), for a buffer nothing here uses. The colour is resolved
    and read exactly as pyrender does (the same calls, so the same pixels); the depth
    returned is ``None``. Offscreen rendering on Linux only (macOS rescales its buffers:
    pyrender's own reader is kept there).
    """
    import sys

    if sys.platform == "darwin":
        return
    from OpenGL import GL
    from pyrender.constants import RenderFlags

    def read(scene: Any, flags: int) -> tuple[np.ndarray, None]:
        width, height = renderer._main_fb_dims[0], renderer._main_fb_dims[1]
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, renderer._main_fb_ms)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, renderer._main_fb)
        GL.glBlitFramebuffer(0, 0, width, height, 0, 0, width, height, GL.GL_COLOR_BUFFER_BIT, GL.GL_LINEAR)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, renderer._main_fb)
        channels, layout = (4, GL.GL_RGBA) if flags & RenderFlags.RGBA else (3, GL.GL_RGB)
        buffer = GL.glReadPixels(0, 0, width, height, layout, GL.GL_UNSIGNED_BYTE)
        colour = np.frombuffer(buffer, dtype=np.uint8).reshape((height, width, channels))
        return np.flip(colour, axis=0), None

    renderer._read_main_framebuffer = read


def _handle(pointer: Any) -> int | None:
    """An EGL handle's address (``None`` for none: ``EGL_NO_CONTEXT``, a null pointer)."""
    import ctypes

    if pointer is None:
        return None
    address = pointer if isinstance(pointer, int) else ctypes.cast(pointer, ctypes.c_void_p).value
    return int(address) if address else None


def _release_egl_context_only(renderer: Any) -> None:
    """Free an ``OffscreenRenderer``'s GL objects and EGL context, keeping the EGL display.

    pyrender's ``OffscreenRenderer.delete`` ends with ``eglTerminate`` on the display,
    which every EGL context of the process shares: it would invalidate the contexts of
    all other open renderers (``eglMakeCurrent`` then fails with EGL_BAD_DISPLAY).
    """
    from OpenGL.EGL import (
        EGL_DRAW,
        EGL_NO_CONTEXT,
        EGL_NO_SURFACE,
        EGL_READ,
        eglDestroyContext,
        eglGetCurrentContext,
        eglGetCurrentDisplay,
        eglGetCurrentSurface,
        eglMakeCurrent,
    )

    platform = renderer._platform
    # The context current before, restored after: a renderer closed by the garbage collector
    # (one a failed run never closed) may close in the middle of another's render, whose
    # next GL call would then find no context ("Link failure (0)" compiling a shader).
    was = (eglGetCurrentDisplay(), eglGetCurrentSurface(EGL_DRAW), eglGetCurrentSurface(EGL_READ), eglGetCurrentContext())
    platform.make_current()
    renderer._renderer.delete()
    eglMakeCurrent(platform._egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)
    eglDestroyContext(platform._egl_display, platform._egl_context)
    if _handle(was[3]) not in (None, _handle(platform._egl_context)):
        eglMakeCurrent(*was)
    platform._egl_context = None
    platform._egl_display = None
    renderer._renderer = None
    renderer._platform = None


def _check_in_scene(scene: Any, nodes: Mapping[Any, Any], primitives: Mapping[Any, Any]) -> None:
    """Refuse an animated node or primitive that ``scene`` does not hold (it would not be
    drawn, or its vertex buffer would not exist), and a moved node that carries the camera or
    a light (the replayed frames keep the first frame's view and lighting)."""
    import networkx as nx

    held = {id(p) for mesh in scene.meshes for p in mesh.primitives}
    if any(node not in scene.nodes for node in nodes) or any(id(p) not in held for p in primitives):
        raise ValueError("render_sequence: every animated node and primitive must be in the scene rendered")
    view = set(scene.camera_nodes) | set(scene.light_nodes)
    # Scene-graph edges run from child to parent: what a node carries are its ancestors here.
    if any(node in view or view & nx.ancestors(scene._digraph, node) for node in nodes):
        raise ValueError(
            "render_sequence moves mesh nodes only: the camera and the lights stay where they are in the "
            "first frame (render a moving view frame by frame with render)"
        )


def _upload_vertices(primitive: Any) -> None:
    """Copy a primitive's vertex data into its GL buffer (the context must be current)."""
    from OpenGL import GL

    data = _interleaved_vertex_data(primitive)
    GL.glBindBuffer(GL.GL_ARRAY_BUFFER, primitive._buffers[0])
    GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, data.nbytes, data)
    GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)


def _interleaved_vertex_data(primitive: Any) -> np.ndarray:
    """The vertex buffer contents of a primitive, laid out as pyrender 0.1.45 lays them out.

    One row per vertex: position, then normal, tangent, texcoord_0, texcoord_1, color_0 for
    those the primitive has (see ``pyrender.Primitive._add_to_context``).
    """
    columns = [primitive.positions]
    for attribute in ("normals", "tangents", "texcoord_0", "texcoord_1", "color_0"):
        value = getattr(primitive, attribute)
        if value is not None:
            columns.append(value)
    return np.ascontiguousarray(np.hstack(columns), dtype=np.float32)
