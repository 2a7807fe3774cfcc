"""Trajectories from files: physinfer's NPZ or a folder of per-frame OBJ meshes.

This is how another simulator's output enters physinfer (``physinfer render
--trajectory``): a trajectory NPZ as :meth:`physinfer.types.Trajectory.save` writes it,
or one Wavefront OBJ file per frame, sorted by the frame number in their names
(``frame_0001.obj``, or ArcSim's ``0001_00.obj``). Every frame must have the same
vertex count and faces; quads and larger polygons are split into triangles (a fan);
texture coordinates (``vt``) become ``extras["uv"]`` normalised to ``[0, 1]``. The
coordinates are taken as they are, in physinfer's frame (metres, z up, wind along +x,
a flag's hoist on the pole at x = y = 0): nothing is rescaled or rotated.

Everything a user can get wrong (object arrays in an NPZ, a missing frame, a face
indexing a vertex that does not exist, a NaN) is a :class:`~physinfer.errors.UserInputError`
naming the file. numpy only.

A file is never trusted with the machine's memory: an NPZ's arrays are sized from their
``.npy`` headers and the archive's member sizes before anything is loaded (a 2 MB file of
compressed zeros may declare gigabytes), faces must be integers, and a coordinate beyond
:data:`MAX_COORDINATE` metres is refused as a unit mistake.
"""

from __future__ import annotations

import math
import re
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from physinfer.errors import UserInputError
from physinfer.io import atomic_write_text
from physinfer.types import FPS_RANGE, Trajectory
from physinfer.types import check_fps as types_check_fps

#: The most bytes a trajectory file's arrays may hold once loaded (a long flag: ~10 MB).
MAX_TRAJECTORY_BYTES = 1 << 30
#: The farthest a vertex may lie from the origin, in metres.
MAX_COORDINATE = 1e6


def load_trajectory(path: str | Path, fps: float | None = None) -> Trajectory:
    """Read a trajectory NPZ or a folder of per-frame OBJ meshes.

    Args:
        path: An ``.npz`` written by ``physinfer simulate --trajectory-out`` (or a refine
            run's ``best_trajectory.npz``), or a folder of ``.obj`` files, one per frame.
        fps: Frame rate; overrides the NPZ's and is required for an OBJ folder.

    Returns:
        The trajectory, vertices ``(T, V, 3)`` float32, faces ``(F, 3)`` int32.

    Raises:
        UserInputError: a path that is neither, unreadable or inconsistent content, a
            non-finite vertex, a frame rate that is not a positive number.
    """
    path = Path(path)
    if fps is not None:
        check_fps(fps)
    if path.is_dir():
        if fps is None:
            raise UserInputError(
                f"{path}: OBJ files carry no frame rate; pass it with --fps (e.g. --fps 25)"
            )
        trajectory = read_obj_sequence(path, fps)
    elif path.is_file():
        trajectory = read_trajectory_npz(path)
        if fps is not None:
            trajectory = replace(trajectory, fps=float(fps))
        elif math.isfinite(trajectory.fps) and not FPS_RANGE[0] <= trajectory.fps <= FPS_RANGE[1]:
            raise UserInputError(  # a rate no video is written at: say so before rendering
                f"{path} records {trajectory.fps:g} fps; give --fps from {FPS_RANGE[0]:g} to "
                f"{FPS_RANGE[1]:g} to render it at another rate"
            )
    else:
        raise UserInputError(
            f"trajectory {path} does not exist; give an .npz file or a folder of .obj files"
        )
    check_trajectory(trajectory, str(path))
    return trajectory


def check_fps(fps: float) -> None:
    """Refuse a ``--fps`` that is not a frame rate from 0.1 to 1000 (:func:`physinfer.types.check_fps`)."""
    types_check_fps(fps)


def read_trajectory_npz(path: str | Path) -> Trajectory:
    """Read an NPZ written by :meth:`Trajectory.save`, refusing object arrays (no unpickling).

    Raises:
        UserInputError: not an NPZ, object arrays, missing ``vertices``/``faces``/``fps``.
    """
    path = Path(path)
    check_npz_size(path)
    _refuse_other_formats(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            names = list(data.files)
            for name in names:
                array = data[name]  # loading each array is the check
                if name == "faces" and array.dtype.kind not in "iu":
                    raise UserInputError(
                        f"{path}: faces must be integers (vertex indices), got {array.dtype} values"
                    )
    except UserInputError:
        raise
    except ValueError as exc:
        if "allow_pickle" in str(exc) or "Object arrays" in str(exc):
            raise UserInputError(
                f"{path} holds object arrays (pickled Python objects), which physinfer never loads; "
                "save plain numeric arrays (vertices, faces, fps) as Trajectory.save does"
            ) from None
        raise UserInputError(f"cannot read trajectory {path}: {exc}") from None
    except (OSError, EOFError) as exc:
        raise UserInputError(f"cannot read trajectory {path} as an NPZ file: {exc}") from None
    missing = [k for k in ("vertices", "faces", "fps") if k not in names]
    if missing:
        raise UserInputError(
            f"{path} is not a physinfer trajectory: it lacks {', '.join(missing)} "
            "(expected vertices (T, V, 3), faces (F, 3), fps)"
        )
    return Trajectory.load(path)


#: How an NPZ (a zip archive) and a lone ``.npy`` array begin.
_NUMPY_MAGIC = (b"PK\x03\x04", b"PK\x05\x06", b"\x93NUMPY")


def _refuse_other_formats(path: Path) -> None:
    """Refuse a file that is neither an NPZ nor an ``.npy`` before numpy reads it: numpy takes
    any other file for a pickle, and its refusal would name pickles (a video given as the
    trajectory was told it "holds object arrays")."""
    try:
        with path.open("rb") as f:
            head = f.read(6)
    except OSError as exc:
        raise UserInputError(f"cannot read trajectory {path}: {exc}") from None
    if not head.startswith(_NUMPY_MAGIC):
        raise UserInputError(
            f"{path} is not an NPZ file: a trajectory is the NPZ `simulate --trajectory-out` (or "
            "Trajectory.save) writes, or a folder of per-frame OBJ meshes with --fps"
        )


def check_npz_size(path: Path) -> None:
    """Refuse an NPZ whose arrays would take more than :data:`MAX_TRAJECTORY_BYTES`, from the
    ``.npy`` headers and the archive's member sizes alone (nothing is loaded).

    Raises:
        UserInputError: naming the largest array, its shape and the total.
    """
    try:
        archive = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile):
        return  # not an archive: read_trajectory refuses it by its first bytes (or np.load reads a .npy)
    declared: list[tuple[int, str, tuple[int, ...], str]] = []
    with archive:
        for info in archive.infolist():
            name = info.filename.removesuffix(".npy")
            size = info.file_size  # what the member inflates to, header included
            shape: tuple[int, ...] = ()
            dtype = "?"
            try:
                with archive.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    read = {(1, 0): np.lib.format.read_array_header_1_0,
                            (2, 0): np.lib.format.read_array_header_2_0}.get(version)  # fmt: skip
                    if read is not None:
                        shape, _, kind = read(fh, max_header_size=10_000)
                        size = max(size, math.prod(shape) * kind.itemsize)
                        dtype = str(kind)
            except (OSError, ValueError, zipfile.BadZipFile, EOFError):
                pass  # a damaged member: np.load names it
            declared.append((size, name, shape, dtype))
    total = sum(size for size, *_ in declared)
    if total > MAX_TRAJECTORY_BYTES:
        size, name, shape, dtype = max(declared)
        what = f"{name} {shape} {dtype}" if shape else f"{name} ({size / 1e9:.1f} GB inflated)"
        raise UserInputError(
            f"{path} declares {what}, {total / 1e9:.1f} GB of arrays in all; a trajectory file may hold "
            f"at most {MAX_TRAJECTORY_BYTES / 1e9:.2g} GB, so it is refused before loading"
        )


def check_trajectory(trajectory: Trajectory, source: str) -> None:
    """Refuse what no renderer can draw: no frames, bad faces, non-finite vertices.

    Raises:
        UserInputError: naming ``source`` and the first offending frame or face.
    """
    n_frames, n_vertices = trajectory.vertices.shape[:2]
    if n_frames == 0 or n_vertices == 0:
        raise UserInputError(f"{source}: the trajectory has no frames or no vertices")
    if not math.isfinite(trajectory.fps):
        raise UserInputError(f"{source}: fps is {trajectory.fps}; pass a frame rate with --fps")
    faces = trajectory.faces
    if faces.size and (faces.min() < 0 or faces.max() >= n_vertices):
        bad = int(np.flatnonzero((faces < 0).any(axis=1) | (faces >= n_vertices).any(axis=1))[0])
        raise UserInputError(
            f"{source}: face {bad} {faces[bad].tolist()} indexes a vertex outside 0..{n_vertices - 1}"
        )
    finite = np.isfinite(trajectory.vertices).all(axis=(1, 2))
    if not finite.all():
        frame = int(np.flatnonzero(~finite)[0])
        raise UserInputError(f"{source}: frame {frame} has a NaN or infinite vertex position")
    far = np.abs(trajectory.vertices).max(axis=(1, 2)) > MAX_COORDINATE
    if far.any():
        frame = int(np.flatnonzero(far)[0])
        value = float(np.abs(trajectory.vertices[frame]).max())
        raise UserInputError(
            f"{source}: frame {frame} has a vertex coordinate of {value:g} m, beyond {MAX_COORDINATE:g} m; "
            "give coordinates in metres"
        )


# ------------------------------------------------------------------------------- OBJ


def read_obj_sequence(folder: str | Path, fps: float) -> Trajectory:
    """Read one OBJ mesh per frame from ``folder`` (see the module docstring for the rules).

    Args:
        folder: Folder holding the ``.obj`` files (other files are ignored).
        fps: Frame rate of the sequence.

    Returns:
        The trajectory; ``extras["uv"]`` ``(V, 2)`` when the first file has ``vt`` lines.

    Raises:
        UserInputError: no OBJ files, a missing or repeated frame number, files whose
            vertex count or faces differ from the first file's, a face out of range, a
            non-finite vertex, an unparsable line.
    """
    folder = Path(folder)
    files = frame_files(folder)
    first = read_obj(files[0])
    frames = [first.vertices]
    for path in files[1:]:
        mesh = read_obj(path)
        if len(mesh.vertices) != len(first.vertices):
            raise UserInputError(
                f"{path.name} has {len(mesh.vertices)} vertices but {files[0].name} has "
                f"{len(first.vertices)}; every frame must have the same vertices"
            )
        if not np.array_equal(mesh.faces, first.faces):
            raise UserInputError(
                f"{path.name}: its faces differ from {files[0].name}'s; every frame must share them"
            )
        frames.append(mesh.vertices)
    extras = {} if first.uv is None else {"uv": first.uv}
    return Trajectory(np.stack(frames).astype(np.float32), first.faces, float(fps), extras)


def frame_files(folder: Path) -> list[Path]:
    """The folder's ``.obj`` files in frame order, checked to be one contiguous sequence.

    Names are split into text and numbers; they must share their text parts, and exactly
    one number may vary (the frame number: ``frame_0007.obj``, ArcSim's ``0007_00.obj``).
    Without numbers the files are taken in name order.

    Raises:
        UserInputError: no OBJ files, mixed name patterns, frame numbers with a gap or a repeat.
    """
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".obj" and p.is_file())
    if not files:
        raise UserInputError(
            f"{folder}: the folder holds no .obj files (one mesh per frame expected)"
        )
    parts = [re.split(r"(\d+)", p.stem) for p in files]
    texts = {tuple(x[0::2]) for x in parts}
    if len(texts) > 1:
        examples = ", ".join(sorted("#".join(t) for t in texts)[:3])
        raise UserInputError(
            f"{folder}: the .obj names follow several patterns ({examples}); keep one sequence"
        )
    numbers = np.array([[int(n) for n in x[1::2]] for x in parts], dtype=np.int64).reshape(
        len(files), -1
    )
    varying = [c for c in range(numbers.shape[1]) if len(set(numbers[:, c])) > 1]
    if len(varying) > 1:
        raise UserInputError(
            f"{folder}: more than one number varies in the .obj names ({files[0].name}, {files[-1].name}); "
            "keep one sequence of frames in the folder"
        )
    if not varying:
        if numbers.shape[1] and len(files) > 1:  # same numbers, different text is excluded above
            raise UserInputError(f"{folder}: several .obj files carry the same frame number")
        return files
    index = numbers[:, varying[0]]
    order = np.argsort(index, kind="stable")
    index, files = index[order], [files[i] for i in order]
    steps = np.diff(index)
    if (steps == 0).any():
        k = int(np.flatnonzero(steps == 0)[0])
        raise UserInputError(
            f"{folder}: {files[k].name} and {files[k + 1].name} carry the same frame number"
        )
    if (steps != 1).any():
        k = int(np.flatnonzero(steps != 1)[0])
        raise UserInputError(
            f"{folder}: frames {index[k] + 1}..{index[k + 1] - 1} are missing between {files[k].name} and "
            f"{files[k + 1].name}; the sequence must be contiguous"
        )
    return files


@dataclass(frozen=True)
class ObjMesh:
    """One OBJ file: vertices ``(V, 3)`` float64, triangles ``(F, 3)`` int32, uv ``(V, 2)`` or None."""

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None


def read_obj(path: str | Path) -> ObjMesh:
    """Read the vertices, faces and texture coordinates of one OBJ file.

    Faces may use ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` and negative (relative)
    indices; polygons are split into a fan of triangles. A vertex's uv is that of its
    first face corner with a ``vt`` (a seam keeps the first); uv are rescaled to span
    ``[0, 1]`` on each axis.

    Raises:
        UserInputError: an unparsable line, no vertices, a face index out of range, a
            non-finite coordinate.
    """
    path = Path(path)
    vertices: list[list[float]] = []
    texcoords: list[list[float]] = []
    faces: list[list[int]] = []
    face_uv: list[list[int]] = []
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as exc:
        raise UserInputError(f"cannot read {path}: {exc.strerror or exc}") from None
    for number, line in enumerate(lines, 1):
        fields = line.split()
        if not fields:
            continue
        try:
            if fields[0] == "v":
                vertices.append([float(x) for x in fields[1:4]])
            elif fields[0] == "vt":
                texcoords.append([float(x) for x in fields[1:3]])
            elif fields[0] == "f":
                corners = [_corner(c, len(vertices), len(texcoords)) for c in fields[1:]]
                for k in range(1, len(corners) - 1):  # fan: (0, k, k+1)
                    tri = (corners[0], corners[k], corners[k + 1])
                    faces.append([c[0] for c in tri])
                    face_uv.append([c[1] for c in tri])
        except (ValueError, IndexError):
            raise UserInputError(
                f"{path.name} line {number}: cannot read {line.strip()[:60]!r}"
            ) from None
        if fields[0] == "v" and len(vertices[-1]) != 3:
            raise UserInputError(f"{path.name} line {number}: a vertex needs x y z")
    if not vertices:
        raise UserInputError(f"{path.name}: the file has no vertices ('v' lines)")
    v = np.asarray(vertices, dtype=np.float64)
    if not np.isfinite(v).all():
        raise UserInputError(f"{path.name}: a vertex coordinate is NaN or infinite")
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        bad = int(np.flatnonzero((f < 0).any(axis=1) | (f >= len(v)).any(axis=1))[0])
        raise UserInputError(
            f"{path.name}: face {bad} indexes vertex {int(f[bad].max()) + 1} (1-based) but the file has {len(v)}"
        )
    return ObjMesh(v, f.astype(np.int32), _vertex_uv(texcoords, f, face_uv, len(v), path))


def _corner(token: str, n_vertices: int, n_texcoords: int) -> tuple[int, int]:
    """``"v/vt/vn"`` → 0-based ``(v, vt)`` (``vt`` -1 when absent); OBJ counts from 1, negatives from the end."""
    parts = token.split("/")
    v = int(parts[0])
    vt = int(parts[1]) if len(parts) > 1 and parts[1] else 0
    v = v - 1 if v > 0 else n_vertices + v
    if vt == 0:
        return v, -1
    return v, (vt - 1 if vt > 0 else n_texcoords + vt)


def _vertex_uv(
    texcoords: list[list[float]],
    faces: np.ndarray,
    face_uv: list[list[int]],
    n_vertices: int,
    path: Path,
) -> np.ndarray | None:
    """Per-vertex uv normalised to ``[0, 1]``, or None without ``vt``."""
    if not texcoords:
        return None
    table = np.asarray(texcoords, dtype=np.float64)
    corner_uv = np.asarray(face_uv, dtype=np.int64).reshape(-1)
    corner_v = faces.reshape(-1)
    used = corner_uv >= 0
    if used.any() and corner_uv[used].max() >= len(table):
        raise UserInputError(
            f"{path.name}: a face uses texture coordinate {int(corner_uv.max()) + 1} of {len(table)}"
        )
    uv = np.full((n_vertices, 2), np.nan)
    # Write in reverse so that the first corner naming a vertex wins.
    uv[corner_v[used][::-1]] = table[corner_uv[used][::-1]]
    if np.isnan(uv).any():
        if len(table) != n_vertices:
            return None  # faces do not name a vt for every vertex: let the renderer derive uv
        uv = table  # one vt per vertex, in vertex order (a common export)
    lo, span = uv.min(axis=0), np.ptp(uv, axis=0)
    if not np.isfinite(uv).all() or (span <= 0).any():
        raise UserInputError(
            f"{path.name}: the texture coordinates (vt) are not finite or span nothing"
        )
    return ((uv - lo) / span).astype(np.float32)


def write_obj_sequence(
    trajectory: Trajectory, folder: str | Path, prefix: str = "frame_"
) -> list[Path]:
    """Write one OBJ per frame (``frame_0000.obj``...), with ``vt`` when the trajectory has uv.

    The inverse of :func:`read_obj_sequence` (nine significant digits: float32 positions
    read back exactly), for handing physinfer's meshes to other tools; each file is
    written atomically.

    Returns:
        The paths written, in frame order.
    """
    folder = Path(folder)
    uv = trajectory.extras.get("uv")
    faces = np.asarray(trajectory.faces) + 1
    face_lines = (
        "\n".join(f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in faces)
        if uv is not None
        else "\n".join(f"f {a} {b} {c}" for a, b, c in faces)
    )
    uv_lines = (
        "" if uv is None else "\n".join(f"vt {u:.9g} {v:.9g}" for u, v in np.asarray(uv)) + "\n"
    )
    digits = max(4, len(str(trajectory.n_frames - 1)))
    paths = []
    for index, frame in enumerate(trajectory.vertices):
        vertex_lines = "\n".join(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in frame)
        path = folder / f"{prefix}{index:0{digits}d}.obj"
        atomic_write_text(
            path, f"# physinfer frame {index}\n{vertex_lines}\n{uv_lines}{face_lines}\n"
        )
        paths.append(path)
    return paths
