"""Bouman-format hanging-fabric data: videos plus a ground-truth table, loaded and checked.

Expected layout (docs/hanging-cloth.md)::

    DIR/
      ground_truth.csv          or ground_truth.xlsx (first sheet)
      videos/
        <fabric>_W1.mp4         one video per fabric and fan level W1–W3
        <fabric>_W2.mp4         (.mp4 .avi .mov .mkv .webm .m4v .gif)
        ...

The table has a ``fabric`` column naming each fabric as its videos do, and one or more
``area_weight…`` and ``stiffness…`` columns whose headers carry their unit in brackets,
e.g. ``stiffness_1 [lbf*in^2]``. A fabric's measurements of one quantity (Bouman et al.
measured two, in orthogonal directions) are converted to oz/yd² and lbf·in² and averaged.
Every user mistake ends in a :class:`~physinfer.errors.UserInputError` saying what is wrong.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physinfer.errors import UserInputError
from physinfer.video import VIDEO_SUFFIXES
from physinfer_hanging_cloth.fan import FAN_LEVELS
from physinfer_hanging_cloth.units import CANONICAL_UNITS, unit_factor

TABLE_NAMES = ("ground_truth.csv", "ground_truth.xlsx")
"""File names the ground-truth table is looked for under, in this order."""
VIDEO_DIR = "videos"
"""Folder of the videos inside the dataset directory."""
VIDEO_FILE_SUFFIXES = tuple(sorted(VIDEO_SUFFIXES | {".gif"}))
_VIDEO_NAME = re.compile(r"^(?P<fabric>.+)_(?P<level>[wW][1-3])$")
_HEADER = re.compile(r"^\s*(?P<name>[^\[\(]*?)\s*(?:[\[\(](?P<unit>[^\]\)]*)[\]\)])?\s*$")
QUANTITIES = ("area_weight", "stiffness")


@dataclass(frozen=True)
class FabricTruth:
    """Ground truth of one fabric, in the canonical units.

    Attributes:
        fabric: The fabric's name (as in its video file names).
        area_weight: Mean area weight in oz/yd².
        stiffness: Mean bending stiffness in lbf·in².
        area_weight_measurements: Each area-weight measurement in oz/yd².
        stiffness_measurements: Each stiffness measurement in lbf·in².
    """

    fabric: str
    area_weight: float
    stiffness: float
    area_weight_measurements: tuple[float, ...]
    stiffness_measurements: tuple[float, ...]


@dataclass(frozen=True)
class VideoEntry:
    """One video of the dataset.

    Attributes:
        path: The video file.
        fabric: Its fabric.
        fan_level: ``"W1"``, ``"W2"`` or ``"W3"``.
    """

    path: Path
    fabric: str
    fan_level: str


@dataclass(frozen=True)
class BoumanDataset:
    """A checked dataset: every video has a known fabric, every fabric has videos.

    Attributes:
        root: The dataset directory.
        table: The ground-truth table file.
        fabrics: Ground truth by fabric name, in table order.
        videos: The videos, sorted by fabric (table order) then fan level.
    """

    root: Path
    table: Path
    fabrics: dict[str, FabricTruth]
    videos: tuple[VideoEntry, ...]

    @property
    def n_fabrics(self) -> int:
        """Number of fabrics."""
        return len(self.fabrics)

    def targets(self) -> dict[str, np.ndarray]:
        """Per-video natural logs of the ground truth: ``{"stiffness": (N,), "area_weight": (N,)}``."""
        return {
            q: np.log([getattr(self.fabrics[v.fabric], q) for v in self.videos]) for q in QUANTITIES
        }

    def groups(self) -> np.ndarray:
        """``(N,)`` int fabric index of every video (the leave-one-fabric-out folds)."""
        index = {name: i for i, name in enumerate(self.fabrics)}
        return np.array([index[v.fabric] for v in self.videos], dtype=np.int64)


def find_table(root: Path) -> Path:
    """The ground-truth table inside ``root``.

    Raises:
        UserInputError: when none of :data:`TABLE_NAMES` exists.
    """
    for name in TABLE_NAMES:
        if (root / name).is_file():
            return root / name
    raise UserInputError(
        f"no ground truth in {root}: expected {' or '.join(TABLE_NAMES)} "
        "(columns: fabric, area_weight_* [oz/yd^2], stiffness_* [lbf*in^2]; see docs/hanging-cloth.md)"
    )


def read_table_rows(path: Path) -> list[list[str]]:
    """Rows of a CSV file or of an XLSX file's first sheet as strings (header first).

    Blank rows and CSV lines starting with ``#`` are dropped.

    Raises:
        UserInputError: for another suffix or an unreadable file.
    """
    suffix = path.suffix.lower()
    try:
        if suffix == ".csv":
            with path.open(newline="", encoding="utf-8-sig") as handle:
                rows = [row for row in csv.reader(handle) if row and not row[0].lstrip().startswith("#")]
        elif suffix == ".xlsx":
            import openpyxl

            book = openpyxl.load_workbook(path, read_only=True, data_only=True)
            try:
                sheet = book.worksheets[0]
                rows = [["" if c is None else str(c) for c in row] for row in sheet.iter_rows(values_only=True)]
            finally:
                book.close()
        else:
            raise UserInputError(f"{path}: the ground-truth table must be .csv or .xlsx, not {suffix!r}")
    except UserInputError:
        raise
    except Exception as exc:  # csv.Error, zipfile.BadZipFile, OSError, openpyxl's own errors
        raise UserInputError(f"cannot read the ground-truth table {path}: {type(exc).__name__}: {exc}") from None
    return [row for row in rows if any(cell.strip() for cell in row)]


def _parse_header(header: Sequence[str], path: Path) -> tuple[int, dict[str, list[tuple[int, float]]]]:
    """Column of ``fabric`` and, per quantity, ``(column, factor to canonical unit)``."""
    fabric_col = None
    columns: dict[str, list[tuple[int, float]]] = {q: [] for q in QUANTITIES}
    for col, text in enumerate(header):
        match = _HEADER.match(text)
        name = re.sub(r"[\s\-]+", "_", match["name"].strip().lower()) if match else text.strip().lower()
        if name == "fabric":
            fabric_col = col
            continue
        quantity = next((q for q in QUANTITIES if name.startswith(q) or name.startswith(f"bending_{q}")), None)
        if quantity is None:
            continue  # other columns (names, notes) are allowed and ignored
        unit = match["unit"] if match else None
        if not unit or not unit.strip():
            raise UserInputError(
                f"{path}: column {text!r} has no unit; write it in brackets, e.g. "
                f"'{quantity}_1 [{CANONICAL_UNITS[quantity]}]'"
            )
        columns[quantity].append((col, unit_factor(quantity, unit)))
    if fabric_col is None:
        raise UserInputError(f"{path}: no 'fabric' column in the header {list(header)}")
    for quantity, found in columns.items():
        if not found:
            raise UserInputError(
                f"{path}: no {quantity} column; expected e.g. '{quantity}_1 [{CANONICAL_UNITS[quantity]}]' "
                f"(header: {list(header)})"
            )
    return fabric_col, columns


def _measurement(text: str, fabric: str, column: str, path: Path) -> float | None:
    """A positive measurement, ``None`` for an empty cell."""
    if not text.strip():
        return None
    try:
        value = float(text)
    except ValueError:
        raise UserInputError(f"{path}: fabric {fabric!r}, column {column!r}: {text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise UserInputError(f"{path}: fabric {fabric!r}, column {column!r}: {text!r} must be a positive number")
    return value


def load_ground_truth(path: str | Path) -> dict[str, FabricTruth]:
    """Read a ground-truth table (see the module docstring) into canonical units.

    Each quantity's non-empty measurements are converted and averaged (arithmetic mean).

    Raises:
        UserInputError: for a missing file, a bad header or unit, a duplicate fabric, a
            non-numeric or non-positive value, or a fabric without any measurement of a
            quantity.
    """
    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"ground-truth table {path} does not exist")
    rows = read_table_rows(path)
    if len(rows) < 2:
        raise UserInputError(f"{path}: the table needs a header row and at least one fabric")
    header = rows[0]
    fabric_col, columns = _parse_header(header, path)
    fabrics: dict[str, FabricTruth] = {}
    for row in rows[1:]:
        row = list(row) + [""] * (len(header) - len(row))
        fabric = row[fabric_col].strip()
        if not fabric:
            raise UserInputError(f"{path}: a row has values but no fabric name: {row}")
        if fabric in fabrics:
            raise UserInputError(f"{path}: fabric {fabric!r} appears twice; give each fabric one row")
        values: dict[str, tuple[float, ...]] = {}
        for quantity, found in columns.items():
            measured = [
                (_measurement(row[col], fabric, header[col], path), factor) for col, factor in found
            ]
            values[quantity] = tuple(v * factor for v, factor in measured if v is not None)
            if not values[quantity]:
                raise UserInputError(f"{path}: fabric {fabric!r} has no {quantity.replace('_', ' ')} measurement")
        fabrics[fabric] = FabricTruth(
            fabric=fabric,
            area_weight=float(np.mean(values["area_weight"])),
            stiffness=float(np.mean(values["stiffness"])),
            area_weight_measurements=values["area_weight"],
            stiffness_measurements=values["stiffness"],
        )
    return fabrics


def parse_video_name(path: Path) -> tuple[str, str]:
    """``(fabric, fan level)`` of a video named ``<fabric>_W<k>.<ext>``.

    Raises:
        UserInputError: when the name does not follow that pattern.
    """
    match = _VIDEO_NAME.match(path.stem)
    if match is None:
        raise UserInputError(
            f"video {path.name!r} is not named <fabric>_W1, _W2 or _W3 (e.g. 'denim_W2.mp4'); rename it"
        )
    return match["fabric"], match["level"].upper()


def list_videos(video_dir: Path) -> list[VideoEntry]:
    """Every video file in ``video_dir`` (other files are ignored).

    Raises:
        UserInputError: when the folder is missing, holds no video, or a video is misnamed
            or duplicated (same fabric and fan level twice).
    """
    if not video_dir.is_dir():
        raise UserInputError(f"no video folder {video_dir}; put the videos in DIR/{VIDEO_DIR}/")
    entries: dict[tuple[str, str], VideoEntry] = {}
    for path in sorted(video_dir.iterdir()):
        if path.name.startswith(".") or path.suffix.lower() not in VIDEO_FILE_SUFFIXES:
            continue
        fabric, level = parse_video_name(path)
        if (fabric, level) in entries:
            raise UserInputError(
                f"two videos of fabric {fabric!r} at {level}: {entries[fabric, level].path.name} and {path.name}"
            )
        entries[fabric, level] = VideoEntry(path=path, fabric=fabric, fan_level=level)
    if not entries:
        raise UserInputError(
            f"no videos in {video_dir} (looked for {', '.join(VIDEO_FILE_SUFFIXES)} named <fabric>_W<k>)"
        )
    return list(entries.values())


def load_dataset(root: str | Path, *, min_fabrics: int = 3) -> BoumanDataset:
    """Load and check a Bouman-format dataset directory.

    Args:
        root: The dataset directory (layout in the module docstring).
        min_fabrics: Fewest fabrics accepted (leave-one-fabric-out needs several).

    Raises:
        UserInputError: for a missing directory, table or video folder; videos of fabrics
            the table does not know; fabrics of the table without any video; fewer than
            ``min_fabrics`` fabrics; and every table error of :func:`load_ground_truth`.
    """
    root = Path(root)
    if not root.is_dir():
        raise UserInputError(f"dataset directory {root} does not exist")
    table = find_table(root)
    fabrics = load_ground_truth(table)
    videos = list_videos(root / VIDEO_DIR)
    unknown = sorted({v.fabric for v in videos} - set(fabrics))
    if unknown:
        raise UserInputError(
            f"videos of unknown fabrics {unknown} (not in {table.name}); add them to the table or remove the videos"
        )
    missing = [name for name in fabrics if not any(v.fabric == name for v in videos)]
    if missing:
        raise UserInputError(
            f"missing videos: no video of fabric(s) {missing} in {root / VIDEO_DIR}; "
            "add <fabric>_W1/_W2/_W3 videos or drop those rows from the table"
        )
    if len(fabrics) < min_fabrics:
        raise UserInputError(f"{len(fabrics)} fabric(s) in {table.name}; the evaluation needs at least {min_fabrics}")
    order = {name: i for i, name in enumerate(fabrics)}
    videos.sort(key=lambda v: (order[v.fabric], FAN_LEVELS.index(v.fan_level)))
    return BoumanDataset(root=root, table=table, fabrics=fabrics, videos=tuple(videos))
