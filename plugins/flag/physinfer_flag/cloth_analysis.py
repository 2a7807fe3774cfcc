"""Motion statistics of flag trajectories: flapping frequency, energy, motion descriptors.

The flag's motion is chaotic, so single trajectories are compared through statistics:
the flapping frequency at the fly edge (power spectra averaged over several fly-edge
points and records, cross-checked by the zero-crossing rate), the kinetic energy, the
fold (dihedral) angles, and a few scalar clip features whose spread over seeds measures
how far apart two parameter settings are (Cohen's d).
All functions take :class:`~physinfer.types.Trajectory` objects from the flag simulator
(with ``extras["grid_shape"]`` = ``(nv, nu)``) and assume the wind blows along +x, so the
cross-wind (flapping) direction is y.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from physinfer.errors import UserInputError
from physinfer.types import Trajectory
from physinfer_flag.cloth_mesh import mesh_hinges


def grid_vertices(traj: Trajectory) -> np.ndarray:
    """Vertices as a grid, ``(T, nv, nu, 3)`` (row 0 at the bottom, column 0 on the pole)."""
    if "grid_shape" not in traj.extras:
        raise UserInputError("trajectory has no extras['grid_shape']; it is not from the flag simulator")
    nv, nu = (int(n) for n in traj.extras["grid_shape"])
    return traj.vertices.reshape(traj.n_frames, nv, nu, 3)


def fly_edge_crosswind(traj: Trajectory, n_points: int = 5) -> np.ndarray:
    """Cross-wind (y) displacement from its mean at ``n_points`` fly-edge points, ``(T, n_points)``."""
    grid = grid_vertices(traj)
    rows = np.linspace(0, grid.shape[1] - 1, n_points).round().astype(int)
    y = grid[:, rows, -1, 1].astype(np.float64)
    return y - y.mean(axis=0)


def power_spectrum(signals: Sequence[np.ndarray], fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Hann-windowed power spectrum averaged over records and points.

    Args:
        signals: Records of shape ``(T, P)`` (equal ``T``), zero-mean.
        fps: Sampling rate in Hz.

    Returns:
        Frequencies ``(T // 2 + 1,)`` in Hz and mean power of the same shape.
    """
    if not signals:
        raise UserInputError("power_spectrum needs at least one record")
    n = signals[0].shape[0]
    window = np.hanning(n)[:, None]
    power = np.mean([(np.abs(np.fft.rfft(s * window, axis=0)) ** 2).mean(axis=1) for s in signals], axis=0)
    return np.fft.rfftfreq(n, 1.0 / fps), power


def dominant_frequency(signals: Sequence[np.ndarray], fps: float, f_min: float = 0.2) -> float:
    """Peak of the averaged power spectrum above ``f_min`` Hz (excludes drift), in Hz."""
    freqs, power = power_spectrum(signals, fps)
    keep = freqs >= f_min
    return float(freqs[keep][np.argmax(power[keep])])


def spectral_centroid(signals: Sequence[np.ndarray], fps: float, f_min: float = 0.2) -> float:
    """Power-weighted mean frequency above ``f_min`` Hz of the averaged spectrum, in Hz."""
    freqs, power = power_spectrum(signals, fps)
    keep = freqs >= f_min
    return float(np.sum(freqs[keep] * power[keep]) / max(np.sum(power[keep]), 1e-300))


def zero_crossing_rate(signals: Sequence[np.ndarray], fps: float) -> float:
    """Mean number of full oscillations per second (sign changes / 2 / duration), in Hz."""
    rates = []
    for s in signals:
        crossings = (np.diff(np.signbit(s), axis=0) != 0).sum(axis=0)
        rates.append(crossings / 2.0 / (s.shape[0] / fps))
    return float(np.mean(rates))


def kinetic_energy(traj: Trajectory, node_mass: np.ndarray) -> np.ndarray:
    """Kinetic energy between consecutive frames, ``(T - 1,)`` joules (finite differences)."""
    velocity = np.diff(traj.vertices.astype(np.float64), axis=0) * traj.fps
    return 0.5 * np.einsum("tvk,tvk,v->t", velocity, velocity, node_mass)


def dihedral_angles(vertices: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """Signed dihedral angle of every hinge, ``(T, H)`` radians, from ``(T, V, 3)`` vertices.

    Uses the solver's convention (0 when flat); ``hinges`` ``(H, 4)`` as from
    :func:`~physinfer_flag.cloth_mesh.mesh_hinges`.
    """
    x0, x1, x2, x3 = (vertices[:, hinges[:, k]].astype(np.float64) for k in range(4))
    e = x1 - x0
    n0 = np.cross(e, x2 - x0)
    n1 = np.cross(x3 - x0, e)
    n0 /= np.maximum(np.linalg.norm(n0, axis=-1, keepdims=True), 1e-300)
    n1 /= np.maximum(np.linalg.norm(n1, axis=-1, keepdims=True), 1e-300)
    sine = (np.cross(n0, n1) * e).sum(-1) / np.maximum(np.linalg.norm(e, axis=-1), 1e-300)
    return np.arctan2(sine, (n0 * n1).sum(-1))


def mean_fold_angle(traj: Trajectory) -> float:
    """Mean absolute dihedral angle over all hinges and frames, radians (how much it folds)."""
    hinges, _, _ = mesh_hinges(traj.faces)
    return float(np.abs(dihedral_angles(traj.vertices, hinges)).mean())


#: Names of the scalar clip features, in the order :func:`clip_features` returns them.
FEATURES = ("reach", "height", "amplitude", "frequency", "fold")


def clip_features(traj: Trajectory) -> dict[str, float]:
    """Scalar statistics of one clip, the quantities a viewer (or an embedding) can see.

    Returns:
        ``reach``: mean downwind (x) position of the fly edge, m; ``height``: its mean
        height, m (a heavy or slack flag droops); ``amplitude``: RMS displacement from
        the time-mean shape, averaged over all nodes, m; ``frequency``: spectral centroid
        of the fly edge's cross-wind motion, Hz; ``fold``: mean absolute dihedral angle,
        rad (how sharply the cloth folds, which bending controls and shading shows).
    """
    grid = grid_vertices(traj).astype(np.float64)
    fly = grid[:, :, -1]
    disp = traj.vertices.astype(np.float64) - traj.vertices.mean(axis=0)
    return {
        "reach": float(fly[..., 0].mean()),
        "height": float(fly[..., 2].mean()),
        "amplitude": float(np.sqrt((disp**2).sum(axis=2).mean())),
        "frequency": spectral_centroid([fly_edge_crosswind(traj)], traj.fps),
        "fold": mean_fold_angle(traj),
    }


def effect_size(low: Sequence[float], high: Sequence[float]) -> float:
    """Cohen's d: ``|mean(high) - mean(low)|`` over the pooled standard deviation.

    With chaotic clips, ``d > 1`` means a single clip mostly tells the two settings apart.
    """
    low, high = np.asarray(low, float), np.asarray(high, float)
    pooled = np.sqrt(0.5 * (low.var(ddof=1) + high.var(ddof=1)))
    return float(abs(high.mean() - low.mean()) / max(pooled, 1e-12))
