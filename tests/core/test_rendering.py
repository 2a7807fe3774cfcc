"""Tests of :mod:`physinfer.rendering`: camera poses and the reusable headless context."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physinfer.rendering import OffscreenContext, look_at, spherical_camera, use_headless_gl


def triangle_scene(offset: float = 0.0) -> tuple[object, object]:
    """A scene with one white triangle in front of the camera, and that triangle's primitive."""
    import pyrender

    positions = np.array([[-0.5 + offset, -0.5, 0.0], [0.5 + offset, -0.5, 0.0], [offset, 0.5, 0.0]], np.float32)
    normals = np.tile(np.array([[0.0, 0.0, 1.0]], np.float32), (3, 1))
    material = pyrender.MetallicRoughnessMaterial(baseColorFactor=[1.0, 1.0, 1.0, 1.0])
    primitive = pyrender.Primitive(positions=positions, normals=normals, indices=np.array([[0, 1, 2]]),
                                   material=material)
    scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[1.0, 1.0, 1.0])
    scene.add(pyrender.Mesh([primitive]))
    scene.add(pyrender.PerspectiveCamera(yfov=1.0), pose=look_at(np.array([0.0, 0.0, 2.0]), np.zeros(3),
                                                                 up=np.array([0.0, 1.0, 0.0])))
    return scene, primitive


def test_use_headless_gl_selects_egl_and_a_headless_pyglet(monkeypatch: pytest.MonkeyPatch) -> None:
    """pyrender imports pyglet, which wants an X display unless told it is headless (issue 45)."""
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    monkeypatch.delenv("PYGLET_HEADLESS", raising=False)
    use_headless_gl()
    import os

    assert os.environ["PYOPENGL_PLATFORM"] == "egl" and os.environ["PYGLET_HEADLESS"] == "1"
    monkeypatch.setenv("PYOPENGL_PLATFORM", "osmesa")
    monkeypatch.setenv("PYGLET_HEADLESS", "0")
    use_headless_gl()  # what the user chose stays
    assert os.environ["PYOPENGL_PLATFORM"] == "osmesa" and os.environ["PYGLET_HEADLESS"] == "0"


def test_look_at_points_the_camera_minus_z_axis_at_the_target() -> None:
    eye, target = np.array([1.0, -3.0, 2.0]), np.array([0.0, 0.0, 1.0])
    pose = look_at(eye, target)
    forward = (target - eye) / np.linalg.norm(target - eye)
    np.testing.assert_allclose(-pose[:3, 2], forward, atol=1e-12)
    np.testing.assert_allclose(pose[:3, 3], eye)
    np.testing.assert_allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-12)
    assert pose[2, 1] > 0, "image up has a positive z component"
    straight_down = look_at(np.array([0.0, 0.0, 5.0]), np.zeros(3))
    assert np.isfinite(straight_down).all()


def test_spherical_camera_azimuth_zero_looks_along_plus_x() -> None:
    pose = spherical_camera(np.zeros(3), 4.0, 0.0, 0.0)
    np.testing.assert_allclose(pose[:3, 3], [-4.0, 0.0, 0.0], atol=1e-12)


def test_rgba_render_has_coverage_alpha() -> None:
    scene, _ = triangle_scene()
    context = OffscreenContext(32, 32)
    try:
        rgba = context.render(scene, rgba=True)
        rgb = context.render(scene)
    finally:
        context.close()
    assert rgba.shape == (32, 32, 4) and rgb.shape == (32, 32, 3)
    assert rgba[0, 0, 3] == 0 and rgba[16, 16, 3] == 255
    np.testing.assert_array_equal(rgba[..., :3], rgb)


def test_colour_only_readback_gives_pyrenders_pixels() -> None:
    """The context reads back only the colour (no depth); pyrender's own reader, which
    reads both, gives the same pixels, RGB and RGBA."""
    import pyrender

    scene, _ = triangle_scene(offset=0.1)
    context = OffscreenContext(48, 40)
    try:
        ours = context.render(scene), context.render(scene, rgba=True)
        renderer = context._renderer
        own_reader = type(renderer._renderer)._read_main_framebuffer.__get__(renderer._renderer)
        renderer._renderer._read_main_framebuffer = own_reader
        theirs = renderer.render(scene)[0], renderer.render(scene, flags=pyrender.RenderFlags.RGBA)[0]
    finally:
        context.close()
    assert ours[0].shape == (40, 48, 3) and ours[1].shape == (40, 48, 4)
    np.testing.assert_array_equal(ours[0], theirs[0])
    np.testing.assert_array_equal(ours[1], theirs[1])
    assert ours[1][..., 3].max() == 255


def test_update_vertices_reaches_the_gpu() -> None:
    moved_scene, _ = triangle_scene(offset=0.3)
    scene, primitive = triangle_scene()
    context = OffscreenContext(32, 32)
    try:
        before = context.render(scene)
        expected = context.render(moved_scene)
        context.update_vertices(primitive, primitive.positions + np.array([0.3, 0.0, 0.0], np.float32))
        after = context.render(scene)
    finally:
        context.close()
    assert np.abs(before.astype(int) - after).max() > 100
    np.testing.assert_array_equal(after, expected)


def test_closing_one_context_keeps_the_others_working() -> None:
    # pyrender's own delete() terminates the EGL display that all contexts share.
    first, second = OffscreenContext(16, 16), OffscreenContext(16, 16)
    scene_a, _ = triangle_scene()
    scene_b, _ = triangle_scene()
    try:
        reference = first.render(scene_a)
        second.render(scene_b)
        second.close()
        np.testing.assert_array_equal(first.render(scene_a), reference)
    finally:
        first.close()
        second.close()
    third = OffscreenContext(16, 16)
    try:
        np.testing.assert_array_equal(third.render(triangle_scene()[0]), reference)
    finally:
        third.close()


def test_missing_mesh_shader_is_reported(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nope.frag"):
        OffscreenContext(8, 8, mesh_shaders=(tmp_path / "nope.vert", tmp_path / "nope.frag"))


def test_custom_mesh_shaders_are_used(tmp_path: Path) -> None:
    vertex = tmp_path / "flat.vert"
    vertex.write_text(
        "#version 330 core\nlayout(location = 0) in vec3 position;\nlayout(location = INST_M_LOC) in mat4 inst_m;\n"
        "uniform mat4 M;\nuniform mat4 V;\nuniform mat4 P;\n"
        "void main() { gl_Position = P * V * M * inst_m * vec4(position, 1.0); }\n"
    )
    fragment = tmp_path / "flat.frag"
    fragment.write_text("#version 330 core\nout vec4 frag_color;\nvoid main() { frag_color = vec4(0.0, 1.0, 0.0, 1.0); }\n")
    scene, _ = triangle_scene()
    context = OffscreenContext(32, 32, mesh_shaders=(vertex, fragment))
    try:
        image = context.render(scene)
    finally:
        context.close()
    np.testing.assert_array_equal(image[16, 16], [0, 255, 0])


def two_mesh_scene() -> tuple[object, object, object, object]:
    """Two triangles of different colours that cross as they move, a light and a camera:
    (scene, the moving node, the deforming primitive, the camera node)."""
    import pyrender

    scene, primitive = triangle_scene()
    red = pyrender.MetallicRoughnessMaterial(baseColorFactor=[0.9, 0.1, 0.1, 1.0], roughnessFactor=0.4)
    positions = np.array([[-0.4, -0.3, 0.1], [0.4, -0.3, 0.1], [0.0, 0.4, 0.1]], np.float32)
    other = pyrender.Primitive(positions=positions, normals=np.tile([[0.0, 0.0, 1.0]], (3, 1)).astype(np.float32),
                               indices=np.array([[0, 1, 2]]), material=red)
    moving = scene.add(pyrender.Mesh([other]))
    scene.add(pyrender.DirectionalLight(intensity=2.0), pose=look_at(np.array([1.0, 1.0, 2.0]), np.zeros(3)))
    return scene, moving, primitive, scene.main_camera_node


def animation(frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses of the moving node (it passes behind and in front of the other triangle, so the
    draw order changes) and vertices of the deforming triangle, ``frames`` long."""
    t = np.linspace(0.0, 1.0, frames)
    poses = np.tile(np.eye(4), (frames, 1, 1))
    poses[:, 0, 3], poses[:, 2, 3] = 0.6 * np.sin(6 * t), 0.3 * np.cos(5 * t)
    base = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.0, 0.5, 0.0]], np.float32)
    positions = base[None] + (0.2 * np.sin(np.outer(t, [3.0, 4.0, 5.0]))[..., None] * [1.0, 0.5, 0.0]).astype(np.float32)
    normals = np.tile(np.array([[0.0, 0.0, 1.0]], np.float32), (frames, 3, 1))
    return poses, positions, normals


@pytest.mark.parametrize("rgba", [False, True])
def test_a_sequence_gives_pyrenders_own_pixels_frame_by_frame(rgba: bool) -> None:
    """render_sequence (frames replayed, uniforms not re-uploaded) against a plain
    ``pyrender.OffscreenRenderer`` rendering each frame from scratch: bit for bit."""
    import pyrender
    from pyrender.shader_program import ShaderProgramCache

    frames = 12
    poses, positions, normals = animation(frames)
    scene, moving, primitive, _ = two_mesh_scene()
    context = OffscreenContext(40, 32)
    try:
        ours = context.render_sequence(scene, poses={moving: poses}, vertices={primitive: (positions, normals)},
                                       rgba=rgba)
    finally:
        context.close()
    reference_scene, reference_moving, reference_primitive, _ = two_mesh_scene()
    # pyrender's own renderer, program cache and reader, in a context closed as ours are (a
    # bare OffscreenRenderer's delete() would end the EGL display every context shares).
    reference = OffscreenContext(40, 32)
    reference._ensure_renderer()
    renderer = reference._renderer
    gl_renderer = renderer._renderer
    gl_renderer._read_main_framebuffer = type(gl_renderer)._read_main_framebuffer.__get__(gl_renderer)
    gl_renderer._program_cache = ShaderProgramCache()
    try:
        theirs = []
        for i in range(frames):
            reference_scene.set_pose(reference_moving, poses[i])
            reference_scene.remove_node(next(iter(reference_scene.get_nodes(obj=next(
                m for m in reference_scene.meshes if reference_primitive in m.primitives)))))
            reference_primitive = pyrender.Primitive(
                positions=positions[i], normals=normals[i], indices=np.array([[0, 1, 2]]),
                material=reference_primitive.material)
            reference_scene.add(pyrender.Mesh([reference_primitive]))
            flags = pyrender.RenderFlags.RGBA if rgba else pyrender.RenderFlags.NONE
            theirs.append(renderer.render(reference_scene, flags=flags)[0])
    finally:
        reference.close()
    assert ours.shape == (frames, 32, 40, 4 if rgba else 3)
    assert len({frame.tobytes() for frame in ours}) == frames, "every frame differs"
    np.testing.assert_array_equal(ours, np.stack(theirs)[..., : ours.shape[-1]])


def test_a_moved_camera_is_seen_although_uniforms_are_remembered() -> None:
    """The programs skip re-uploading a uniform they hold; a changed one (the camera's
    matrices) is uploaded: the moved view equals a fresh context's."""
    scene, _, _, camera = two_mesh_scene()
    fresh_scene, _, _, fresh_camera = two_mesh_scene()
    moved = look_at(np.array([0.4, 0.2, 2.0]), np.zeros(3), up=np.array([0.0, 1.0, 0.0]))
    context, fresh = OffscreenContext(32, 32), OffscreenContext(32, 32)
    try:
        before = context.render(scene)
        scene.set_pose(camera, moved)
        after = context.render(scene)
        fresh_scene.set_pose(fresh_camera, moved)
        expected = fresh.render(fresh_scene)
    finally:
        context.close()
        fresh.close()
    assert np.abs(before.astype(int) - after).max() > 50
    np.testing.assert_array_equal(after, expected)


def test_a_sequence_needs_one_frame_count_and_its_own_scene() -> None:
    scene, moving, primitive, camera = two_mesh_scene()
    poses, positions, normals = animation(4)
    context = OffscreenContext(16, 16)
    try:
        with pytest.raises(ValueError, match=r"one frame count >= 1.*\[3, 4\]"):
            context.render_sequence(scene, poses={moving: poses}, vertices={primitive: (positions[:3], normals[:3])})
        with pytest.raises(ValueError, match="one frame count"):
            context.render_sequence(scene)
        _, other_primitive = triangle_scene()
        with pytest.raises(ValueError, match="must be in the scene"):
            context.render_sequence(scene, vertices={other_primitive: (positions, normals)})
        with pytest.raises(ValueError, match="mesh nodes only"):
            context.render_sequence(scene, poses={camera: poses})
        import pyrender

        carrier = scene.add(pyrender.Mesh([pyrender.Primitive(positions=positions[0], indices=np.array([[0, 1, 2]]))]))
        scene.add(pyrender.PointLight(intensity=1.0), parent_node=carrier)
        with pytest.raises(ValueError, match="mesh nodes only"):
            context.render_sequence(scene, poses={carrier: poses})
    finally:
        context.close()


def test_closing_a_context_leaves_the_one_in_use_current() -> None:
    """A renderer closed while another renders (the garbage collector closing one that a
    failed run left open) used to leave no context current: the other's next GL call failed
    ("Link failure (0)" compiling a shader, seen once in the test suite)."""
    from OpenGL.EGL import eglGetCurrentContext
    from pyrender.constants import RenderFlags

    from physinfer.rendering import _handle

    scene, _ = triangle_scene()
    other_scene, _ = triangle_scene(offset=0.1)
    in_use, leaked = OffscreenContext(32, 32), OffscreenContext(32, 32)
    try:
        first = in_use.render(scene)
        leaked.render(other_scene)
        in_use._renderer._platform.make_current()  # in the middle of its render
        current = _handle(eglGetCurrentContext())
        leaked.close()
        assert current is not None and _handle(eglGetCurrentContext()) == current
        colour, _ = in_use._renderer._renderer.render(scene, RenderFlags.OFFSCREEN)  # no make_current again
        np.testing.assert_array_equal(colour, first)
    finally:
        in_use.close()
        leaked.close()
