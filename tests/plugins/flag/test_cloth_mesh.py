"""Tests of physinfer_flag.cloth_mesh: grid, triangles, hinges, pinning, placement."""

from __future__ import annotations

import numpy as np
import pytest

from physinfer.errors import UserInputError
from physinfer_flag.cloth_mesh import build_flag_mesh, grid_faces


@pytest.fixture(scope="module")
def mesh():
    return build_flag_mesh(width=1.5, height=1.0, nu=31, nv=21, pin_mode="edge", top_z=2.95)


def test_counts_and_areas(mesh):
    nu, nv = 31, 21
    assert mesh.n_vertices == nu * nv
    assert mesh.faces.shape == (2 * (nu - 1) * (nv - 1), 3) and mesh.faces.dtype == np.int32
    n_edges = nu * (nv - 1) + nv * (nu - 1) + (nu - 1) * (nv - 1)
    assert mesh.edges.shape == (n_edges, 2)
    boundary = 2 * (nu - 1) + 2 * (nv - 1)
    assert mesh.hinges.shape == (n_edges - boundary, 4)
    assert mesh.face_area.sum() == pytest.approx(1.5)
    assert mesh.node_area.sum() == pytest.approx(1.5)
    assert mesh.spacing == pytest.approx(0.05)


def test_rest_shape_sits_on_the_pole_and_extends_to_plus_x(mesh):
    hoist = mesh.uv[:, 0] == 0
    np.testing.assert_allclose(mesh.rest[hoist, :2], 0.0)
    assert mesh.rest[:, 0].max() == pytest.approx(1.5)
    assert mesh.rest[:, 2].max() == pytest.approx(2.95) and mesh.rest[:, 2].min() == pytest.approx(1.95)
    # uv: u from hoist 0 to fly 1, v from bottom 0 to top 1.
    assert mesh.uv.min() == 0 and mesh.uv.max() == 1
    top = mesh.uv[:, 1] == 1
    assert np.all(mesh.rest[top, 2] == mesh.rest[:, 2].max())


def test_triangles_are_consistently_oriented(mesh):
    p = mesh.rest[mesh.faces]
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(normals[:, 1] < 0) or np.all(normals[:, 1] > 0)


def test_alternating_diagonals_use_both_directions():
    faces = grid_faces(3, 3)
    diagonals = {tuple(sorted(e)) for f in faces for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))
                 if abs(e[0] - e[1]) in (2, 4)}
    assert diagonals == {(0, 4), (2, 4), (4, 6), (4, 8)}  # an X pattern around the centre


def test_hinge_directions_fall_on_table_rows(mesh):
    # Square cells: every hinge is exactly 0, 45 or 90 degrees to the warp.
    values, counts = np.unique(np.round(mesh.hinge_direction, 9), return_counts=True)
    np.testing.assert_allclose(values, [0.0, 1.0, 2.0])
    assert counts.min() > 500
    h = mesh.hinges
    du = mesh.material_uv[h[:, 1]] - mesh.material_uv[h[:, 0]]
    horizontal = np.abs(du[:, 1]) < 1e-12
    assert np.all(mesh.hinge_direction[horizontal] == 0)


def test_hinge_faces_and_opposite_vertices_agree(mesh):
    for k in range(0, len(mesh.hinges), 97):
        e0, e1, o0, o1 = mesh.hinges[k]
        f0, f1 = mesh.faces[mesh.hinge_faces[k]]
        assert {e0, e1, o0} == set(f0) and {e0, e1, o1} == set(f1)
        # (e0, e1, o0) is the stored orientation of f0 (a cyclic rotation).
        assert tuple(f0) in {(e0, e1, o0), (e1, o0, e0), (o0, e0, e1)}


def test_pin_modes():
    edge = build_flag_mesh(width=1.5, height=1.0, nu=7, nv=5, pin_mode="edge", top_z=3.0)
    corners = build_flag_mesh(width=1.5, height=1.0, nu=7, nv=5, pin_mode="corners", top_z=3.0)
    assert edge.pinned.sum() == 5 and np.all(edge.uv[edge.pinned, 0] == 0)
    assert corners.pinned.sum() == 2
    np.testing.assert_array_equal(np.sort(corners.uv[corners.pinned, 1]), [0, 1])


@pytest.mark.parametrize(
    "kwargs, message",
    [({"nu": 2}, "at least 3x3"), ({"width": 0.0}, "positive"), ({"pin_mode": "top"}, "pin_mode")],
)
def test_bad_mesh_settings(kwargs, message):
    settings = {"width": 1.5, "height": 1.0, "nu": 5, "nv": 5, "pin_mode": "edge", "top_z": 3.0, **kwargs}
    with pytest.raises(UserInputError, match=message):
        build_flag_mesh(**settings)
