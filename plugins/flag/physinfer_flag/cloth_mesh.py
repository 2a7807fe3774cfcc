"""The flag's triangle mesh and the per-element data the cloth solver needs.

A rectangular flag of ``width`` (hoist to fly, along the warp) × ``height`` is a grid of
``nu × nv`` nodes cut into triangles with alternating diagonals, so that both diagonal
directions appear and neither shear sense is favoured. Vertex ``j * nu + i`` sits at
column ``i`` (``u = i / (nu - 1)``, hoist 0 to fly 1) and row ``j`` (``v = j / (nv - 1)``,
bottom 0 to top 1). The rest shape lies flat in the x–z plane, hoist edge on the pole
(x = y = 0), extending towards +x. Everything is precomputed here once: rest-shape
inverses of the triangles, lumped node areas, bending hinges with their material
direction, and the edges strain limiting acts on.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from physinfer.errors import UserInputError

PinMode = Literal["edge", "corners"]


@dataclass(frozen=True)
class FlagMesh:
    """A flag mesh with its rest-state data.

    Attributes:
        nu: Nodes along the width (hoist to fly).
        nv: Nodes along the height (bottom to top).
        rest: ``(V, 3)`` float64 rest positions in metres.
        material_uv: ``(V, 2)`` float64 material coordinates in metres (warp, weft).
        uv: ``(V, 2)`` float32 texture coordinates in ``[0, 1]``.
        faces: ``(F, 3)`` int32 triangles, counter-clockwise in material space.
        face_dm_inv: ``(F, 4)`` float64 inverse rest edge matrix ``[a, b, c, d]`` of each
            triangle (row-major 2×2, maps material edges to the deformation gradient).
        face_area: ``(F,)`` float64 rest areas in m².
        node_area: ``(V,)`` float64 lumped areas (a third of each adjacent triangle).
        hinges: ``(H, 4)`` int32 bending hinges ``[edge0, edge1, opposite0, opposite1]``.
        hinge_faces: ``(H, 2)`` int32 the two triangles of each hinge (their normals are
            the hinge's normals).
        hinge_length: ``(H,)`` float64 rest length of the hinge edge.
        hinge_area: ``(H,)`` float64 summed rest area of the two triangles.
        hinge_direction: ``(H,)`` float64 bending direction in ``[0, 2]`` (0 = 0°, 1 = 45°,
            2 = 90° to the warp), as ArcSim measures it from the hinge edge in material space.
        edges: ``(E, 2)`` int32 unique mesh edges (strain limiting acts on them).
        edge_length: ``(E,)`` float64 rest lengths.
        pinned: ``(V,)`` bool, nodes held on the pole.
    """

    nu: int
    nv: int
    rest: np.ndarray
    material_uv: np.ndarray
    uv: np.ndarray
    faces: np.ndarray
    face_dm_inv: np.ndarray
    face_area: np.ndarray
    node_area: np.ndarray
    hinges: np.ndarray
    hinge_faces: np.ndarray
    hinge_length: np.ndarray
    hinge_area: np.ndarray
    hinge_direction: np.ndarray
    edges: np.ndarray
    edge_length: np.ndarray
    pinned: np.ndarray

    @property
    def n_vertices(self) -> int:
        """Number of nodes ``V``."""
        return int(self.rest.shape[0])

    @property
    def spacing(self) -> float:
        """Largest grid spacing in metres (the resolution that matters for bending)."""
        du = self.material_uv[1, 0] - self.material_uv[0, 0]
        dv = self.material_uv[self.nu, 1] - self.material_uv[0, 1]
        return float(max(du, dv))


def grid_faces(nu: int, nv: int) -> np.ndarray:
    """Triangles of an ``nu × nv`` grid with alternating diagonals, ``(2 (nu-1)(nv-1), 3)`` int32."""
    faces = []
    for j in range(nv - 1):
        for i in range(nu - 1):
            a, b = j * nu + i, j * nu + i + 1
            c, d = a + nu, b + nu
            if (i + j) % 2 == 0:  # diagonal a–d
                faces += [(a, b, d), (a, d, c)]
            else:  # diagonal b–c
                faces += [(a, b, c), (b, d, c)]
    return np.asarray(faces, dtype=np.int32)


def mesh_hinges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Interior edges with their two opposite vertices and two faces, and all unique edges.

    Returns:
        ``(H, 4)`` hinges ``[e0, e1, o0, o1]`` where ``(e0, e1, o0)`` is a triangle in its
        stored orientation (so ``(e1, e0, o1)`` is the other one, the mesh being
        consistently oriented), ``(H, 2)`` the indices of those two faces, and ``(E, 2)``
        unique edges.
    """
    first: dict[tuple[int, int], tuple[int, int, int, int]] = {}
    hinges, hinge_faces = [], []
    for f, tri in enumerate(faces):
        for k in range(3):
            e0, e1, opp = int(tri[k]), int(tri[(k + 1) % 3]), int(tri[(k + 2) % 3])
            key = (min(e0, e1), max(e0, e1))
            if key in first:
                h = first[key]
                hinges.append((h[0], h[1], h[2], opp))
                hinge_faces.append((h[3], f))
            else:
                first[key] = (e0, e1, opp, f)
    edges = np.asarray(sorted(first), dtype=np.int32)
    return (
        np.asarray(hinges, dtype=np.int32).reshape(-1, 4),
        np.asarray(hinge_faces, dtype=np.int32).reshape(-1, 2),
        edges,
    )


def _bending_direction(du: np.ndarray) -> np.ndarray:
    """ArcSim's bias angle of a hinge edge: its angle to the warp folded into ``[0, 2]``.

    ``0`` is an edge along the warp, ``1`` a diagonal at ±45°, ``2`` an edge along the weft;
    the table rows are interpolated linearly in this coordinate.
    """
    a = np.abs(np.arctan2(du[:, 1], du[:, 0]) * 4.0 / np.pi)
    a = np.where(a > 4.0, 8.0 - a, a)
    a = np.where(a > 2.0, 4.0 - a, a)
    # Snap round-off so that grid edges use exactly one table row.
    return np.where(np.abs(a - np.round(a)) < 1e-9, np.round(a), a)


def build_flag_mesh(
    *,
    width: float,
    height: float,
    nu: int,
    nv: int,
    pin_mode: PinMode = "edge",
    top_z: float,
) -> FlagMesh:
    """Build the flag mesh and its rest-state data.

    Args:
        width: Hoist-to-fly length in metres (along the warp and +x).
        height: Hoist length in metres (along the weft and +z).
        nu: Nodes along the width, at least 3.
        nv: Nodes along the height, at least 3.
        pin_mode: ``"edge"`` holds every hoist node on the pole, ``"corners"`` only the two
            hoist corners (as in ArcSim's flag scene).
        top_z: Height of the flag's top hoist corner above the ground, metres.

    Raises:
        UserInputError: on a grid smaller than 3×3, non-positive sizes or an unknown pin mode.
    """
    if nu < 3 or nv < 3:
        raise UserInputError(f"the flag grid needs at least 3x3 nodes, got {nu}x{nv}")
    if not (width > 0 and height > 0):
        raise UserInputError(f"flag size must be positive, got {width} x {height} m")
    if pin_mode not in ("edge", "corners"):
        raise UserInputError(f"pin_mode must be 'edge' or 'corners', got {pin_mode!r}")
    i, j = np.meshgrid(np.arange(nu), np.arange(nv))
    u = (i.ravel() / (nu - 1)).astype(np.float64)
    v = (j.ravel() / (nv - 1)).astype(np.float64)
    material_uv = np.stack([u * width, v * height], axis=1)
    rest = np.stack([material_uv[:, 0], np.zeros_like(u), top_z - height + material_uv[:, 1]], axis=1)
    faces = grid_faces(nu, nv)

    p0, p1, p2 = (material_uv[faces[:, k]] for k in range(3))
    e1, e2 = p1 - p0, p2 - p0
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    # Inverse of the 2x2 matrix [e1 e2] (columns), stored row-major.
    dm_inv = np.stack([e2[:, 1], -e2[:, 0], -e1[:, 1], e1[:, 0]], axis=1) / det[:, None]
    face_area = 0.5 * np.abs(det)
    node_area = np.zeros(len(rest))
    for k in range(3):
        np.add.at(node_area, faces[:, k], face_area / 3.0)

    hinges, hinge_faces, edges = mesh_hinges(faces)
    du = material_uv[hinges[:, 1]] - material_uv[hinges[:, 0]]
    hinge_length = np.linalg.norm(du, axis=1)
    cross = lambda a, b: np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])  # noqa: E731
    a0 = 0.5 * cross(du, material_uv[hinges[:, 2]] - material_uv[hinges[:, 0]])
    a1 = 0.5 * cross(du, material_uv[hinges[:, 3]] - material_uv[hinges[:, 0]])

    pinned = i.ravel() == 0
    if pin_mode == "corners":
        pinned &= (j.ravel() == 0) | (j.ravel() == nv - 1)
    return FlagMesh(
        nu=nu,
        nv=nv,
        rest=rest,
        material_uv=material_uv,
        uv=np.stack([u, v], axis=1).astype(np.float32),
        faces=faces,
        face_dm_inv=np.ascontiguousarray(dm_inv),
        face_area=face_area,
        node_area=node_area,
        hinges=hinges,
        hinge_faces=hinge_faces,
        hinge_length=hinge_length,
        hinge_area=a0 + a1,
        hinge_direction=_bending_direction(du),
        edges=edges,
        edge_length=np.linalg.norm(material_uv[edges[:, 1]] - material_uv[edges[:, 0]], axis=1),
        pinned=pinned,
    )
