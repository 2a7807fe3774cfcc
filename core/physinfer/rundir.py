"""The run directory of a refinement: configuration, append-only trial log, results.

Layout of ``--out DIR``::

    run.json          what was run (plugin, optimizer, seed, parameter space, target, ...)
    trials.jsonl      one JSON object per completed trial, appended and fsynced as it ends
    target.mp4        the target clip as embedded (for the side-by-side video)
    result.json       written at the end
    refinement.png    distance and parameters against the step
    side_by_side.mp4  target | best simulation
    best_trajectory.npz
    report.html       one self-contained page of the run (:mod:`physinfer.report`)

    noise_prior.json, selection.json   the observation noise and --select-top's re-simulations
    .physinfer.lock   held by the process writing the run (:mod:`physinfer.locking`)

    .physinfer.json   the manifest: this folder is a refine run's (:mod:`physinfer.outputs`)

Nothing outside ``DIR`` is written, and nothing in it that the run did not create: an
``--out`` holding anything but a run (a new or empty directory) is refused, and
``--overwrite`` removes only the files listed above. A run is recognised by its manifest,
never by a ``run.json`` alone. ``--resume`` reads ``run.json`` and
``trials.jsonl`` back; a corrupt log is a clear error and nothing is overwritten.

Everything a resumed run depends on is its identity (:data:`IDENTITY`): plugin, optimizer,
seed, effects, fixed values, parameter space, embedder and its weights, clip length, the scene
(``--scene-set``, recorded only when given), ζ, the target video, the warm start, and a fingerprint of the target's embedding (which changes
with the embedder's weights even when they are the plugin's shipped ones). A resume that
differs in any of them is refused with a short list of what differs, in the CLI's words
(``--render-set size: run 128, now 64``).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from physinfer.errors import ResumeMismatch, UserInputError
from physinfer.io import atomic_write_json, check_output_dir, to_jsonable
from physinfer.outputs import MANIFEST_FILE, OutputFolder

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
    "posterior_samples.npz",
)

#: ``run.json`` entries a resume must match, with the name a difference is shown under
#: (the CLI's option where there is one).
IDENTITY = {
    "plugin": "--plugin",
    "optimizer": "--optimizer",
    "seed": "--seed",
    "effects": "--effect",
    "fixed": "--fix",
    "parameters": "parameter",
    "embedder": "--embedder",
    "weights_sha256": "--weights",
    "embedder_frames": "--embedder-frames",
    "duration_s": "--duration",
    "scene": "--scene-set",
    "seeds_per_trial": "--seeds-per-trial",
    "render_params": "--render-set",
    "target_sha256": "--target",
    "start_x": "search start (--model / --posterior)",
    "search_box": "search box (--posterior)",
    "embedder_fingerprint": "the embedder's output",
}
RESUME_KEYS = tuple(IDENTITY)
#: Identity entries recorded only since runs have had them: a ``run.json`` without one is
#: an older run, resumed without that check.
RECORDED_LATER = ("weights_sha256", "target_sha256", "start_x", "embedder_fingerprint", "search_box")
#: Entries compared with a tolerance (floats from a network or a sampler, which may differ
#: in their last bits across BLAS builds and thread counts): largest relative difference.
TOLERANCES = {"embedder_fingerprint": 1e-3, "start_x": 1e-6, "search_box": 1e-6}
#: Length of :func:`embedding_fingerprint`.
FINGERPRINT_DIM = 16
#: Differences listed in a refusal; the rest are counted.
SHOWN_DIFFERENCES = 5


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
        if target is not None and Path(target).resolve() in {
            (self.path / name).resolve() for name in RUN_OUTPUTS
        }:
            raise UserInputError(
                f"--target {target} is a file the run writes into --out {self.path}; "
                "move the video elsewhere or choose another --out"
            )
        if self.run_file.exists() and not self.holds_run():
            raise UserInputError(
                f"--out {self.path} holds a {RUN_FILE} that physinfer did not write (no {MANIFEST_FILE} "
                "of a refine run beside it); choose another --out"
            )
        self.output_folder().check(overwrite=overwrite)

    def output_folder(self) -> OutputFolder:
        """The run directory as an output folder of ``refine`` (:mod:`physinfer.outputs`)."""
        return OutputFolder(self.path, "refine", RUN_OUTPUTS, noun="run", resumes=True)

    def holds_run(self) -> bool:
        """Whether the folder holds a physinfer run: its manifest says ``refine`` wrote it and
        ``run.json`` is a JSON object naming its plugin (a ``run.json`` alone is anyone's)."""
        if not self.output_folder().owned():
            return False
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
        if self.run_file.exists() and not self.holds_run():
            raise UserInputError(
                f"--out {self.path} holds a {RUN_FILE} that physinfer did not write; choose another --out"
            )
        self.output_folder().claim(overwrite=overwrite)
        for name in RUN_OUTPUTS:
            (self.path / name).unlink(missing_ok=True)
        atomic_write_json(self.run_file, run_info)
        self.trials_file.touch()

    def load_run_info(self) -> dict[str, Any]:
        """``run.json`` of an existing run."""
        if not self.run_file.exists():
            raise UserInputError(
                f"{self.path} holds no run to resume (no {RUN_FILE}); start without --resume"
            )
        try:
            return json.loads(self.run_file.read_text())
        except json.JSONDecodeError as exc:
            raise UserInputError(
                f"{self.run_file} is corrupt ({exc}); start a new run with another --out"
            ) from None

    def check_compatible(
        self, run_info: dict[str, Any], keys: Sequence[str] = RESUME_KEYS
    ) -> dict[str, Any]:
        """Refuse to resume the stored run with a ``run_info`` whose identity differs.

        Args:
            run_info: What the resuming process would write into ``run.json``.
            keys: The identity entries to compare (:data:`RESUME_KEYS`).

        Returns:
            The stored ``run.json``.

        Raises:
            ResumeMismatch: one line listing what differs (``--seed: run 0, now 1``).
        """
        stored = self.load_run_info()
        differences = resume_differences(stored, run_info, keys)
        if differences:
            shown = "; ".join(differences[:SHOWN_DIFFERENCES])
            more = len(differences) - SHOWN_DIFFERENCES
            shown += f"; and {more} more" if more > 0 else ""
            raise ResumeMismatch(
                f"cannot resume {self.path}, it was run otherwise: {shown}. Resume with the run's "
                "settings, or start a new run (another --out, or --overwrite)",
                shown,
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


# ------------------------------------------------------------------------ run identity


def resume_differences(
    stored: Mapping[str, Any], current: Mapping[str, Any], keys: Sequence[str] = RESUME_KEYS
) -> list[str]:
    """What differs between a stored run's identity and a resuming one's, one phrase each.

    ``current`` is compared as it would be stored (through JSON), so tuples equal lists.
    """
    current = json.loads(json.dumps(to_jsonable(dict(current)), allow_nan=False))
    lines: list[str] = []
    for key in keys:
        if key in RECORDED_LATER and key not in stored:
            continue
        old, new = stored.get(key), current.get(key)
        if _same(key, old, new):
            continue
        if key == "parameters" and {"effects", "fixed", "plugin"} & {
            _key_of(line) for line in lines
        }:
            continue  # another model: the space differs because of what is already listed
        if key == "embedder_fingerprint" and lines:
            continue  # a consequence of what is already listed
        lines.extend(_describe(key, old, new))
    return lines


def _key_of(line: str) -> str:
    """The identity key a phrase of :func:`_describe` is about."""
    for key, label in IDENTITY.items():
        if line.startswith(label):
            return key
    return ""


def _same(key: str, old: Any, new: Any) -> bool:
    if key == "parameters":  # what the search depends on; a reworded description is not
        return _searched(old) == _searched(new)
    if key not in TOLERANCES or old is None or new is None:
        return old == new
    a, b = np.asarray(old, dtype=np.float64), np.asarray(new, dtype=np.float64)
    if a.shape != b.shape:
        return False
    scale = max(float(np.linalg.norm(a)), 1.0 if key in ("start_x", "search_box") else 1e-12)
    return bool(np.linalg.norm(a - b) <= TOLERANCES[key] * scale)


def _describe(key: str, old: Any, new: Any) -> list[str]:
    """``LABEL: run OLD, now NEW`` phrases for one identity entry that differs."""
    label = IDENTITY[key]
    if key in ("fixed", "render_params", "scene"):
        old, new = old or {}, new or {}
        unset = "not fixed" if key == "fixed" else "not set"
        return [
            f"{label} {name}: run {_show(old.get(name), unset)}, now {_show(new.get(name), unset)}"
            for name in sorted(set(old) | set(new))
            if old.get(name) != new.get(name)
        ]
    if key == "parameters":
        return _parameter_differences(old or {}, new or {})
    if key == "target_sha256":
        return [f"{label}: the video differs from the run's target"]
    if key == "embedder_fingerprint":
        return [
            f"{label} on the target differs from the run's (other weights or another version of "
            "the embedder)"
        ]
    if key == "start_x":
        return [f"{label}: run {_show(old, 'the centre')}, now {_show(new, 'the centre')}"]
    default = {
        "effects": "none",
        "weights_sha256": "the plugin's shipped weights",
        "duration_s": "the plugin's default",
        "embedder_frames": "the embedder's default",
    }.get(key, "not set")
    return [f"{label}: run {_show(old, default)}, now {_show(new, default)}"]


def _searched(space: Any) -> list[tuple[Any, ...]]:
    """``(name, bounds, scaling)`` of each parameter of a stored parameter space."""
    if not isinstance(space, list):
        return [("?", space)]
    return [(p.get("name"), p.get("bounds"), p.get("scaling", "linear")) for p in space]


def _parameter_differences(old: Any, new: Any) -> list[str]:
    """Per parameter: searched in one and not the other, or another range or scaling."""
    old_specs = {name: (bounds, scaling) for name, bounds, scaling in _searched(old or [])}
    new_specs = {name: (bounds, scaling) for name, bounds, scaling in _searched(new or [])}
    lines = []
    for name in [*old_specs, *(n for n in new_specs if n not in old_specs)]:
        a, b = old_specs.get(name), new_specs.get(name)
        if a != b:
            lines.append(f"parameter {name}: run {_show_range(a)}, now {_show_range(b)}")
    return lines or ["parameter space: the order of the parameters differs from the run's"]


def _show_range(spec: tuple[Any, str] | None) -> str:
    if spec is None:
        return "not searched"
    bounds, scaling = spec
    lo, hi = bounds if isinstance(bounds, list) and len(bounds) == 2 else ("?", "?")
    return f"{_show(lo, '?')}–{_show(hi, '?')}" + (f" ({scaling})" if scaling != "linear" else "")


def _show(value: Any, missing: str) -> str:
    """A stored value as the user would type it (``128``, ``0.5``, ``a, b``)."""
    if value is None or value == [] or value == {}:
        return missing
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list) and all(isinstance(v, float) for v in value):
        return "(" + ", ".join(f"{v:.3g}" for v in value) + ")"
    if isinstance(value, list):
        return ", ".join(_show(v, "?") for v in value)
    if isinstance(value, str) and value.startswith("sha256:"):
        return value[:19] + "…"
    return str(value)


def optional_settings(
    fixed: Mapping[str, float], duration_s: float | None, embedder_frames: int | None
) -> dict[str, Any]:
    """The ``run.json`` (and ``model.json``) entries of ``--fix``, ``--duration`` and
    ``--embedder-frames``: only those set.

    All are resume keys; leaving an unset one out keeps runs made before the option existed
    resumable.
    """
    settings: dict[str, Any] = {}
    if fixed:
        settings["fixed"] = dict(fixed)
    if duration_s is not None:
        settings["duration_s"] = duration_s
    if embedder_frames is not None:
        settings["embedder_frames"] = embedder_frames
    return settings


def embedding_fingerprint(embedding: np.ndarray) -> list[float]:
    """A short, fixed random projection of an embedding, stored in ``run.json``.

    It identifies the embedder (its weights included, even the plugin's shipped ones) on
    the run's target: another embedder gives an unrelated vector, the same one the same
    vector up to float noise. :data:`FINGERPRINT_DIM` numbers instead of the whole
    embedding keep ``run.json`` readable; relative distances are kept (Johnson–Lindenstrauss).
    """
    vector = np.asarray(embedding, dtype=np.float64).ravel()
    rng = np.random.default_rng(vector.size)  # one projection per embedding size
    projection = rng.standard_normal((FINGERPRINT_DIM, vector.size)) / math.sqrt(
        max(vector.size, 1)
    )
    return [float(v) for v in projection @ vector]


def array_sha256(frames: np.ndarray, *extra: Any) -> str:
    """``"sha256:<hex>"`` of an array's shape, dtype and bytes, and of ``extra`` values."""
    digest = hashlib.sha256(json.dumps([list(frames.shape), str(frames.dtype), *extra]).encode())
    digest.update(np.ascontiguousarray(frames).data)
    return "sha256:" + digest.hexdigest()


def path_sha256(path: str | Path) -> str:
    """``"sha256:<hex>"`` of a file's bytes, or of a directory's files (names and bytes)."""
    path = Path(path)
    digest = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for file in files:
        if path.is_dir():
            digest.update(str(file.relative_to(path)).encode() + b"\0")
        with open(file, "rb") as fh:
            for block in iter(lambda fh=fh: fh.read(1 << 20), b""):
                digest.update(block)
    return "sha256:" + digest.hexdigest()
