"""The run directory of a refinement: configuration, append-only trial log, results.

Layout of ``--out DIR``::

    run.json          what was run (plugin, optimizer, seed, parameter space, target, ...)
    trials.jsonl      one JSON object per completed trial, appended and fsynced as it ends
    target.mp4        the target clip as embedded (for the side-by-side video)
    result.json       written at the end
    refinement.png    distance and parameters against the step
    side_by_side.mp4  target | best simulation
    best_trajectory.npz

Nothing outside ``DIR`` is written. ``--resume`` reads ``run.json`` and ``trials.jsonl``
back; a mismatch (another plugin) or a corrupt log is a clear error and nothing is
overwritten.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json, to_jsonable

RUN_FILE = "run.json"
TRIALS_FILE = "trials.jsonl"


@dataclass
class TrialRecord:
    """One completed (or failed) trial as logged.

    Attributes:
        step: 0-based position in the refinement.
        index: The optimizer's trial index.
        x: Normalised coordinates in ``[-1, 1]^D``.
        params: Physical values by name.
        distance: Embedding distance, ``None`` when failed.
        status: ``"ok"`` or ``"failed"``.
        error: Why it failed, if it did.
        timings: Seconds spent per phase (``simulate``, ``render``, ``embed``, ``optimizer``).
    """

    step: int
    index: int
    x: list[float]
    params: dict[str, float]
    distance: float | None
    status: str = "ok"
    error: str | None = None
    timings: dict[str, float] = field(default_factory=dict)


class RunDirectory:
    """Reads and writes one run directory.

    Args:
        path: The ``--out`` directory.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    @property
    def run_file(self) -> Path:
        return self.path / RUN_FILE

    @property
    def trials_file(self) -> Path:
        return self.path / TRIALS_FILE

    def create(self, run_info: dict[str, Any], *, overwrite: bool = False) -> None:
        """Start a new run; refuse to clobber an existing one unless ``overwrite``."""
        if self.run_file.exists() and not overwrite:
            raise UserInputError(
                f"{self.path} already holds a run; continue it with --resume, "
                "or choose another --out (or pass --overwrite to start over)"
            )
        self.path.mkdir(parents=True, exist_ok=True)
        self.trials_file.unlink(missing_ok=True)
        atomic_write_json(self.run_file, run_info)
        self.trials_file.touch()

    def load_run_info(self) -> dict[str, Any]:
        """``run.json`` of an existing run."""
        if not self.run_file.exists():
            raise UserInputError(f"{self.path} holds no run to resume (no {RUN_FILE}); start without --resume")
        try:
            return json.loads(self.run_file.read_text())
        except json.JSONDecodeError as exc:
            raise UserInputError(f"{self.run_file} is corrupt ({exc}); start a new run with another --out") from None

    def check_compatible(self, run_info: dict[str, Any], keys: tuple[str, ...]) -> dict[str, Any]:
        """Compare ``keys`` of a stored run with the requested one; raise on mismatch."""
        stored = self.load_run_info()
        for key in keys:
            if stored.get(key) != run_info.get(key):
                raise UserInputError(
                    f"cannot resume {self.path}: it was run with {key}={stored.get(key)!r}, "
                    f"not {run_info.get(key)!r}; use the same settings or another --out"
                )
        return stored

    def read_trials(self) -> list[TrialRecord]:
        """All logged trials. An incomplete last line (a write cut by a kill) is dropped.

        Raises:
            UserInputError: when a complete line is not a valid trial record.
        """
        if not self.trials_file.exists():
            return []
        text = self.trials_file.read_text()
        lines = text.split("\n")
        complete, tail = lines[:-1], lines[-1]
        records = []
        for lineno, line in enumerate(complete, start=1):
            if not line.strip():
                continue
            try:
                records.append(TrialRecord(**json.loads(line)))
            except (json.JSONDecodeError, TypeError) as exc:
                raise UserInputError(
                    f"{self.trials_file} line {lineno} is corrupt ({exc}); nothing was changed. "
                    "Delete that line (and those after it) to resume from the trials before it."
                ) from None
        if tail.strip():  # a cut write: the trial reruns
            self._truncate_to(len(text) - len(tail))
        return records

    def _truncate_to(self, size: int) -> None:
        with open(self.trials_file, "r+b") as fh:
            fh.truncate(size)

    def append_trial(self, record: TrialRecord) -> None:
        """Append one trial durably (one write, flushed and fsynced)."""
        line = json.dumps(to_jsonable(asdict(record)), allow_nan=False) + "\n"
        with open(self.trials_file, "a", encoding="utf-8") as fh:
            fh.write(line)
            fh.flush()
            os.fsync(fh.fileno())
