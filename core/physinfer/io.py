"""Atomic file writes and small safe readers used everywhere.

Every file physinfer writes goes through a temporary file in the same directory and an
``os.replace``, so an interrupted run never leaves a half-written result behind.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import UserInputError


def check_output_dir(path: str | Path, option: str = "--out") -> None:
    """Refuse an output directory that cannot be made, before any work starts.

    ``path`` may not exist yet; then the closest existing folder above it must be a
    writable directory. (Some places refuse even root, ``/proc`` for one; creating the
    directory reports those, as one line, where the run takes its lock.)

    Raises:
        UserInputError: ``path`` or a folder above it is a file, or no permission to write.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserInputError(f"{option} {path} is a file; give a directory")
    existing = next(p for p in (path, *path.parents) if p.exists() or p == p.parent)
    if not existing.is_dir():
        raise UserInputError(f"{option} {path}: {existing} is a file, so no directory can be made there")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UserInputError(f"{option} {path}: no permission to write in {existing}; choose another {option}")


def check_output_file(
    path: str | Path,
    option: str = "--out",
    *,
    overwrite: bool = False,
    suffixes: tuple[str, ...] = (),
    what: str = "the file",
    shown: str | None = None,
) -> Path:
    """Refuse an output file before any work: one the user has, or one that cannot be written.

    Nothing is made: ``path`` and the folders above it may not exist yet. The closest existing
    folder above it is tried with a temporary file, made and removed at once, so a place no one
    can write (``/proc``, a read-only mount, a folder without permission) is found even by root.

    Args:
        path: The file a command will write (atomically, :func:`atomic_path`).
        option: The option that named it, for messages.
        overwrite: Whether an existing file may be replaced (the command's ``--overwrite``).
        suffixes: Endings the name must have (lower case; empty: any).
        what: What the file is, for the suffix message (``"the trajectory file"``).
        shown: How the path is named in messages (default ``"OPTION PATH"``).

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        UserInputError: a wrong ending, a directory, an existing file without ``overwrite``, a
            file above it, or a folder that cannot be written.
    """
    path = Path(path)
    shown = shown or f"{option} {path}"
    if suffixes and path.suffix.lower() not in suffixes:
        raise UserInputError(f"{shown}: name {what} " + " or ".join(f"*{s}" for s in suffixes))
    if path.is_dir():
        raise UserInputError(f"{shown} is a directory; give a file name")
    if path.exists() and not overwrite:
        raise UserInputError(f"{shown} exists; give --overwrite to replace it, or another name")
    folder = next(p for p in path.parents if p.exists() or p == p.parent)
    if not folder.is_dir():
        raise UserInputError(f"{shown}: {folder} is a file, so nothing can be written under it")
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".physinfer-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UserInputError(
            f"{shown}: cannot write in {folder} ({exc.strerror or exc}); choose another {option}"
        ) from None
    return path


@contextmanager
def atomic_path(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it replaces ``path`` atomically.

    Args:
        path: Final destination.
        suffix: Suffix for the temporary file (some writers pick the format from it).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=suffix or path.suffix)
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results should read like any new file
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write text atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def atomic_write_json(path: str | Path, obj: Any) -> None:
    """Write JSON (indented, NaN-free) atomically."""
    atomic_write_text(path, json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n")


def read_keyed_json(path: str | Path, key: Any) -> dict[str, Any] | None:
    """The JSON object a resumable stage wrote to ``path`` (``{"key": key, ...}``, by
    :func:`atomic_write_json`) when it was written for this ``key``; ``None`` when there is
    no such file or it was written for another key (the stage then runs again)."""
    path = Path(path)
    if not path.is_file():
        return None
    stored = json.loads(path.read_text())
    return stored if stored.get("key") == key else None


def atomic_save_npz(path: str | Path, **arrays: Any) -> None:
    """Save arrays to an ``.npz`` atomically (object arrays are refused)."""
    for name, arr in arrays.items():
        if np.asarray(arr).dtype == object:
            raise TypeError(f"array {name!r} has dtype object; NPZ files here never hold pickles")
    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, **arrays)


def to_jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays and paths to JSON types; non-finite floats become None."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj
