"""Tests of physinfer_flag.cloth_kernels: forces against energies, stiffness lookup, wind, limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physinfer_flag.cloth_kernels import (
    STATUS_NAN,
    STATUS_OK,
    STATUS_SPEED,
    add_bending_forces,
    add_face_forces,
    fast_atan2,
    frame_status,
    limit_strain,
    stretching_stiffness,
    update_stiffness,
)
from physinfer_flag.material import load_material

H = 0.05  # grid spacing of the test triangles


@pytest.fixture(scope="module")
def samples():
    return np.ascontiguousarray(load_material().stretching_samples())


def one_triangle():
    """A right triangle with legs H in material space: (faces, dm_inv, area, rest (3, 3))."""
    uv = np.array([[0.0, 0.0], [H, 0.0], [0.0, H]])
    dm = np.linalg.inv(np.stack([uv[1] - uv[0], uv[2] - uv[0]], axis=1))
    rest = np.stack([uv[:, 0], np.zeros(3), uv[:, 1]], axis=1)
    return np.array([[0, 1, 2]], np.int32), dm.reshape(1, 4).copy(), np.array([0.5 * H * H]), rest


def face_forces(x, v, samples, *, beta=0.0, wind=(1.0, 0.0, 0.0), rho=0.0, drag=0.0):
    faces, dm, area, _ = one_triangle()
    force = np.zeros((3, 3))
    normal = np.zeros((1, 3))
    inv_len = np.zeros(1)
    stiffness = np.zeros((1, 4))
    update_stiffness(x, faces, dm, samples, stiffness)
    add_face_forces(x, v, faces, dm, area, stiffness, beta, wind[0], wind[1], 0.0, wind[2], 0.0, 1.0, rho, drag,
                    force, normal, inv_len)
    return force, normal


def stretch_energy(x, samples):
    """ArcSim's membrane energy with the strain-0 stiffness (valid while compressed)."""
    _, dm, area, _ = one_triangle()
    k = 2 * np.maximum(samples[0, 0], 0)
    F = np.stack([x[1] - x[0], x[2] - x[0]], axis=1) @ dm.reshape(2, 2)
    G = 0.5 * (F.T @ F - np.eye(2))
    return area[0] * (0.5 * k[0] * G[0, 0] ** 2 + k[1] * G[0, 0] * G[1, 1] + 0.5 * k[2] * G[1, 1] ** 2
                      + k[3] * G[0, 1] ** 2)


def numeric_force(energy, x, h=1e-7):
    out = np.zeros_like(x)
    for i in range(x.shape[0]):
        for k in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, k] += h
            xm[i, k] -= h
            out[i, k] = -(energy(xp) - energy(xm)) / (2 * h)
    return out


def test_fast_atan2_matches_libm():
    rng = np.random.default_rng(0)
    pts = np.concatenate([rng.standard_normal((2000, 2)), [[0, 1], [0, -1], [1, 0], [-1, 0], [0, 0]]])
    err = max(abs(fast_atan2(y, x) - math.atan2(y, x)) for y, x in pts)
    assert err < 5e-8


def test_stretching_force_is_minus_energy_gradient(samples):
    rng = np.random.default_rng(1)
    _, _, _, rest = one_triangle()
    x = 0.97 * rest + 1e-3 * rng.standard_normal((3, 3))  # compressed: constant stiffness
    force, _ = face_forces(x, np.zeros((3, 3)), samples)
    expected = numeric_force(lambda y: stretch_energy(y, samples), x)
    np.testing.assert_allclose(force, expected, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(force.sum(axis=0), 0.0, atol=1e-12)


def test_rest_and_rigid_motion_give_no_stretching_force(samples):
    _, _, _, rest = one_triangle()
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for x in (rest, rest @ rot.T + 3.0):
        force, _ = face_forces(x, np.zeros((3, 3)), samples)
        np.testing.assert_allclose(force, 0.0, atol=1e-12)


def test_stiffness_lookup_follows_the_arcsim_table(samples):
    k_rest = stretching_stiffness(1.0, 1.0, 0.0, samples)
    np.testing.assert_allclose(k_rest, 2 * np.maximum(samples[0, 0], 0))
    # Stretch 1 + 1/6 along the warp (0 deg) and along the weft (90 deg).
    s = (7 / 6) ** 2
    np.testing.assert_allclose(stretching_stiffness(s, 1.0, 0.0, samples), 2 * np.maximum(samples[1, 0], 0), rtol=1e-5)
    np.testing.assert_allclose(stretching_stiffness(1.0, s, 0.0, samples), 2 * np.maximum(samples[1, 4], 0), rtol=1e-5)
    # Half-way in strain: the mean of the strain-0 and strain-1/6 samples.
    half = (1 + 1 / 12) ** 2
    np.testing.assert_allclose(
        stretching_stiffness(half, 1.0, 0.0, samples),
        2 * np.maximum(0.5 * (samples[0, 0] + samples[1, 0]), 0), rtol=1e-5,
    )
    # Orthotropic symmetry: a principal direction at +phi and -phi looks the same.
    c = np.array([[1.2, 0.1], [0.1, 1.05]])
    m = np.array([[1, 0], [0, -1]])
    np.testing.assert_allclose(stretching_stiffness(c[0, 0], c[1, 1], c[0, 1], samples),
                               stretching_stiffness(*(m @ c @ m)[[0, 1, 0], [0, 1, 1]], samples))


def test_damping_opposes_stretching_rate(samples):
    _, _, _, rest = one_triangle()
    v = np.zeros((3, 3))
    v[1, 0] = 1.0  # node 1 moves away along the warp: the edge lengthens
    force, _ = face_forces(rest, v, samples, beta=1e-3)
    assert force[1, 0] < 0 and force[0, 0] > 0


def test_wind_pressure_and_drag(samples):
    _, _, area, rest = one_triangle()
    still = np.zeros((3, 3))
    # Wind along +y hits the x-z triangle face-on: rho A U^2 along +y, whatever the normal's sign.
    for x in (rest, rest[[0, 2, 1]]):
        force, normal = face_forces(x, still, samples, wind=(0.0, 1.0, 5.0), rho=1.2)
        np.testing.assert_allclose(force.sum(axis=0), [0, 1.2 * area[0] * 25, 0], rtol=1e-12, atol=1e-15)
        assert abs(normal[0, 1]) == pytest.approx(1.0)
    # Wind along +x slides over it: only the tangential drag c A U.
    force, _ = face_forces(rest, still, samples, wind=(1.0, 0.0, 5.0), rho=1.2, drag=0.05)
    np.testing.assert_allclose(force.sum(axis=0), [0.05 * area[0] * 5, 0, 0], rtol=1e-12, atol=1e-15)
    # A face moving with the wind feels nothing.
    force, _ = face_forces(rest, np.tile([0.0, 5.0, 0.0], (3, 1)), samples, wind=(0.0, 1.0, 5.0), rho=1.2)
    np.testing.assert_allclose(force, 0.0, atol=1e-15)


def hinge_setup(theta_scale=0.3, seed=0):
    rng = np.random.default_rng(seed)
    x = np.array([[0, 0, 0], [1, 0, 0], [0.4, 1, 0], [0.6, -1, 0]], float) + theta_scale * rng.standard_normal((4, 3))
    faces = np.array([[0, 1, 2], [1, 0, 3]], np.int32)
    hinges = np.array([[0, 1, 2, 3]], np.int32)
    return x, faces, hinges


def hinge_forces(x, faces, hinges, curve, length=1.0, area=1.0):
    normal = np.zeros((2, 3))
    inv_len = np.zeros(2)
    for f in range(2):
        n = np.cross(x[faces[f, 1]] - x[faces[f, 0]], x[faces[f, 2]] - x[faces[f, 0]])
        normal[f] = n / np.linalg.norm(n)
        inv_len[f] = 1 / np.linalg.norm(n)
    force = np.zeros((4, 3))
    add_bending_forces(x, hinges, np.array([[0, 1]], np.int32), np.array([length / (10 * area)]),
                       np.array([length**2 / (4 * area)]), curve, normal, inv_len, force)
    return force


def dihedral(x):
    e = x[1] - x[0]
    n0 = np.cross(e, x[2] - x[0])
    n1 = np.cross(x[3] - x[0], e)
    n0, n1 = n0 / np.linalg.norm(n0), n1 / np.linalg.norm(n1)
    return math.atan2(np.dot(np.cross(n0, n1), e) / np.linalg.norm(e), np.dot(n0, n1))


def test_bending_force_is_minus_energy_gradient():
    x, faces, hinges = hinge_setup()
    ke = 2e-4
    force = hinge_forces(x, faces, hinges, np.full((1, 5), ke))
    expected = numeric_force(lambda y: ke * 1.0 / 2.0 * dihedral(y) ** 2 / 4, x, h=1e-6)
    np.testing.assert_allclose(force, expected, rtol=1e-5, atol=1e-12)
    np.testing.assert_allclose(force.sum(axis=0), 0.0, atol=1e-15)


def test_flat_hinge_has_no_bending_force():
    x, faces, hinges = hinge_setup(theta_scale=0.0)
    np.testing.assert_allclose(hinge_forces(x, faces, hinges, np.full((1, 5), 1e-4)), 0.0, atol=1e-18)


def test_bending_stiffness_interpolates_in_half_curvature():
    # With l = A = 1 the half-curvature is |theta| / 2 (1/m); pick curve samples 1..5 and a
    # hinge whose half-curvature sits between two samples: ke must interpolate linearly.
    x, faces, hinges = hinge_setup(theta_scale=0.3, seed=3)
    theta = abs(dihedral(x))
    area = theta / (2 * 7.5)  # half-curvature |theta| l / (2 A) = 7.5 1/m, between c05 and c10
    curve = np.array([[1.0, 2.0, 3.0, 4.0, 5.0]])
    unit = hinge_forces(x, faces, hinges, np.ones((1, 5)), area=area)
    force = hinge_forces(x, faces, hinges, curve, area=area)
    np.testing.assert_allclose(force, 2.5 * unit, rtol=1e-7)


def test_strain_limit_pulls_back_long_edges_but_not_pins():
    x = np.array([[0.0, 0.0, 0.0], [1.2, 0.0, 0.0]])
    v = np.zeros((2, 3))
    limit_strain(x, v, np.array([0.0, 10.0]), np.array([[0, 1]], np.int32), np.array([1.0]), 0.05, 1e-3)
    np.testing.assert_allclose(x[0], 0.0)
    assert np.linalg.norm(x[1] - x[0]) == pytest.approx(1.05)
    assert v[1, 0] == pytest.approx(-0.15 / 1e-3)


def test_frame_status_detects_nan_and_speed():
    x = np.zeros((3, 3))
    v = np.zeros((3, 3))
    assert frame_status(x, v, 10.0, 5.0) == STATUS_OK
    v[1, 2] = 11.0
    assert frame_status(x, v, 10.0, 5.0) == STATUS_SPEED
    x[2, 0] = np.nan
    v[1, 2] = 0.0
    assert frame_status(x, v, 10.0, 5.0) == STATUS_NAN
