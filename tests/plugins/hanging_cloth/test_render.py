"""Tests of physinfer_hanging_cloth.render: ζ, the contract, and what the picture shows."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer.testing import check_renderer
from physinfer.types import Trajectory
from physinfer_hanging_cloth.render import (
    HangingClothRenderer,
    HangingRenderParams,
    sample_fabric_look,
)
from physinfer_hanging_cloth.simulator import make_simulator

SMALL = {"image_size": 48}


@pytest.fixture(scope="module")
def trajectory() -> Trajectory:
    return make_simulator((), spacing=0.08, warmup_s=0.4, n_frames=3).simulate({}, seed=0)


@pytest.fixture(scope="module")
def renderer():
    r = HangingClothRenderer()
    yield r
    r.close()


def test_contract(renderer, trajectory):
    clip = check_renderer(renderer, trajectory, SMALL)
    assert clip.frames.shape == (3, 48, 48, 3)


def test_cloth_in_front_of_a_plain_backdrop(renderer, trajectory):
    zeta = {**SMALL, "pattern": "plain", "fabric_colour": "200,20,20", "backdrop_colour": [240, 240, 240]}
    frame = renderer.render(trajectory, zeta).frames[0].astype(int)
    red = (frame[..., 0] > 150) & (frame[..., 1] < 90)
    assert 0.05 < red.mean() < 0.7  # the fabric fills part of the view
    corner = frame[:4, :4]
    assert (np.abs(corner - 240) < 30).all()  # the backdrop shows around it
    without_rod = renderer.render(trajectory, {**zeta, "rod": "false"}).frames[0]
    assert np.any(without_rod != frame)


def test_camera_angle_changes_the_view(renderer, trajectory):
    a = renderer.render(trajectory, {**SMALL, "camera_azimuth_deg": 0}).frames[0]
    b = renderer.render(trajectory, {**SMALL, "camera_azimuth_deg": 45}).frames[0]
    assert np.abs(a.astype(int) - b.astype(int)).mean() > 2


def test_zeta_coercion_and_sampling():
    params = HangingRenderParams.from_mapping(
        {"image_size": "32,48", "fabric_colour": "1,2,3", "light_direction": "0,1,-1", "rod": "no", "framing": "1.2"}
    )
    assert params.size == (32, 48) and params.fabric_colour == (1, 2, 3) and params.rod is False
    rng = np.random.default_rng(0)
    zeta = HangingClothRenderer().sample_render_params(rng)
    assert HangingRenderParams.from_mapping(zeta).to_dict() == zeta
    look = sample_fabric_look(np.random.default_rng(1))
    assert set(look) == {"pattern", "fabric_colour", "accent_colour", "pattern_repeats"}


@pytest.mark.parametrize(
    ("zeta", "message"),
    [
        ({"texture": "x"}, "unknown hanging-cloth render parameter"),
        ({"pattern": "tartan"}, "pattern"),
        ({"fabric_colour": "1,2"}, "wrong type"),
        ({"backdrop_colour": [0, 0, 999]}, "backdrop_colour"),
        ({"camera_azimuth_deg": 120}, "camera_azimuth_deg"),
        ({"image_size": 8}, "image_size"),
        ({"light_direction": [0, 0, 0]}, "light_direction"),
        ({"fov_deg": 200}, "fov_deg"),
    ],
)
def test_bad_zeta_is_refused(zeta, message):
    with pytest.raises(UserInputError, match=message):
        HangingRenderParams.from_mapping(zeta)


def test_bad_trajectories_are_refused(renderer, trajectory):
    empty = Trajectory(trajectory.vertices[:0], trajectory.faces, trajectory.fps, {})
    with pytest.raises(UserInputError, match="no frames"):
        renderer.render(empty, SMALL)
    broken = trajectory.vertices.copy()
    broken[0, 0, 0] = np.nan
    with pytest.raises(UserInputError, match="NaN"):
        renderer.render(Trajectory(broken, trajectory.faces, trajectory.fps, {}), SMALL)
    bad_uv = Trajectory(trajectory.vertices, trajectory.faces, trajectory.fps, {"uv": np.zeros((3, 2))})
    with pytest.raises(UserInputError, match="uv"):
        renderer.render(bad_uv, SMALL)


def test_trajectory_without_extras_still_renders(renderer, trajectory):
    bare = Trajectory(trajectory.vertices, trajectory.faces, trajectory.fps, {})
    assert renderer.render(bare, SMALL).frames.std() > 1.0


def test_camera_is_fixed_whatever_the_pose():
    from physinfer_hanging_cloth.render import hanging_length

    sim = make_simulator((), spacing=0.08, warmup_s=0.4, n_frames=3)
    calm = sim.simulate({}, seed=0)
    blown = make_simulator((), spacing=0.08, warmup_s=1.0, n_frames=3, fan_level="W3").simulate(
        {"area_weight": 0.05}, seed=0
    )
    assert np.ptp(blown.vertices[0, :, 2]) < 0.8 * sim.config.height  # blown up, shorter on screen
    for traj in (calm, blown):
        assert hanging_length(traj) == pytest.approx(sim.config.height, rel=0.06)
