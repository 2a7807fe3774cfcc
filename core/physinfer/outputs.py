"""Which output folders a command owns: a small manifest, ``DIR/.physinfer.json``.

Every command that writes into an ``--out DIR`` (``refine``, ``diagnose``, ``infer``,
``evaluate calibration``, ``report``, and plugins' commands such as the flag's ``train`` or the
hanging cloth's ``dataset bouman``) claims the folder first with :class:`OutputFolder`: the
manifest names the command and the files and folders it writes there. Only physinfer writes
that file, so it is the one mark of a folder physinfer made. From it follows, for every command
alike:

- a folder holding anything without a manifest (your files) is refused before any work, with
  one line naming what is there;
- a folder another command claimed is refused (an ``infer`` never writes into a refinement's
  run, ``report`` writes only into a refine, diagnose or infer run);
- an earlier run of the same command is replaced only with ``--overwrite`` (or continued, for
  commands that resume), and ``--overwrite`` removes only the names the old manifest lists
  *and* the command writes: a file of yours put beside the outputs stays.

A ``run.json`` or ``posterior.json`` alone does not make a run; the manifest does.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from physinfer import __version__
from physinfer.errors import UserInputError
from physinfer.io import atomic_write_json, check_output_dir
from physinfer.locking import LOCK_FILE

#: The manifest's file name inside an output folder.
MANIFEST_FILE = ".physinfer.json"
#: The manifest's ``format``: what tells physinfer's manifest from any other JSON file.
MANIFEST_FORMAT = "physinfer-outputs/1"
#: Files that are neither the user's nor a command's output (the lock, the manifest).
_BOOKKEEPING = (LOCK_FILE, MANIFEST_FILE)


def read_manifest(folder: str | Path) -> dict[str, Any] | None:
    """The manifest of ``folder``, or ``None`` when there is none physinfer wrote."""
    path = Path(folder) / MANIFEST_FILE
    try:
        info = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(info, dict) or info.get("format") != MANIFEST_FORMAT:
        return None
    if not isinstance(info.get("command"), str) or not isinstance(info.get("outputs"), list):
        return None
    return info


def folder_command(folder: str | Path) -> str | None:
    """The command that claimed ``folder`` (``"refine"``, ``"infer"``, ...), or ``None``."""
    info = read_manifest(folder)
    return None if info is None else info["command"]


def _shown(names: Sequence[str]) -> str:
    return ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")


@dataclass(frozen=True)
class OutputFolder:
    """An ``--out DIR`` that one command writes.

    Args:
        path: The folder.
        command: The command, as the CLI names it (``"infer"``, ``"evaluate calibration"``).
        outputs: Every file or folder name the command writes into ``path``.
        option: The option that named ``path``, for messages.
        resumes: Whether running again on the command's own folder continues it (then an
            earlier run's outputs are no reason to refuse).
        example: A sub-folder name suggested when ``path`` holds the user's files.
        noun: What the folder holds, for messages (default ``"COMMAND results"``).
    """

    path: Path
    command: str
    outputs: tuple[str, ...]
    option: str = "--out"
    resumes: bool = False
    example: str = "run"
    noun: str = ""
    _claimed_new: list[bool] = field(default_factory=list, compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))

    def contents(self) -> list[str]:
        """Names in the folder other than the lock and the manifest (sorted)."""
        if not self.path.is_dir():
            return []
        return sorted(p.name for p in self.path.iterdir() if p.name not in _BOOKKEEPING)

    def owned(self) -> bool:
        """Whether the manifest says this command wrote the folder."""
        return folder_command(self.path) == self.command

    def check(self, *, overwrite: bool = False) -> None:
        """Refuse a folder the command may not write, before any work; nothing is changed.

        Raises:
            UserInputError: the folder is a file or cannot be written, holds files without a
                manifest, belongs to another command, or holds an earlier run's outputs
                (unless ``overwrite``, or the command resumes).
        """
        where = f"{self.option} {self.path}"
        check_output_dir(self.path, self.option)
        others = self.contents()
        if not others:
            return
        claimed = folder_command(self.path)
        if claimed is None:
            noun = self.noun or f"{self.command} results"
            raise UserInputError(
                f"{where} is not empty ({_shown(others)}) and holds no physinfer {noun} (no {MANIFEST_FILE}); "
                f"{self.command} would mix its files with yours: give a new or empty directory, e.g. "
                f"{self.option} {self.path / self.example}"
            )
        if claimed != self.command:
            raise UserInputError(
                f"{where} holds physinfer's {claimed} output, not {self.command}'s; give another {self.option}"
            )
        earlier = [name for name in others if name in self.outputs]
        if earlier and not overwrite and not self.resumes:
            raise UserInputError(
                f"{where} holds an earlier {self.command}'s results ({_shown(earlier)}); give --overwrite to "
                f"replace them, or another {self.option}"
            )

    def claim(self, *, overwrite: bool = False) -> None:
        """Make the folder the command's: create it, remove an earlier run's outputs when
        ``overwrite`` (only names both the old manifest lists and the command writes), and
        write the manifest. Call :meth:`check` first."""
        self._claimed_new[:] = [not self.path.exists()]
        self.path.mkdir(parents=True, exist_ok=True)
        old = read_manifest(self.path)
        if overwrite and old is not None and old["command"] == self.command:
            for name in old["outputs"]:
                if name not in self.outputs or name in _BOOKKEEPING or Path(name).name != name:
                    continue
                target = self.path / name
                if target.is_dir() and not target.is_symlink():
                    shutil.rmtree(target)
                else:
                    target.unlink(missing_ok=True)

        atomic_write_json(
            self.path / MANIFEST_FILE,
            {"format": MANIFEST_FORMAT, "command": self.command, "physinfer": __version__,
             "outputs": list(self.outputs)},
        )  # fmt: skip

    def release_if_unused(self) -> None:
        """Undo :meth:`claim` when the command failed before writing anything: the manifest
        goes, and the folder too when the claim made it."""
        if self.contents():
            return
        (self.path / MANIFEST_FILE).unlink(missing_ok=True)
        if self._claimed_new and self._claimed_new[0]:
            try:
                (self.path / LOCK_FILE).unlink(missing_ok=True)
                self.path.rmdir()
            except OSError:
                pass

    @contextmanager
    def writing(self, *, overwrite: bool = False) -> Iterator[Path]:
        """:meth:`check`, :meth:`claim`, and :meth:`release_if_unused` when the body fails."""
        self.check(overwrite=overwrite)
        self.claim(overwrite=overwrite)
        try:
            yield self.path
        except BaseException:
            self.release_if_unused()
            raise
