"""Compiled (numba) time loop of the cloth solver: integrator, strain limiting and the clip.

One call of :func:`run_flag` simulates a whole clip — warm-up and recorded frames — in
compiled code, so a single flag pays no per-step Python overhead; :func:`run_flag_batch`
runs ``B`` flags in parallel threads by calling :func:`run_flag` once per flag (one flag
per thread, no shared writes), so one implementation serves both. Per substep:

1. the forces of :mod:`physinfer_flag.cloth_forces`: stretching (stiffnesses looked up
   every few substeps, as ArcSim looks them up once per 5 ms implicit step) with damping
   and wind per face, then bending per hinge;
2. symplectic Euler: ``v += dt · a``, ``x += dt · v``; pinned nodes never move;
3. optional strain limiting (Provot): edges longer than ``(1 + limit)`` rest are pulled
   back (one or more Gauss–Seidel sweeps) and the correction is added to the velocities.

The force kernels are re-exported here. Arrays are float64 (state) and int32 (indices);
shapes are documented per function.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

# cloth_numba, imported by each of these first, picks numba's cache directory.
from physinfer_flag import cloth_forces, cloth_numba, cloth_wind
from physinfer_flag.cloth_forces import (
    FASTMATH,
    add_bending_forces,
    add_face_forces,
    fast_atan2,
    stretching_stiffness,
    update_stiffness,
)
from physinfer_flag.cloth_numba import cache_depends_on
from physinfer_flag.cloth_wind import wind_at_time

__all__ = [
    "FASTMATH", "N_SCALARS", "S_BETA", "S_C_DRAG", "S_DT", "S_GRAVITY", "S_LIMIT_SWEEPS", "S_LOOKUP_EVERY",
    "S_MAX_DIST", "S_MAX_SPEED", "S_RHO_AIR", "S_STRAIN_LIMIT", "STATUS_DISTANCE", "STATUS_NAN", "STATUS_OK",
    "STATUS_SPEED", "add_bending_forces", "add_face_forces", "fast_atan2", "frame_status", "limit_strain", "run_flag",
    "run_flag_batch", "stretching_stiffness", "update_stiffness",
]

# Indices into the ``scalars`` vector of the kernels.
(S_DT, S_GRAVITY, S_RHO_AIR, S_C_DRAG, S_BETA, S_STRAIN_LIMIT, S_MAX_SPEED, S_MAX_DIST, S_LOOKUP_EVERY,
 S_LIMIT_SWEEPS) = range(10)
N_SCALARS = 10

STATUS_OK, STATUS_NAN, STATUS_SPEED, STATUS_DISTANCE = 0, 1, 2, 3


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def limit_strain(
    x: np.ndarray,
    v: np.ndarray,
    inv_mass: np.ndarray,
    edges: np.ndarray,
    edge_length: np.ndarray,
    limit: float,
    dt: float,
) -> None:
    """Pull every edge longer than ``(1 + limit)`` times its rest length back to that length.

    One Gauss–Seidel sweep, mass-weighted (pinned nodes do not move); the position change
    is added to the velocities so the next step sees a consistent state.
    """
    inv_dt = 1.0 / dt
    for k in range(edges.shape[0]):
        ia, ib = edges[k, 0], edges[k, 1]
        dx = x[ib, 0] - x[ia, 0]
        dy = x[ib, 1] - x[ia, 1]
        dz = x[ib, 2] - x[ia, 2]
        length = math.sqrt(dx * dx + dy * dy + dz * dz)
        lmax = (1.0 + limit) * edge_length[k]
        if length <= lmax:
            continue
        wa = inv_mass[ia]
        wb = inv_mass[ib]
        wsum = wa + wb
        if wsum == 0.0:
            continue
        corr = (length - lmax) / (length * wsum)
        ca = wa * corr
        cb = wb * corr
        x[ia, 0] += ca * dx
        x[ia, 1] += ca * dy
        x[ia, 2] += ca * dz
        x[ib, 0] -= cb * dx
        x[ib, 1] -= cb * dy
        x[ib, 2] -= cb * dz
        v[ia, 0] += ca * dx * inv_dt
        v[ia, 1] += ca * dy * inv_dt
        v[ia, 2] += ca * dz * inv_dt
        v[ib, 0] -= cb * dx * inv_dt
        v[ib, 1] -= cb * dy * inv_dt
        v[ib, 2] -= cb * dz * inv_dt


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def frame_status(x: np.ndarray, v: np.ndarray, max_speed: float, max_dist: float) -> int:
    """Blow-up test of one state: NaN, a node faster than ``max_speed`` or farther than
    ``max_dist`` from the origin's vertical axis (the pole). Returns a ``STATUS_*`` code."""
    max_v2 = max_speed * max_speed
    max_d2 = max_dist * max_dist
    for i in range(x.shape[0]):
        s2 = v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1] + v[i, 2] * v[i, 2]
        d2 = x[i, 0] * x[i, 0] + x[i, 1] * x[i, 1]
        if not (s2 == s2 and d2 == d2 and x[i, 2] == x[i, 2]):
            return STATUS_NAN
        if s2 > max_v2:
            return STATUS_SPEED
        if d2 > max_d2:
            return STATUS_DISTANCE
    return STATUS_OK


@njit(cache=True, error_model="numpy", fastmath=FASTMATH)
def run_flag(
    x: np.ndarray,
    v: np.ndarray,
    inv_mass: np.ndarray,
    faces: np.ndarray,
    dm_inv: np.ndarray,
    face_area: np.ndarray,
    samples: np.ndarray,
    hinges: np.ndarray,
    hinge_faces: np.ndarray,
    hinge_curvature: np.ndarray,
    hinge_shape: np.ndarray,
    hinge_curve: np.ndarray,
    edges: np.ndarray,
    edge_length: np.ndarray,
    wind_table: np.ndarray,
    wind_scalars: np.ndarray,
    scalars: np.ndarray,
    substeps: int,
    warmup_frames: int,
    out: np.ndarray,
) -> tuple[int, int]:
    """Simulate one flag: ``warmup_frames`` unrecorded frames, then ``out.shape[0]`` recorded.

    Args:
        x, v: ``(V, 3)`` float64 initial state, advanced in place.
        inv_mass: ``(V,)`` inverse lumped masses, 0 for pinned nodes.
        faces, dm_inv, face_area: see :func:`add_face_forces`; samples: see
            :func:`update_stiffness`.
        hinges, hinge_faces, hinge_curvature, hinge_shape, hinge_curve: see
            :func:`add_bending_forces`.
        edges, edge_length: ``(E, 2)``, ``(E,)`` edges for strain limiting.
        wind_table: ``(K, 4)`` wind samples ``[speed, yaw, shear exponent, inclination]``.
        wind_scalars: ``[sample dt, z_ref, base direction]``.
        scalars: ``(N_SCALARS,)`` ``[dt, gravity, rho_air, c_drag, beta, strain limit
            (<= 0: off), max speed, max distance, steps between stretching-stiffness
            look-ups, strain-limiting sweeps per step]``.
        substeps: Integration steps per output frame.
        warmup_frames: Frames simulated before recording.
        out: ``(T, V, 3)`` float32, receives the positions at the end of each recorded frame.

    Returns:
        ``(status, frame)``: a ``STATUS_*`` code and the (global) frame where it occurred.
    """
    dt = scalars[S_DT]
    gravity = scalars[S_GRAVITY]
    rho_air = scalars[S_RHO_AIR]
    c_drag = scalars[S_C_DRAG]
    beta = scalars[S_BETA]
    strain_limit = scalars[S_STRAIN_LIMIT]
    max_speed = scalars[S_MAX_SPEED]
    max_dist = scalars[S_MAX_DIST]
    lookup_every = max(int(scalars[S_LOOKUP_EVERY]), 1)
    limit_sweeps = max(int(scalars[S_LIMIT_SWEEPS]), 1)
    sample_dt = wind_scalars[0]
    z_ref = wind_scalars[1]
    base_dir = wind_scalars[2]
    n = x.shape[0]
    force = np.zeros((n, 3))
    stiffness = np.zeros((faces.shape[0], 4))
    normal = np.zeros((faces.shape[0], 3))
    inv_normal_length = np.zeros(faces.shape[0])
    n_frames = warmup_frames + out.shape[0]
    step = 0
    for frame in range(n_frames):
        for _ in range(substeps):
            t = step * dt
            speed, yaw, shear_exp, inclination = wind_at_time(wind_table, sample_dt, t)
            horizontal = math.cos(inclination)
            wind_x = horizontal * math.cos(base_dir + yaw)
            wind_y = horizontal * math.sin(base_dir + yaw)
            wind_z = math.sin(inclination)
            if step % lookup_every == 0:
                update_stiffness(x, faces, dm_inv, samples, stiffness)
            force[:, :] = 0.0
            add_face_forces(x, v, faces, dm_inv, face_area, stiffness, beta, wind_x, wind_y, wind_z,
                            speed, shear_exp, z_ref, rho_air, c_drag, force, normal, inv_normal_length)
            add_bending_forces(x, hinges, hinge_faces, hinge_curvature, hinge_shape, hinge_curve,
                               normal, inv_normal_length, force)
            for i in range(n):
                w = inv_mass[i]
                if w == 0.0:
                    continue
                v[i, 0] += dt * w * force[i, 0]
                v[i, 1] += dt * w * force[i, 1]
                v[i, 2] += dt * (w * force[i, 2] - gravity)
                x[i, 0] += dt * v[i, 0]
                x[i, 1] += dt * v[i, 1]
                x[i, 2] += dt * v[i, 2]
            if strain_limit > 0.0:
                for _ in range(limit_sweeps):
                    limit_strain(x, v, inv_mass, edges, edge_length, strain_limit, dt)
            step += 1
        status = frame_status(x, v, max_speed, max_dist)
        if status != STATUS_OK:
            return status, frame
        rec = frame - warmup_frames
        if rec >= 0:
            for i in range(n):
                out[rec, i, 0] = x[i, 0]
                out[rec, i, 1] = x[i, 1]
                out[rec, i, 2] = x[i, 2]
    return STATUS_OK, n_frames


@njit(cache=True, error_model="numpy", parallel=True)
def run_flag_batch(
    x0: np.ndarray,
    v0: np.ndarray,
    inv_mass: np.ndarray,
    faces: np.ndarray,
    dm_inv: np.ndarray,
    face_area: np.ndarray,
    samples: np.ndarray,
    hinges: np.ndarray,
    hinge_faces: np.ndarray,
    hinge_curvature: np.ndarray,
    hinge_shape: np.ndarray,
    hinge_curve: np.ndarray,
    edges: np.ndarray,
    edge_length: np.ndarray,
    wind_table: np.ndarray,
    wind_lengths: np.ndarray,
    wind_scalars: np.ndarray,
    scalars: np.ndarray,
    substeps: int,
    warmup_frames: int,
    out: np.ndarray,
) -> np.ndarray:
    """Simulate ``B`` flags on the same mesh, one per thread.

    Args:
        x0, v0: ``(B, V, 3)`` initial states.
        inv_mass: ``(B, V)``; hinge_curve: ``(B, H, 5)``; wind_table: ``(B, K, 4)``, of
            which flag ``b`` reads its first ``wind_lengths[b]`` rows (so a flag is simulated
            as :func:`run_flag` simulates it alone, whatever the batch's longest table);
            wind_scalars: ``(B, 3)`` — the per-flag inputs of :func:`run_flag`.
        out: ``(B, T, V, 3)`` float32 recorded positions.
        Other arguments are shared and as in :func:`run_flag`.

    Returns:
        ``(B, 2)`` int64 ``(status, frame)`` per flag.
    """
    batch = x0.shape[0]
    result = np.zeros((batch, 2), dtype=np.int64)
    for b in prange(batch):
        x = x0[b].copy()
        v = v0[b].copy()
        status, frame = run_flag(x, v, inv_mass[b], faces, dm_inv, face_area, samples, hinges,
                                 hinge_faces, hinge_curvature, hinge_shape, hinge_curve[b], edges, edge_length,
                                 wind_table[b, : wind_lengths[b]], wind_scalars[b], scalars, substeps, warmup_frames,
                                 out[b])
        result[b, 0] = status
        result[b, 1] = frame
    return result


# Callees are linked into the cached code: a change to their files must recompile these.
cache_depends_on((limit_strain, frame_status, run_flag, run_flag_batch), cloth_numba, cloth_forces, cloth_wind)
