"""Tests of the flag renderer on headless pyrender (EGL; Mesa's llvmpipe on CPU machines).

Trajectories come from :func:`physinfer_flag.flag_scene.waving_sheet`, a synthetic 2:3 sheet
with a travelling wave that follows the cloth simulator's contract, so these tests do not
depend on the simulator.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from physinfer.errors import UserInputError
from physinfer.testing import check_renderer
from physinfer.types import Trajectory
from physinfer_flag.backgrounds import BACKGROUND_NAMES
from physinfer_flag.flag_scene import measure_flag, waving_sheet
from physinfer_flag.render import FlagRenderer
from physinfer_flag.render_params import FlagRenderParams
from physinfer_flag.sheet_render import DoubleSidedSheet, composite_over
from physinfer_flag.textures import FLAG_NAMES

SMALL = {"image_size": 64}
MAGENTA = (255, 0, 255)


@pytest.fixture(scope="module")
def renderer() -> Iterator[FlagRenderer]:
    r = FlagRenderer()
    yield r
    r.close()


@pytest.fixture
def magenta_background(tmp_path: Path) -> str:
    """A flat magenta image: pixels of any other colour belong to the flag (or pole)."""
    path = tmp_path / "magenta.png"
    Image.fromarray(np.full((8, 8, 3), MAGENTA, dtype=np.uint8)).save(path)
    return str(path)


def flag_mask(frame: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: pixels that differ from the magenta background."""
    return np.abs(frame.astype(int) - np.array(MAGENTA)).max(axis=-1) > 40


def rotated_about_pole(trajectory: Trajectory, degrees: list[float]) -> Trajectory:
    """Frames of the first frame turned about the pole (z axis): same size, same hoist."""
    first = trajectory.vertices[0]
    frames = []
    for angle in np.radians(degrees):
        c, s = np.cos(angle), np.sin(angle)
        rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=np.float32)
        frames.append(first @ rotation.T)
    return Trajectory(np.stack(frames), trajectory.faces, trajectory.fps, dict(trajectory.extras))


def test_clip_has_trajectory_length_size_and_fps(renderer: FlagRenderer) -> None:
    trajectory = waving_sheet(n_frames=4, fps=25.0)
    clip = renderer.render(trajectory, {"image_size": (48, 80)})
    assert clip.frames.shape == (4, 48, 80, 3)
    assert clip.frames.dtype == np.uint8
    assert clip.fps == 25.0


def test_renderer_meets_the_renderer_contract(renderer: FlagRenderer) -> None:
    check_renderer(renderer, waving_sheet(n_frames=3), SMALL)


def test_default_image_size_is_224(renderer: FlagRenderer) -> None:
    clip = renderer.render(waving_sheet(n_frames=1))
    assert clip.size == (224, 224)


def test_renders_are_deterministic_for_fixed_params(renderer: FlagRenderer) -> None:
    trajectory = waving_sheet(n_frames=5)
    zeta = renderer.sample_render_params(np.random.default_rng(3)) | SMALL
    first = renderer.render(trajectory, zeta).frames
    np.testing.assert_array_equal(first, renderer.render(trajectory, zeta).frames)
    other = FlagRenderer()
    try:
        np.testing.assert_array_equal(first, other.render(trajectory, zeta).frames)
    finally:
        other.close()


def test_draw_order_does_not_depend_on_object_ids(renderer: FlagRenderer) -> None:
    # pyrender sorts solid meshes by their node origin's distance from the camera and
    # leaves ties in set order (object ids). Where the flag enters the pole, a sample
    # can have equal depths for both, so a tie made renders differ between processes.
    for seed in range(20):
        zeta = renderer.sample_render_params(np.random.default_rng(seed))
        trajectory = waving_sheet(n_frames=1, length=[1.5, 3.0][seed % 2], height=[1.0, 2.0][seed % 2])
        geometry = measure_flag(trajectory)
        sheet = DoubleSidedSheet(trajectory.faces, trajectory.vertices.shape[1])
        scene, _ = renderer._build_scene(trajectory, geometry, sheet, FlagRenderParams.from_mapping(zeta))
        camera = scene.get_pose(scene.main_camera_node)[:3, 3]
        distances = sorted(float(np.linalg.norm(scene.get_pose(n)[:3, 3] - camera)) for n in scene.mesh_nodes)
        assert len(distances) == 2 and distances[1] - distances[0] > 1e-6, distances


def test_flag_pixels_move_when_the_sheet_moves(renderer: FlagRenderer) -> None:
    moving = renderer.render(waving_sheet(n_frames=6, amplitude=0.3), SMALL).frames.astype(int)
    changed = (np.abs(np.diff(moving, axis=0)).max(axis=-1) > 20).mean(axis=(1, 2))
    assert (changed > 0.01).all(), f"fraction of pixels changing per frame: {changed}"
    still = renderer.render(waving_sheet(n_frames=3, amplitude=0.0), SMALL).frames
    np.testing.assert_array_equal(still[0], still[1])
    np.testing.assert_array_equal(still[0], still[2])


def test_per_frame_vertex_update_matches_a_freshly_built_scene(renderer: FlagRenderer) -> None:
    # Turning the sheet about the pole keeps its measured size and hoist, hence the camera,
    # so the last frame rendered through the in-place vertex update must equal a scene
    # built from that pose directly.
    turned = rotated_about_pole(waving_sheet(n_frames=1, amplitude=0.1), [0.0, 25.0, 50.0])
    sequence = renderer.render(turned, SMALL).frames
    assert np.abs(sequence[0].astype(int) - sequence[2]).max() > 50
    alone = Trajectory(turned.vertices[2:], turned.faces, turned.fps, dict(turned.extras))
    np.testing.assert_array_equal(sequence[2], renderer.render(alone, SMALL).frames[0])


def test_both_sides_of_the_flag_are_drawn_and_lit(renderer: FlagRenderer, magenta_background: str) -> None:
    # Reversing the winding swaps front and back; a double-sided flag looks the same.
    sheet = waving_sheet(n_frames=1, amplitude=0.2)
    flipped = Trajectory(sheet.vertices, sheet.faces[:, ::-1].copy(), sheet.fps, dict(sheet.extras))
    zeta = SMALL | {"background": magenta_background, "pole": False, "texture": "japan"}
    front = renderer.render(sheet, zeta).frames[0]
    back = renderer.render(flipped, zeta).frames[0]
    mask = flag_mask(front)
    assert mask.mean() > 0.15
    assert np.median(front[mask].astype(int).sum(axis=-1)) > 450, "the white field is lit, not dark"
    np.testing.assert_array_equal(front, back)


def test_texture_is_upright_with_hoist_at_the_pole(renderer: FlagRenderer, magenta_background: str) -> None:
    flat = waving_sheet(n_frames=1, amplitude=0.0)
    zeta = {"image_size": 96, "background": magenta_background, "pole": False}
    netherlands = renderer.render(flat, zeta | {"texture": "netherlands"}).frames[0].astype(int)
    rows, cols = np.nonzero(flag_mask(netherlands))
    top, bottom = netherlands[rows.min() + 3, int(cols.mean())], netherlands[rows.max() - 3, int(cols.mean())]
    assert top[0] > top[2] + 60, f"red on top, got {top}"
    assert bottom[2] > bottom[0] + 40, f"blue at the bottom, got {bottom}"
    france = renderer.render(flat, zeta | {"texture": "france"}).frames[0].astype(int)
    hoist, fly = france[int(rows.mean()), cols.min() + 3], france[int(rows.mean()), cols.max() - 3]
    assert hoist[2] > hoist[0] + 40, f"blue at the hoist (left), got {hoist}"
    assert fly[0] > fly[2] + 60, f"red at the fly (right), got {fly}"


@pytest.mark.parametrize(
    ("light", "ambient", "light_direction"),
    [(2.5, 0.3, (0.35, 0.8, -0.5)), (0.0, 0.3, (0.0, 1.0, 0.0)), (2.0, 0.0, (0.0, 1.0, 0.0)), (2.0, 0.2, (0.0, -1.0, 0.0))],
)
def test_white_cloth_brightness_follows_diffuse_lighting(
    renderer: FlagRenderer, magenta_background: str, light: float, ambient: float, light_direction: tuple
) -> None:
    # A flat white field facing the camera (normal -y): linear radiance is
    # ambient + intensity · max(n · -direction, 0) / π, shown with gamma 2.2. Light from
    # behind the flag (last case) leaves only the ambient term: the lit side is the one
    # the light falls on, whichever side the camera sees.
    zeta = SMALL | {"background": magenta_background, "pole": False, "texture": "japan",
                    "light_intensity": light, "ambient_intensity": ambient, "light_direction": light_direction}
    frame = renderer.render(waving_sheet(n_frames=1, amplitude=0.0), zeta).frames[0]
    rows, cols = np.nonzero(flag_mask(frame))
    white = frame[rows.min() + 3, cols.min() + 3].astype(float)
    d = np.asarray(light_direction, dtype=float) / np.linalg.norm(light_direction)
    linear = min(1.0, ambient + light * max(d[1], 0.0) / np.pi)
    expected = 255.0 * linear ** (1.0 / 2.2)
    np.testing.assert_allclose(white, expected, atol=3.0)


def test_flag_stays_in_view_flying_or_drooping(renderer: FlagRenderer, magenta_background: str) -> None:
    flying = waving_sheet(n_frames=1, length=3.0, height=2.0, hoist_top=8.0, amplitude=0.4)
    # Drooping in a light wind: the hoist stays on the pole, every row hangs 25° down.
    u, v = flying.extras["uv"].T
    droop = np.radians(25.0)
    drooped = np.stack(
        [3.0 * u * np.cos(droop), np.zeros_like(u), 8.0 - 2.0 * (1.0 - v) - 3.0 * u * np.sin(droop)], axis=1
    )
    both = Trajectory(np.stack([flying.vertices[0], drooped]).astype(np.float32), flying.faces, 25.0, flying.extras)
    zeta = SMALL | {"background": magenta_background, "pole": False, "texture": "germany"}
    for azimuth in (-15.0, 0.0, 15.0):
        for frame in renderer.render(both, zeta | {"camera_azimuth_deg": azimuth}).frames:
            mask = flag_mask(frame)
            assert mask.mean() > 0.1
            border = np.concatenate([mask[0], mask[-1], mask[:, 0], mask[:, -1]])
            assert not border.any(), f"flag touches the image border at azimuth {azimuth}"


def test_pole_is_drawn_when_asked(renderer: FlagRenderer, magenta_background: str) -> None:
    sheet = waving_sheet(n_frames=1)
    zeta = SMALL | {"background": magenta_background}
    with_pole = flag_mask(renderer.render(sheet, zeta | {"pole": True}).frames[0])
    without = flag_mask(renderer.render(sheet, zeta | {"pole": False}).frames[0])
    assert with_pole.sum() > without.sum() + 20
    assert with_pole[-1].any() and not without[-1].any(), "the pole reaches the bottom of the image"


def test_camera_more_than_15_degrees_off_the_wind_is_refused(renderer: FlagRenderer) -> None:
    for azimuth in (15.5, -20.0, 90.0):
        with pytest.raises(UserInputError, match="camera_azimuth_deg.*15"):
            renderer.render(waving_sheet(n_frames=1), {"camera_azimuth_deg": azimuth})
    FlagRenderParams.from_mapping({"camera_azimuth_deg": -15.0})


@pytest.mark.parametrize(
    ("zeta", "key"),
    [
        ({"zoom": 2}, "zoom"),
        ({"fov_deg": 170}, "fov_deg"),
        ({"fov_deg": "wide"}, "fov_deg"),
        ({"camera_elevation_deg": 80}, "camera_elevation_deg"),
        ({"camera_distance": -1}, "camera_distance"),
        ({"light_direction": [0, 0, 0]}, "light_direction"),
        ({"light_direction": [1, 2]}, "light_direction"),
        ({"light_intensity": -1}, "light_intensity"),
        ({"ambient_intensity": 2}, "ambient_intensity"),
        ({"texture": "atlantis"}, "texture"),
        ({"background": "/no/such/image.png"}, "background"),
        ({"image_size": 4}, "image_size"),
        ({"image_size": [1, 2, 3]}, "image_size"),
        ({"pole": "maybe"}, "pole"),
    ],
)
def test_bad_render_params_name_the_key(zeta: dict, key: str) -> None:
    with pytest.raises(UserInputError, match=key):
        FlagRenderParams.from_mapping(zeta)


def test_render_params_accept_command_line_strings() -> None:
    params = FlagRenderParams.from_mapping(
        {"image_size": "120,160", "light_direction": "0,1,-1", "pole": "off", "camera_distance": "auto", "fov_deg": "35"}
    )
    assert params.size == (120, 160)
    assert params.light_direction == (0.0, 1.0, -1.0)
    assert params.pole is False and params.camera_distance is None and params.fov_deg == 35.0
    # `physinfer simulate --render-set image_size=160` passes numbers as floats.
    assert FlagRenderParams.from_mapping({"image_size": 160.0}).size == (160, 160)
    with pytest.raises(UserInputError, match="image_size"):
        FlagRenderParams.from_mapping({"image_size": 160.5})


def test_check_render_params_completes_and_refuses_without_rendering() -> None:
    renderer = FlagRenderer()  # never renders: no GL context
    zeta = renderer.check_render_params({"image_size": 160.0, "pole": "false"})
    assert zeta == FlagRenderParams(image_size=160, pole=False).to_dict()
    with pytest.raises(UserInputError, match="camera_azimuth_deg"):
        renderer.check_render_params({"camera_azimuth_deg": 30})
    assert renderer._context is None


def test_default_render_params_are_complete_and_valid(renderer: FlagRenderer) -> None:
    defaults = dict(renderer.default_render_params)
    assert defaults == FlagRenderParams().to_dict()
    assert defaults["image_size"] == 224
    assert FlagRenderParams.from_mapping(defaults) == FlagRenderParams.from_mapping(None)


def test_sampled_params_are_valid_varied_and_reproducible(tmp_path: Path) -> None:
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(tmp_path / "photo.png")
    renderer = FlagRenderer(background_dir=tmp_path)  # never renders: no GL context
    draws = [renderer.sample_render_params(np.random.default_rng(seed)) for seed in range(60)]
    for zeta in draws:
        params = FlagRenderParams.from_mapping(zeta)
        assert abs(params.camera_azimuth_deg) <= 15.0
        assert params.light_direction[1] > 0, "sunlight comes from the camera's side"
    assert len({z["texture"] for z in draws}) >= 8
    assert len({z["background"] for z in draws}) >= 5
    assert str(tmp_path / "photo.png") in {z["background"] for z in draws}
    assert {z["background"] for z in draws} <= set(BACKGROUND_NAMES) | {str(tmp_path / "photo.png")}
    assert renderer.sample_render_params(np.random.default_rng(7)) == renderer.sample_render_params(
        np.random.default_rng(7)
    )


def test_texture_subset_for_sampling_is_checked() -> None:
    assert {FlagRenderer(textures=["japan"]).sample_render_params(np.random.default_rng(i))["texture"]
            for i in range(5)} == {"japan"}
    with pytest.raises(UserInputError, match="unknown flag texture"):
        FlagRenderer(textures=["japan", "mordor"])
    assert set(FLAG_NAMES) == set(FlagRenderer().textures)


def test_measure_flag_recovers_size_hoist_and_pole() -> None:
    trajectory = waving_sheet(length=3.0, height=2.0, hoist_top=6.0, amplitude=0.0)
    geometry = measure_flag(trajectory)
    assert geometry.length == pytest.approx(3.0, rel=1e-3)
    assert geometry.height == pytest.approx(2.0, rel=1e-3)
    np.testing.assert_allclose(geometry.hoist_top, [0.0, 0.0, 6.0], atol=1e-5)
    np.testing.assert_allclose(geometry.pole, trajectory.extras["pole"])
    # A waving, hence foreshortened, first frame gives the same size.
    waving = measure_flag(waving_sheet(length=3.0, height=2.0, amplitude=0.6))
    assert waving.length == pytest.approx(3.0, rel=1e-3)
    assert waving.height == pytest.approx(2.0, rel=1e-3)


def test_trajectory_without_extras_is_rendered(renderer: FlagRenderer) -> None:
    sheet = waving_sheet(n_frames=2)
    bare = Trajectory(sheet.vertices, sheet.faces, sheet.fps)
    geometry = measure_flag(bare)
    assert geometry.length == pytest.approx(1.5, rel=0.05)
    assert geometry.pole[1, 2] > geometry.hoist_top[2]
    with_extras = renderer.render(sheet, SMALL).frames
    without = renderer.render(bare, SMALL).frames
    assert np.abs(with_extras.astype(int) - without).mean() < 10


def test_malformed_extras_are_refused() -> None:
    sheet = waving_sheet(n_frames=1)
    with pytest.raises(UserInputError, match="uv"):
        measure_flag(Trajectory(sheet.vertices, sheet.faces, 25.0, {"uv": np.zeros((3, 2))}))
    with pytest.raises(UserInputError, match="pole"):
        measure_flag(Trajectory(sheet.vertices, sheet.faces, 25.0, {"uv": sheet.extras["uv"], "pole": np.zeros(3)}))


def test_empty_or_non_finite_trajectory_is_refused(renderer: FlagRenderer) -> None:
    sheet = waving_sheet(n_frames=2)
    empty = Trajectory(sheet.vertices[:0], sheet.faces, 25.0, dict(sheet.extras))
    with pytest.raises(UserInputError, match="no frames"):
        renderer.render(empty, SMALL)
    broken = sheet.vertices.copy()
    broken[1, 5, 2] = np.nan
    with pytest.raises(UserInputError, match="NaN"):
        renderer.render(Trajectory(broken, sheet.faces, 25.0, dict(sheet.extras)), SMALL)


def test_double_sided_sheet_normals_point_both_ways() -> None:
    sheet = waving_sheet(n_frames=1, amplitude=0.0)
    double = DoubleSidedSheet(sheet.faces, sheet.vertices.shape[1])
    positions, normals = double.buffers(sheet.vertices[0])
    n_vertices = sheet.vertices.shape[1]
    assert positions.shape == normals.shape == (2 * n_vertices, 3)
    np.testing.assert_allclose(np.abs(normals[:, 1]), 1.0, atol=1e-6)  # flat sheet in the xz plane
    np.testing.assert_allclose(normals[:n_vertices], -normals[n_vertices:])
    assert double.indices.shape == (2 * len(sheet.faces), 3)


def test_buffers_and_compositing_of_many_frames_equal_frame_by_frame() -> None:
    """``render_sheet`` computes every frame's buffers at once and composites blocks of
    frames: the same numbers as one frame at a time, to the last bit."""
    sheet = waving_sheet(n_frames=7)
    double = DoubleSidedSheet(sheet.faces, sheet.vertices.shape[1])
    positions, normals = double.buffers(sheet.vertices)
    for t in range(7):
        one_positions, one_normals = double.buffers(sheet.vertices[t])
        np.testing.assert_array_equal(positions[t], one_positions)
        np.testing.assert_array_equal(normals[t], one_normals)
    rng = np.random.default_rng(0)
    rgba = rng.integers(0, 256, (7, 5, 6, 4), dtype=np.uint8)
    background = rng.integers(0, 256, (5, 6, 3), dtype=np.uint8)
    np.testing.assert_array_equal(composite_over(rgba, background), [composite_over(f, background) for f in rgba])


def test_composite_over_blends_premultiplied_edges() -> None:
    rgba = np.array([[[0, 0, 0, 0], [200, 100, 0, 255], [100, 50, 0, 128]]], dtype=np.uint8)
    background = np.full((1, 3, 3), 100, dtype=np.uint8)
    out = composite_over(rgba, background)
    np.testing.assert_array_equal(out[0, 0], [100, 100, 100])
    np.testing.assert_array_equal(out[0, 1], [200, 100, 0])
    np.testing.assert_allclose(out[0, 2], [150, 100, 50], atol=1)
