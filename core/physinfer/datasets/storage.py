"""The on-disk layout of a dataset directory, its checksums and integrity checks.

```
DIR/dataset.json            what the dataset is (phenomenon, seed, preset, parameter space)
                            and its status ("incomplete" / "complete")
DIR/manifest.jsonl          one JSON row per render, in render order (written last)
DIR/shards/unit-00012.npy   uint8 clips of unit 12, (N, T, H, W) or (N, T, H, W, 3)
DIR/trajectories/sim-000042.npz   the trajectory of simulation 42 (Trajectory.save format)
DIR/units/unit-00012.json   the record of unit 12: its manifest rows and checksums;
                            written after its files, so it marks the unit complete
DIR/.physinfer.lock         held by the process writing the dataset (:mod:`physinfer.locking`)
```

Every file is written atomically (:mod:`physinfer.io`). Shards are hashed as files
(``.npy`` files are deterministic); trajectories by their arrays (an ``.npz`` holds zip
timestamps), see :func:`arrays_digest`.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json, atomic_write_text, to_jsonable

FORMAT_NAME = "physinfer-dataset"
FORMAT_VERSION = 1
DATASET_FILE = "dataset.json"
MANIFEST_FILE = "manifest.jsonl"
SHARDS_DIR = "shards"
TRAJECTORIES_DIR = "trajectories"
UNITS_DIR = "units"
_CHUNK = 8 << 20


def shard_relpath(unit: int) -> str:
    """Path of unit ``unit``'s shard relative to the dataset directory."""
    return f"{SHARDS_DIR}/unit-{unit:05d}.npy"


def trajectory_relpath(sim: int) -> str:
    """Path of simulation ``sim``'s trajectory relative to the dataset directory."""
    return f"{TRAJECTORIES_DIR}/sim-{sim:06d}.npz"


def unit_record_path(root: Path, unit: int) -> Path:
    """Path of unit ``unit``'s completion record."""
    return root / UNITS_DIR / f"unit-{unit:05d}.json"


def file_digest(path: str | Path) -> str:
    """``"sha256:<hex>"`` of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(_CHUNK):
            h.update(chunk)
    return "sha256:" + h.hexdigest()


def arrays_digest(arrays: Mapping[str, np.ndarray]) -> str:
    """``"sha256:<hex>"`` over arrays' names, dtypes, shapes and bytes, in name order."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        arr = np.ascontiguousarray(arrays[name])
        h.update(f"{name}|{arr.dtype.str}|{arr.shape}|".encode())
        h.update(arr.tobytes())
    return "sha256:" + h.hexdigest()


def npz_digest(path: str | Path) -> str:
    """:func:`arrays_digest` of an ``.npz`` file's arrays (no pickles loaded)."""
    with np.load(path, allow_pickle=False) as data:
        return arrays_digest({name: data[name] for name in data.files})


def read_json(path: Path) -> Any:
    """Parse a JSON file; ``None`` if it is missing, empty or not valid JSON."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def write_unit_record(root: Path, record: Mapping[str, Any]) -> None:
    """Write a unit's record atomically; from then on the unit counts as complete."""
    atomic_write_json(unit_record_path(root, int(record["unit"])), record)


def unit_problems(root: Path, record: Mapping[str, Any], *, verify: bool) -> list[str]:
    """What is wrong with a recorded unit's files; empty when it is intact.

    Args:
        root: Dataset directory.
        record: The unit's record.
        verify: Also recompute checksums (reads every byte); otherwise only
            existence and sizes are checked, which catches truncation.
    """
    problems: list[str] = []
    shard = record["shard"]
    path = root / shard["file"]
    if not path.is_file():
        return [f"{shard['file']} is missing"]
    if path.stat().st_size != int(shard["bytes"]):
        problems.append(f"{shard['file']} has {path.stat().st_size} bytes, expected {shard['bytes']}")
    elif verify and file_digest(path) != shard["checksum"]:
        problems.append(f"{shard['file']} does not match its checksum")
    for traj in record["trajectories"]:
        tpath = root / traj["file"]
        if not tpath.is_file():
            problems.append(f"{traj['file']} is missing")
        elif verify:
            try:
                ok = npz_digest(tpath) == traj["checksum"]
            except (OSError, ValueError, KeyError, EOFError):
                ok = False
            if not ok:
                problems.append(f"{traj['file']} is unreadable or does not match its checksum")
    return problems


def remove_unit_files(root: Path, record: Mapping[str, Any]) -> None:
    """Delete a unit's record, shard and trajectories (before regenerating it)."""
    unit_record_path(root, int(record["unit"])).unlink(missing_ok=True)
    (root / record["shard"]["file"]).unlink(missing_ok=True)
    for traj in record["trajectories"]:
        (root / traj["file"]).unlink(missing_ok=True)


def remove_stale_temporaries(root: Path) -> int:
    """Delete temporary files a killed run left behind (``.<name>.*`` from atomic writes)."""
    prefixes = {
        SHARDS_DIR: (".unit-",),
        TRAJECTORIES_DIR: (".sim-",),
        UNITS_DIR: (".unit-",),
        ".": (f".{DATASET_FILE}.", f".{MANIFEST_FILE}."),
    }
    removed = 0
    for sub, starts in prefixes.items():
        folder = root / sub
        if not folder.is_dir():
            continue
        for path in folder.iterdir():
            if path.is_file() and path.name.startswith(starts):
                path.unlink(missing_ok=True)
                removed += 1
    return removed


def write_manifest(root: Path, records: Iterable[Mapping[str, Any]]) -> int:
    """Write ``manifest.jsonl``: every unit's rows, sorted by render id. Returns the row count."""
    rows = sorted((row for rec in records for row in rec["rows"]), key=lambda r: r["render"])
    text = "".join(json.dumps(to_jsonable(row), sort_keys=True, allow_nan=False) + "\n" for row in rows)
    atomic_write_text(root / MANIFEST_FILE, text)
    return len(rows)


def read_manifest(root: Path) -> list[dict[str, Any]]:
    """The rows of ``manifest.jsonl``.

    Raises:
        UserInputError: a line that is not a JSON object (a damaged or cut manifest).
    """
    rows = []
    with open(root / MANIFEST_FILE, encoding="utf-8", errors="replace") as f:
        for number, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                row = None
            if not isinstance(row, dict):
                raise UserInputError(
                    f"{root / MANIFEST_FILE}: line {number} is not a manifest row (the file is damaged or cut); "
                    f"run `physinfer dataset generate --out {root}` again with the same settings to rewrite it"
                )
            rows.append(row)
    return rows


def directory_bytes(root: Path) -> int:
    """Total size of the files under ``root``."""
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())
