"""A dataset directory's description and resuming: what it holds, which units are intact.

``dataset.json`` records what determines the content (:func:`dataset_config`) and whether
the dataset is complete; a run on a directory holding another dataset is refused with the
difference. On resume, :func:`resume_state` keeps units whose record and files are intact
and deletes damaged ones (missing, truncated, checksum mismatch) so they are generated again.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

from physinfer.datasets.generator import DatasetGenerator
from physinfer.datasets.plan import UnitPlan
from physinfer.datasets.presets import DatasetPreset
from physinfer.datasets.storage import (
    DATASET_FILE,
    FORMAT_NAME,
    FORMAT_VERSION,
    read_json,
    remove_unit_files,
    unit_problems,
    unit_record_path,
)
from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json, check_output_dir, to_jsonable
from physinfer.locking import LOCK_FILE
from physinfer.scene import scene_of


class GenerateProgress(Protocol):
    """Receives progress: a phase starts with a total, then advances."""

    def start(self, phase: str, total: int, done: int = 0) -> None:
        """Phase ``"verify"`` (in units) or ``"generate"`` (in renders) begins."""

    def advance(self, n: int) -> None:
        """``n`` more units verified or renders written."""


def dataset_config(generator: DatasetGenerator, preset: DatasetPreset, seed: int) -> dict[str, Any]:
    """What determines a dataset's content; a resumed run must match it exactly.

    ``scene`` (``dataset generate --scene-set``) and ``scene_ranges`` (``--scene-range``)
    are recorded only when given, so datasets made before scenes existed still resume.
    """
    described = preset.to_dict()
    described.pop("description")
    config: dict[str, Any] = {
        "phenomenon": generator.phenomenon,
        "generator": f"{type(generator).__module__}.{type(generator).__qualname__}",
        "seed": seed,
        "preset": described,
        "parameters": generator.parameter_space.to_dict(),
    }
    scene = scene_of(getattr(generator, "record", None))
    if scene is not None:
        config["scene"] = scene
    if generator.scene_ranges:
        config["scene_ranges"] = {name: list(r) for name, r in sorted(generator.scene_ranges.items())}
    return json.loads(json.dumps(to_jsonable(config)))


def check_directory(root: Path) -> None:
    """Refuse an output directory that exists, holds no dataset and is not empty (or is unusable).

    Raises:
        UserInputError: naming a few of the files found.
    """
    check_output_dir(root)
    if root.is_dir() and not (root / DATASET_FILE).exists():
        others = [p.name for p in root.iterdir() if p.name != LOCK_FILE]
        if others:
            raise UserInputError(
                f"--out {root} is not empty and holds no dataset ({', '.join(sorted(others)[:3])}...); "
                "give a new or empty directory"
            )


def start_dataset(root: Path, config: dict[str, Any]) -> None:
    """Describe a new dataset as incomplete in ``dataset.json``, or check that the one there is this one.

    Raises:
        UserInputError: ``dataset.json`` is not a dataset description, or describes another
            dataset (the message lists the differences).
    """
    path = root / DATASET_FILE
    if path.exists():
        existing = read_json(path)
        if not isinstance(existing, dict) or existing.get("format") != FORMAT_NAME:
            raise UserInputError(f"{path} is not a physinfer dataset description; give another --out")
        if existing.get("config") != config:
            diff = _config_difference(existing.get("config") or {}, config)
            raise UserInputError(
                f"{root} holds a different dataset ({diff}); resume it with the same options, "
                "or give another --out"
            )
        if existing.get("status") == "incomplete":
            return
    atomic_write_json(
        path, {"format": FORMAT_NAME, "version": FORMAT_VERSION, "config": config, "status": "incomplete"}
    )


def _config_difference(old: Mapping[str, Any], new: Mapping[str, Any], prefix: str = "") -> str:
    diffs: list[str] = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if a == b:
            continue
        if isinstance(a, dict) and isinstance(b, dict):
            diffs.append(_config_difference(a, b, f"{prefix}{key}."))
        else:
            diffs.append(f"{prefix}{key}: {json.dumps(a)} there, {json.dumps(b)} now")
    return "; ".join(d for d in diffs if d)


def resume_state(
    root: Path, units: list[UnitPlan], *, verify: bool, progress: GenerateProgress | None
) -> tuple[dict[int, dict[str, Any]], list[UnitPlan], int]:
    """Records of intact units, the units still to run and how many were damaged."""
    records: dict[int, dict[str, Any]] = {}
    todo: list[UnitPlan] = []
    regenerated = 0
    recorded = {u.unit for u in units if unit_record_path(root, u.unit).exists()}
    if progress is not None and recorded:
        progress.start("verify", len(recorded))
    for unit in units:
        record = read_json(unit_record_path(root, unit.unit)) if unit.unit in recorded else None
        if unit.unit not in recorded:
            todo.append(unit)
            continue
        if _intact(root, unit, record, verify=verify):
            records[unit.unit] = record
        else:
            if isinstance(record, dict) and "shard" in record:
                remove_unit_files(root, record)
            unit_record_path(root, unit.unit).unlink(missing_ok=True)
            regenerated += 1
            todo.append(unit)
        if progress is not None:
            progress.advance(1)
    return records, todo, regenerated


def _intact(root: Path, unit: UnitPlan, record: Any, *, verify: bool) -> bool:
    """Whether a unit's record is readable, belongs to this plan and its files are intact."""
    try:
        return record["sims"] == [s.sim for s in unit.sims] and not unit_problems(root, record, verify=verify)
    except (TypeError, KeyError):  # an unreadable or foreign record
        return False


def finish_dataset(
    root: Path, config: dict[str, Any], renders: Mapping[str, int], failed_sims: list[dict[str, Any]]
) -> None:
    """Mark the dataset complete, with its final counts (deterministic content only)."""
    atomic_write_json(
        root / DATASET_FILE,
        {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "config": config,
            "status": "complete",
            "renders": renders,
            "failed_sims": [f["sim"] for f in failed_sims],
        },
    )
