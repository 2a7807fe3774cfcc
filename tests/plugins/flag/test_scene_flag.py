"""The flag's scene settings: size, pinning and pole height reach the simulator and renderer.

A scene of defaults is today's flag bit for bit; a 3 m flag is meshed at the same 5 cm and
flies further; ``pinning=corners`` leaves the hoist's middle free; the renderer frames a
3 m flag as it frames a 1.5 m one; a scene's pole height draws the pole of a trajectory
that carries none.
"""

import numpy as np
import pytest

from physinfer.types import Trajectory
from physinfer_flag.flag_scene import measure_flag
from physinfer_flag.phenomenon import DEFAULT_TRUTH_BASE, make_renderer, make_simulator

DEFAULT = {"flag_length": 1.5, "flag_height": 1.0, "pinning": "hoist", "pole_height": 3.0}
#: Short clips: the warm-up (2 s) and 10 recorded frames.
SHORT = 0.4


def scene(**changes):
    return {**DEFAULT, **changes}


def test_the_default_scene_is_the_default_flag_bit_for_bit():
    plain, scened = (
        make_simulator(duration_s=SHORT),
        make_simulator(duration_s=SHORT, scene=DEFAULT),
    )
    assert plain.config == scened.config
    a = plain.simulate(DEFAULT_TRUTH_BASE, seed=3).vertices
    b = scened.simulate(DEFAULT_TRUTH_BASE, seed=3).vertices
    assert np.array_equal(a, b)


@pytest.mark.parametrize(
    ("length", "height", "grid"), [(0.9, 0.6, (19, 13)), (3.0, 2.0, (61, 41)), (1.2, 1.0, (25, 21))]
)
def test_other_sizes_keep_5_cm_cells_and_the_default_time_step(length, height, grid):
    config = make_simulator(scene=scene(flag_length=length, flag_height=height)).config
    assert (config.width, config.height) == (length, height)
    assert (config.grid_u, config.grid_v) == grid
    assert config.spacing == pytest.approx(0.05)
    # The explicit limit is set by the cell size, not the flag's: the default step.
    assert config.dt == pytest.approx(1 / 1200)


def test_a_3_m_flag_flies_further_than_the_default_one():
    wind = {"wind_speed": 5.0}
    spans = {}
    for length, height in ((1.5, 1.0), (3.0, 2.0)):
        simulator = make_simulator(
            duration_s=SHORT, scene=scene(flag_length=length, flag_height=height)
        )
        vertices = simulator.simulate(wind, seed=0).vertices
        # The reach downwind of the pole.
        spans[length] = float(np.median(vertices[:, :, 0].max(axis=1)))
    assert spans[1.5] > 1.0, spans
    assert spans[3.0] > 1.7 * spans[1.5], spans


def test_corner_pinning_leaves_the_middle_of_the_hoist_free():
    small = {"flag_length": 0.9, "flag_height": 0.6}
    corners = make_simulator(duration_s=SHORT, scene=scene(pinning="corners", **small))
    hoist = make_simulator(duration_s=SHORT, scene=scene(**small))
    nu, nv = corners.config.grid_u, corners.config.grid_v
    hoist_nodes = np.arange(nv) * nu
    assert corners.mesh.pinned[hoist_nodes].tolist() == [True] + [False] * (nv - 2) + [True]
    assert hoist.mesh.pinned[hoist_nodes].all()
    middle = hoist_nodes[nv // 2]
    moved = {}
    for name, simulator in (("corners", corners), ("hoist", hoist)):
        vertices = simulator.simulate({"wind_speed": 6.0}, seed=0).vertices
        moved[name] = float(np.abs(vertices[:, middle, :2]).max())  # off the pole (x = y = 0)
    assert moved["hoist"] == 0.0
    assert moved["corners"] > 0.03, moved


def silhouette_share(clip, background) -> float:
    """Share of pixels that differ from the empty background, over the clip."""
    diff = np.abs(clip.frames.astype(np.int16) - background.astype(np.int16)).max(axis=-1)
    return float((diff > 24).mean())


def test_the_renderer_frames_a_3_m_flag_like_a_1_5_m_one():
    from physinfer_flag.backgrounds import background_image

    renderer = make_renderer()
    zeta = {**renderer.default_render_params, "image_size": 96}
    background = background_image(zeta["background"], (96, 96))
    shares = {}
    try:
        for length, height in ((1.5, 1.0), (3.0, 2.0)):
            simulator = make_simulator(
                duration_s=0.2, scene=scene(flag_length=length, flag_height=height)
            )
            shares[length] = silhouette_share(
                renderer.render(simulator.simulate({"wind_speed": 5.0}), zeta), background
            )
    finally:
        renderer.close()
    assert 0.15 < shares[1.5] < 0.7, shares
    assert shares[3.0] == pytest.approx(shares[1.5], rel=0.2)


def test_a_scene_pole_height_places_the_pole_of_a_trajectory_without_one():
    trajectory = make_simulator(
        duration_s=0.04, scene=scene(flag_length=0.9, flag_height=0.6)
    ).simulate({})
    bare = Trajectory(
        trajectory.vertices, trajectory.faces, trajectory.fps, {"uv": trajectory.extras["uv"]}
    )
    assert measure_flag(trajectory).pole[:, 2].tolist() == pytest.approx([0.0, 3.0])
    assert measure_flag(bare, pole_height=4.0).pole[:, 2].tolist() == pytest.approx([0.0, 4.0])
    assert make_renderer(scene(pole_height=4.0)).pole_height == 4.0
    top = float(bare.vertices[0, :, 2].max())
    assert measure_flag(bare).pole[0, 2] < top - 2.0  # without one: 3 fly lengths down
