"""Redraw a pyrender scene frame after frame when only node poses and vertices change.

pyrender's ``Renderer.render`` redoes everything for every frame: it re-checks which
meshes and textures are in the GL context, recomputes the camera matrices and the lights,
sorts the meshes, and uploads every uniform again. For an animation in which only some
nodes move and some vertices deform, all of that but the model matrix ``M`` of each draw
is the same as in the frame before. On a 112-px, 200-frame flag clip on llvmpipe this
Python work was about half of the render time (0.55 → 0.30 s per clip, measured with
:func:`replay_frames` and :func:`program_cache` together).

Two parts, each giving pyrender's own pixels (``tests/core/test_rendering.py`` compares
them bit for bit):

* :func:`program_cache` makes each shader program skip a uniform upload
  whose value it already holds (GL keeps uniform values in the program object, and only
  ``set_uniform`` changes them). pyrender calls ``set_uniform`` about 30 times per draw,
  many of them for uniforms a plugin's cheaper shaders do not declare.
* :func:`replay_frames` draws frames 2 … T with pyrender's own per-draw call
  (``_bind_and_draw_primitive``: model matrix, buffers, material, GL state, the draw) after
  frame 1 was drawn by ``render``; the camera, lights and materials are those of frame 1.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np


def program_cache(mesh_shaders: tuple[str, str] | None) -> Any:
    """A pyrender program cache whose programs remember their uniforms, and which builds
    meshes from ``mesh_shaders`` ``(vertex, fragment)`` when given (else pyrender's own)."""
    from pyrender.shader_program import ShaderProgramCache

    class UniformCachingProgramCache(ShaderProgramCache):  # type: ignore[misc]
        def get_program(
            self, vertex_shader: str, fragment_shader: str, geometry_shader: str | None = None,
            defines: dict[str, Any] | None = None,
        ) -> Any:
            # pyrender joins names to its shader folder; absolute paths survive the join.
            if mesh_shaders is not None and (vertex_shader, fragment_shader, geometry_shader) == (
                "mesh.vert", "mesh.frag", None,
            ):
                vertex_shader, fragment_shader = mesh_shaders
            program = super().get_program(vertex_shader, fragment_shader, geometry_shader, defines)
            remember_uniforms(program)
            return program

    return UniformCachingProgramCache()


def remember_uniforms(program: Any) -> None:
    """Make ``program.set_uniform`` skip a value the program already holds (idempotent)."""
    if getattr(program, "_physinfer_remembers_uniforms", False):
        return
    upload = program.set_uniform
    held: dict[str, Any] = {}
    held_by: list[Any] = [None]  # the GL program the values belong to

    def set_uniform(name: str, value: Any, unsigned: bool = False) -> None:
        if held_by[0] != program._program_id:  # a new GL program: it holds nothing yet
            held.clear()
            held_by[0] = program._program_id
        key = _uniform_key(value, unsigned)
        if key is not None and held.get(name) == key:
            return
        upload(name, value, unsigned)
        if key is not None:
            held[name] = key

    program.set_uniform = set_uniform
    program._physinfer_remembers_uniforms = True


def _uniform_key(value: Any, unsigned: bool) -> Any:
    """What pyrender uploads for ``value``, as a comparable value (``None``: do not cache)."""
    if isinstance(value, np.ndarray):
        return value.dtype.str, value.shape, value.tobytes(), unsigned
    if isinstance(value, (bool, int, float)):
        return type(value), value, unsigned
    return None


#: Frame setter: called with the frame index before that frame is drawn; moves nodes and
#: uploads vertices only (see :func:`replay_frames`).
SetFrame = Callable[[int], None]


def replay_frames(renderer: Any, scene: Any, out: np.ndarray, set_frame: SetFrame, *, rgba: bool) -> None:
    """Draw frames ``1 … len(out) − 1`` into ``out`` after frame 0 was rendered normally.

    Args:
        renderer: The ``pyrender.OffscreenRenderer`` that rendered frame 0 of ``scene``
            just before, with ``rgba`` as here.
        scene: The scene; between frames only node poses and vertex buffers may change
            (``set_frame`` makes those changes, with the GL context current).
        out: ``(T, H, W, C)`` uint8; ``out[0]`` is left as it is.
        set_frame: Puts the scene in frame ``i``.
        rgba: Read RGBA (else RGB), as frame 0 was rendered.
    """
    from OpenGL import GL
    from pyrender.constants import ProgramFlags, RenderFlags

    gl_renderer = renderer._renderer
    flags = RenderFlags.OFFSCREEN | (RenderFlags.RGBA if rgba else RenderFlags.NONE)
    programs = {
        id(primitive): gl_renderer._get_primitive_program(primitive, flags, ProgramFlags.USE_MATERIAL)
        for node in scene.mesh_nodes
        for primitive in node.mesh.primitives
    }
    # The lights' uniforms depend on the node only when pyrender must choose the nearest
    # lights (more lights than its shaders take); then they are bound per draw, as it does.
    light_cap = gl_renderer._compute_max_n_lights(flags)
    lights_per_node = (
        len(scene.directional_light_nodes) > light_cap[0]
        or len(scene.spot_light_nodes) > light_cap[1]
        or len(scene.point_light_nodes) > light_cap[2]
    )
    platform = renderer._platform
    platform.make_current()
    try:
        for index in range(1, len(out)):
            set_frame(index)
            gl_renderer._configure_forward_pass_viewport(flags)
            GL.glClearColor(*scene.bg_color)
            GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)
            GL.glEnable(GL.GL_MULTISAMPLE)
            _draw_meshes(gl_renderer, scene, programs, flags, lights_per_node)
            GL.glFlush()
            colour = gl_renderer._read_main_framebuffer(scene, flags)[0]
            out[index] = colour if rgba else colour[..., :3]
    finally:
        platform.make_uncurrent()


def _draw_meshes(
    gl_renderer: Any, scene: Any, programs: Mapping[int, Any], flags: int, lights_per_node: bool
) -> None:
    """pyrender's forward pass less what frame 0 already set (camera, lights, uploads)."""
    program = None
    # Sorted as pyrender sorts them, every frame: moved nodes may change the order.
    for node in gl_renderer._sorted_mesh_nodes(scene):
        if not node.mesh.is_visible:
            continue
        for primitive in node.mesh.primitives:
            program = programs[id(primitive)]
            program._bind()
            if lights_per_node:
                gl_renderer._bind_lighting(scene, program, node, flags)
            gl_renderer._bind_and_draw_primitive(primitive=primitive, pose=scene.get_pose(node), program=program,
                                                 flags=flags)  # fmt: skip
            gl_renderer._reset_active_textures()
    if program is not None:
        program._unbind()
