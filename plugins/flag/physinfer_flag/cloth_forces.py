"""Compiled (numba) force kernels of the cloth solver: membrane, wind and bending.

The forces of one substep of :func:`physinfer_flag.cloth_kernels.run_flag`, for one flag:

1. stretching (Wang et al. 2011 / ArcSim: anisotropic St. Venant–Kirchhoff membrane whose
   four stiffnesses are looked up from the principal stretch and its direction by
   :func:`update_stiffness`), with Kelvin–Voigt damping ``β · Ġ``, and the wind force per
   face (:func:`add_face_forces`);
2. bending per hinge (:func:`add_bending_forces`: ArcSim's discrete dihedral-angle force
   with the Wang piecewise-linear stiffness in half-curvature).

Arrays are float64 (state) and int32 (indices); shapes are documented per function.
``fastmath`` is enabled without the no-NaN/no-inf assumptions, so blow-up checks work.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from physinfer_flag import cloth_numba, cloth_wind
from physinfer_flag.cloth_numba import FASTMATH, cache_depends_on  # first: numba's cache directory
from physinfer_flag.cloth_wind import shear_factor

# Abramowitz & Stegun 4.4.49: atan(z) on [0, 1] to 2e-8 rad.
_A2, _A4, _A6, _A8 = -0.3333314528, 0.1999355085, -0.1420889944, 0.1065626393
_A10, _A12, _A14, _A16 = -0.0752896400, 0.0429096138, -0.0161657367, 0.0028662257


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def fast_atan2(y: float, x: float) -> float:
    """``atan2(y, x)`` to 2e-8 rad: one division, a polynomial and selects, no branches.

    Dihedral angles change sign at random from hinge to hinge; a branchy atan2 pays a
    mispredicted branch for half of them, which doubled the cost of the bending pass.
    """
    ax = abs(x)
    ay = abs(y)
    hi = max(ax, ay)
    z = min(ax, ay) / (hi if hi > 0.0 else 1.0)
    # The degree-17 odd polynomial by Estrin's scheme: short dependency chains.
    w = z * z
    w2 = w * w
    w4 = w2 * w2
    q0 = (1.0 + _A2 * w) + (_A4 + _A6 * w) * w2
    q1 = (_A8 + _A10 * w) + (_A12 + _A14 * w) * w2
    a = z * (q0 + q1 * w4 + _A16 * (w4 * w4))
    a = 0.5 * math.pi - a if ay > ax else a
    a = math.pi - a if x < 0.0 else a
    return math.copysign(a, y)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def stretching_stiffness(
    c00: float, c11: float, c01: float, samples: np.ndarray
) -> tuple[float, float, float, float]:
    """ArcSim's stretching stiffnesses ``(k0, k1, k2, k3)`` in N/m for one triangle.

    Args:
        c00, c11, c01: Right Cauchy–Green tensor ``FᵀF`` of the triangle.
        samples: ``(2, 5, 4)`` table ``[strain 0 | stretch 1+1/6][direction][C11, C12, C22, shear]``.

    The principal stretch ``w = sqrt(λ_max)`` picks the strain weight ``6 (w - 1)`` in
    ``[0, 1)``; its direction, folded into ``[0°, 90°]`` by orthotropic symmetry, picks
    the direction weight between the five 22.5° samples. Negative results are clamped to
    zero and everything is doubled, as ArcSim does.
    """
    half_diff = 0.5 * (c00 - c11)
    lam = 0.5 * (c00 + c11) + math.sqrt(half_diff * half_diff + c01 * c01)
    # Branch-free on purpose: stretched and compressed triangles alternate unpredictably.
    sw = min(max((math.sqrt(max(lam, 0.0)) - 1.0) * 6.0, 0.0), 1.0 - 1e-6)
    # Major eigenvector angle of [[c00, c01], [c01, c11]], folded to [0, pi/2].
    aw = min(abs(0.5 * fast_atan2(c01, half_diff)) * (8.0 / math.pi), 4.0 - 1e-6)
    ai = int(aw)
    aw -= ai
    w00 = 1.0 - sw
    w1a = sw * (1.0 - aw)
    w1b = sw * aw
    k0 = w00 * samples[0, 0, 0] + w1a * samples[1, ai, 0] + w1b * samples[1, ai + 1, 0]
    k1 = w00 * samples[0, 0, 1] + w1a * samples[1, ai, 1] + w1b * samples[1, ai + 1, 1]
    k2 = w00 * samples[0, 0, 2] + w1a * samples[1, ai, 2] + w1b * samples[1, ai + 1, 2]
    k3 = w00 * samples[0, 0, 3] + w1a * samples[1, ai, 3] + w1b * samples[1, ai + 1, 3]
    return 2.0 * max(k0, 0.0), 2.0 * max(k1, 0.0), 2.0 * max(k2, 0.0), 2.0 * max(k3, 0.0)


@njit(cache=True, error_model="numpy", fastmath=FASTMATH, inline="always")
def deformation_gradient(
    p: np.ndarray, i0: int, i1: int, i2: int, a: float, b: float, c: float, d: float
) -> tuple[float, float, float, float, float, float, float, float, float, float, float, float]:
    """A triangle's edges and ``[e1 e2] Dm⁻¹`` of per-vertex vectors ``p`` (positions or
    velocities), inlined into the kernels that share it.

    Args:
        p: ``(V, 3)`` per-vertex vectors.
        i0, i1, i2: The triangle's vertices.
        a, b, c, d: Its inverse rest edge matrix ``Dm⁻¹``, row-major 2×2.

    Returns:
        ``(e1x, e1y, e1z, e2x, e2y, e2z, ux, uy, uz, vx, vy, vz)``: the edges ``p[i1] - p[i0]``
        and ``p[i2] - p[i0]``, and the columns u (warp) and v (weft) of ``[e1 e2] Dm⁻¹``
        (of positions, the deformation gradient F; of velocities, its rate).
    """
    e1x = p[i1, 0] - p[i0, 0]
    e1y = p[i1, 1] - p[i0, 1]
    e1z = p[i1, 2] - p[i0, 2]
    e2x = p[i2, 0] - p[i0, 0]
    e2y = p[i2, 1] - p[i0, 1]
    e2z = p[i2, 2] - p[i0, 2]
    ux = e1x * a + e2x * c
    uy = e1y * a + e2y * c
    uz = e1z * a + e2z * c
    vx = e1x * b + e2x * d
    vy = e1y * b + e2y * d
    vz = e1z * b + e2z * d
    return e1x, e1y, e1z, e2x, e2y, e2z, ux, uy, uz, vx, vy, vz


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def update_stiffness(
    x: np.ndarray, faces: np.ndarray, dm_inv: np.ndarray, samples: np.ndarray, stiffness: np.ndarray
) -> None:
    """Look up every triangle's four stretching stiffnesses from its current strain.

    Args:
        x: ``(V, 3)`` positions.
        faces: ``(F, 3)`` int32 triangles; dm_inv: ``(F, 4)`` inverse rest edge matrices.
        samples: ``(2, 5, 4)`` stretching samples.
        stiffness: ``(F, 4)`` receives ``(k0, k1, k2, k3)`` in N/m.
    """
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        a, b, c, d = dm_inv[f, 0], dm_inv[f, 1], dm_inv[f, 2], dm_inv[f, 3]
        _, _, _, _, _, _, xux, xuy, xuz, xvx, xvy, xvz = deformation_gradient(
            x, i0, i1, i2, a, b, c, d
        )
        k0, k1, k2, k3 = stretching_stiffness(
            xux * xux + xuy * xuy + xuz * xuz,
            xvx * xvx + xvy * xvy + xvz * xvz,
            xux * xvx + xuy * xvy + xuz * xvz,
            samples,
        )
        stiffness[f, 0] = k0
        stiffness[f, 1] = k1
        stiffness[f, 2] = k2
        stiffness[f, 3] = k3


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def add_face_forces(
    x: np.ndarray,
    v: np.ndarray,
    faces: np.ndarray,
    dm_inv: np.ndarray,
    area: np.ndarray,
    stiffness: np.ndarray,
    beta: float,
    wind_x: float,
    wind_y: float,
    wind_z: float,
    wind_speed: float,
    shear_exp: float,
    z_ref: float,
    rho_air: float,
    c_drag: float,
    force: np.ndarray,
    normal: np.ndarray,
    inv_normal_length: np.ndarray,
) -> None:
    """Add stretching (with damping) and wind forces of every triangle to ``force``.

    Args:
        x, v: ``(V, 3)`` positions and velocities.
        faces: ``(F, 3)`` int32 triangles.
        dm_inv: ``(F, 4)`` inverse rest edge matrices (row-major 2×2).
        area: ``(F,)`` rest areas (ArcSim uses the material area in both terms).
        stiffness: ``(F, 4)`` stretching stiffnesses from :func:`update_stiffness`.
        beta: Kelvin–Voigt damping time in seconds (stress ``C : (G + β Ġ)``).
        wind_x, wind_y, wind_z: Unit wind direction (``wind_z`` ≠ 0 for an inclined wind).
        wind_speed: Speed at ``z_ref`` in m/s; ``shear_exp``: power-law exponent.
        rho_air: Air density (kg/m³) of the normal pressure ``ρ A |v_n| v_n n``.
        c_drag: Tangential drag coefficient (kg/(m²·s)) of ``c A v_t``.
        force: ``(V, 3)`` accumulator.
        normal: ``(F, 3)`` receives the unit normals (zero for a degenerate triangle).
        inv_normal_length: ``(F,)`` receives the inverse length of the unnormalised normal
            (half the inverse current area; inf if degenerate); the bending pass reuses both.
    """
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        a, b, c, d = dm_inv[f, 0], dm_inv[f, 1], dm_inv[f, 2], dm_inv[f, 3]
        # Deformation gradient F = [e1 e2] Dm^-1: columns xu (warp) and xv (weft).
        e1x, e1y, e1z, e2x, e2y, e2z, xux, xuy, xuz, xvx, xvy, xvz = deformation_gradient(
            x, i0, i1, i2, a, b, c, d
        )
        c00 = xux * xux + xuy * xuy + xuz * xuz
        c11 = xvx * xvx + xvy * xvy + xvz * xvz
        c01 = xux * xvx + xuy * xvy + xuz * xvz
        k0, k1, k2, k3 = stiffness[f, 0], stiffness[f, 1], stiffness[f, 2], stiffness[f, 3]
        g00 = 0.5 * (c00 - 1.0)
        g11 = 0.5 * (c11 - 1.0)
        g01 = 0.5 * c01
        # Strain rate from the same gradient applied to velocities.
        _, _, _, _, _, _, vux, vuy, vuz, vvx, vvy, vvz = deformation_gradient(
            v, i0, i1, i2, a, b, c, d
        )
        g00 += beta * (xux * vux + xuy * vuy + xuz * vuz)
        g11 += beta * (xvx * vvx + xvy * vvy + xvz * vvz)
        g01 += beta * 0.5 * (xux * vvx + xuy * vvy + xuz * vvz + xvx * vux + xvy * vuy + xvz * vuz)
        s00 = k0 * g00 + k1 * g11
        s11 = k1 * g00 + k2 * g11
        s01 = k3 * g01
        # First Piola-Kirchhoff P = F S; nodal forces -A P Dm^-T.
        p0x = xux * s00 + xvx * s01
        p0y = xuy * s00 + xvy * s01
        p0z = xuz * s00 + xvz * s01
        p1x = xux * s01 + xvx * s11
        p1y = xuy * s01 + xvy * s11
        p1z = xuz * s01 + xvz * s11
        ar = area[f]
        g1x = -ar * (p0x * a + p1x * b)
        g1y = -ar * (p0y * a + p1y * b)
        g1z = -ar * (p0z * a + p1z * b)
        g2x = -ar * (p0x * c + p1x * d)
        g2y = -ar * (p0y * c + p1y * d)
        g2z = -ar * (p0z * c + p1z * d)

        # Wind: relative velocity of the air to the face, split into normal and tangential.
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        nn = math.sqrt(nx * nx + ny * ny + nz * nz)
        wx = 0.0
        wy = 0.0
        wz = 0.0
        inv_nn = 1.0 / nn if nn > 0.0 else math.inf
        inv_normal_length[f] = inv_nn
        if nn > 0.0:
            nx *= inv_nn
            ny *= inv_nn
            nz *= inv_nn
        else:
            nx = 0.0
            ny = 0.0
            nz = 0.0
        normal[f, 0] = nx
        normal[f, 1] = ny
        normal[f, 2] = nz
        if nn > 0.0:
            speed = wind_speed
            if shear_exp != 0.0:
                speed *= shear_factor(
                    (x[i0, 2] + x[i1, 2] + x[i2, 2]) * (1.0 / 3.0), shear_exp, z_ref
                )
            third = 1.0 / 3.0
            rx = speed * wind_x - (v[i0, 0] + v[i1, 0] + v[i2, 0]) * third
            ry = speed * wind_y - (v[i0, 1] + v[i1, 1] + v[i2, 1]) * third
            rz = speed * wind_z - (v[i0, 2] + v[i1, 2] + v[i2, 2]) * third
            vn = rx * nx + ry * ny + rz * nz
            pn = rho_air * ar * abs(vn) * vn
            ct = c_drag * ar
            wx = (pn * nx + ct * (rx - vn * nx)) * third
            wy = (pn * ny + ct * (ry - vn * ny)) * third
            wz = (pn * nz + ct * (rz - vn * nz)) * third

        force[i0, 0] += wx - g1x - g2x
        force[i0, 1] += wy - g1y - g2y
        force[i0, 2] += wz - g1z - g2z
        force[i1, 0] += wx + g1x
        force[i1, 1] += wy + g1y
        force[i1, 2] += wz + g1z
        force[i2, 0] += wx + g2x
        force[i2, 1] += wy + g2y
        force[i2, 2] += wz + g2z


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def add_bending_forces(
    x: np.ndarray,
    hinges: np.ndarray,
    hinge_faces: np.ndarray,
    hinge_curvature: np.ndarray,
    hinge_shape: np.ndarray,
    hinge_curve: np.ndarray,
    normal: np.ndarray,
    inv_normal_length: np.ndarray,
    force: np.ndarray,
) -> None:
    """Add ArcSim's bending force of every hinge to ``force``.

    Energy per hinge ``ke · l² / (2 (A0 + A1)) · θ² / 4`` with the dihedral angle ``θ`` and
    ``ke`` interpolated linearly in the half-curvature ``|θ| l / (2 (A0 + A1))`` between
    the five samples (5 m⁻¹ apart, held beyond 20 m⁻¹); the force treats ``ke`` as constant
    (ArcSim's convention). ``∂θ/∂x`` of the opposite vertices is ``-n_k / h_k`` (``h_k``
    their heights over the hinge, floored at 1e-3 of the hinge length as in ArcSim) and
    the hinge vertices take barycentric shares, so the forces sum to zero.

    Args:
        x: ``(V, 3)`` positions.
        hinges: ``(H, 4)`` int32 ``[e0, e1, o0, o1]``.
        hinge_faces: ``(H, 2)`` int32 faces ``(e0 e1 o0)`` and ``(e1 e0 o1)``.
        hinge_curvature: ``(H,)`` ``l / (10 (A0 + A1))`` from rest data: times ``|θ|`` it
            is the half-curvature in units of the 5 m⁻¹ sample spacing.
        hinge_shape: ``(H,)`` ``l² / (4 (A0 + A1))``: the force is ``-ke · shape · θ · ∂θ/∂x``.
        hinge_curve: ``(H, 5)`` stiffness samples (N·m) of each hinge's direction, scaled
            by θ's multipliers.
        normal, inv_normal_length: face normals and inverse raw lengths from
            :func:`add_face_forces`.
        force: ``(V, 3)`` accumulator.
    """
    for h in range(hinges.shape[0]):
        i0, i1, i2, i3 = hinges[h, 0], hinges[h, 1], hinges[h, 2], hinges[h, 3]
        fa, fb = hinge_faces[h, 0], hinge_faces[h, 1]
        ex = x[i1, 0] - x[i0, 0]
        ey = x[i1, 1] - x[i0, 1]
        ez = x[i1, 2] - x[i0, 2]
        ee = ex * ex + ey * ey + ez * ez
        if ee == 0.0:
            continue
        inv_le = 1.0 / math.sqrt(ee)
        inv_ee = inv_le * inv_le
        le = ee * inv_le
        n0x, n0y, n0z = normal[fa, 0], normal[fa, 1], normal[fa, 2]
        n1x, n1y, n1z = normal[fb, 0], normal[fb, 1], normal[fb, 2]
        cosine = n0x * n1x + n0y * n1y + n0z * n1z
        sine = (
            (n0y * n1z - n0z * n1y) * ex
            + (n0z * n1x - n0x * n1z) * ey
            + (n0x * n1y - n0y * n1x) * ez
        ) * inv_le
        theta = fast_atan2(sine, cosine)
        value = abs(theta) * hinge_curvature[h]
        if value > 4.0:
            value = 4.0
        vi = int(value)
        if vi > 3:
            vi = 3
        value -= vi
        ke = (1.0 - value) * hinge_curve[h, vi] + value * hinge_curve[h, vi + 1]
        # 1/h_k = |e| / |N_k|, with h_k floored at 1e-3 |e|.
        s = ke * hinge_shape[h] * theta * le
        cap = 1e3 * inv_ee
        q0 = s * min(inv_normal_length[fa], cap)
        q1 = s * min(inv_normal_length[fb], cap)
        t0 = (
            ex * (x[i2, 0] - x[i0, 0]) + ey * (x[i2, 1] - x[i0, 1]) + ez * (x[i2, 2] - x[i0, 2])
        ) * inv_ee
        t1 = (
            ex * (x[i3, 0] - x[i0, 0]) + ey * (x[i3, 1] - x[i0, 1]) + ez * (x[i3, 2] - x[i0, 2])
        ) * inv_ee
        f2x = q0 * n0x
        f2y = q0 * n0y
        f2z = q0 * n0z
        f3x = q1 * n1x
        f3y = q1 * n1y
        f3z = q1 * n1z
        force[i2, 0] += f2x
        force[i2, 1] += f2y
        force[i2, 2] += f2z
        force[i3, 0] += f3x
        force[i3, 1] += f3y
        force[i3, 2] += f3z
        force[i0, 0] -= (1.0 - t0) * f2x + (1.0 - t1) * f3x
        force[i0, 1] -= (1.0 - t0) * f2y + (1.0 - t1) * f3y
        force[i0, 2] -= (1.0 - t0) * f2z + (1.0 - t1) * f3z
        force[i1, 0] -= t0 * f2x + t1 * f3x
        force[i1, 1] -= t0 * f2y + t1 * f3y
        force[i1, 2] -= t0 * f2z + t1 * f3z


# Callees are linked into the cached code: a change to their files must recompile these.
cache_depends_on(
    (
        fast_atan2,
        stretching_stiffness,
        deformation_gradient,
        update_stiffness,
        add_face_forces,
        add_bending_forces,
    ),
    cloth_numba,
    cloth_wind,
)
