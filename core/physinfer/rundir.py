"""The run directory of a refinement: configuration, append-only trial log, results.

Layout of ``--out DIR``::

    run.json          what was run (plugin, optimizer, seed, parameter space, target, ...)
    trials.jsonl      one JSON object per completed trial, appended and fsynced as it ends
    target.mp4        the target clip as embedded (for the side-by-side video)
    result.json       written at the end
    refinement.png    distance and parameters against the step
    side_by_side.mp4  target | best simulation
    best_trajectory.npz

    noise_prior.json, selection.json   the observation noise and --select-top's re-simulations
    .physinfer.lock   held by the process writing the run (:mod:`physinfer.locking`)

Nothing outside ``DIR`` is written, and nothing in it that the run did not create: an
``--out`` holding anything but a run (a new or empty directory) is refused, and
``--overwrite`` removes only the files listed above. ``--resume`` reads ``run.json`` and
``trials.jsonl`` back; a mismatch (another plugin) or a corrupt log is a clear error and
nothing is overwritten.
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json, check_output_dir, to_jsonable
from physinfer.locking import LOCK_FILE

RUN_FILE = "run.json"
TRIALS_FILE = "trials.jsonl"
NOISE_PRIOR_FILE = "noise_prior.json"
SELECTION_FILE = "selection.json"
TARGET_FILE = "target.mp4"
#: Every file a refinement writes into its run directory: ``--overwrite`` removes these and
#: nothing else.
RUN_OUTPUTS = (
    RUN_FILE,
    TRIALS_FILE,
    NOISE_PRIOR_FILE,
    SELECTION_FILE,
    TARGET_FILE,
    "result.json",
    "refinement.png",
    "side_by_side.mp4",
    "best_trajectory.npz",
    "report.html",
)


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

    def check_out(self, *, overwrite: bool = False, target: Path | None = None) -> None:
        """Refuse an ``--out`` that a run may not write, before any work starts.

        Allowed: a new directory, an empty one (a lock file left by a run killed before it
        began counts as empty), or a physinfer run (to ``--resume`` or ``--overwrite``).

        Args:
            overwrite: ``--overwrite`` was given (an existing run may be replaced).
            target: ``--target``; refused when it is a file the run writes.

        Raises:
            UserInputError: ``--out`` is a file or cannot be made, holds files that are not a
                run's, holds a ``run.json`` physinfer did not write, or ``--target`` is one of
                its outputs.
        """
        check_output_dir(self.path)
        if target is not None and Path(target).resolve() in {(self.path / name).resolve() for name in RUN_OUTPUTS}:
            raise UserInputError(
                f"--target {target} is a file the run writes into --out {self.path}; "
                "move the video elsewhere or choose another --out"
            )
        if not self.path.is_dir():
            return
        if self.run_file.exists():
            if not self.holds_run():
                raise UserInputError(
                    f"--out {self.path} holds a {RUN_FILE} that physinfer did not write; choose another --out"
                )
            return
        others = sorted(p.name for p in self.path.iterdir() if p.name != LOCK_FILE)
        if others:
            shown = ", ".join(others[:3]) + (", ..." if len(others) > 3 else "")
            raise UserInputError(
                f"--out {self.path} is not empty ({shown}) and holds no physinfer run; a run would mix its "
                f"files with yours: give a new or empty directory, e.g. --out {self.path / 'run'}"
            )

    def holds_run(self) -> bool:
        """Whether ``run.json`` is a physinfer run's (a JSON object naming its plugin)."""
        try:
            info = json.loads(self.run_file.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            return False
        return isinstance(info, dict) and "plugin" in info

    def create(self, run_info: dict[str, Any], *, overwrite: bool = False) -> None:
        """Start a new run; refuse to clobber an existing one unless ``overwrite``.

        ``overwrite`` removes the outputs of the run there (:data:`RUN_OUTPUTS`) first, so
        no file of the old run is left beside the new one; other files stay.
        """
        if self.run_file.exists() and not overwrite:
            raise UserInputError(
                f"{self.path} already holds a run; continue it with --resume, "
                "or choose another --out (or pass --overwrite to start over)"
            )
        self.path.mkdir(parents=True, exist_ok=True)
        for name in RUN_OUTPUTS:
            (self.path / name).unlink(missing_ok=True)
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
