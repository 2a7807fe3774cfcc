"""Build and write ``report.html`` for a run directory; tell which kind of run a folder holds.

Every ``refine``, ``diagnose`` and ``infer`` run calls :func:`write_report_quietly` at the
end of writing its outputs: a page that cannot be built costs a warning line, never the
run. ``physinfer report RUN_DIR`` rebuilds the page with :func:`write_report`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from physinfer import __version__
from physinfer.errors import UserInputError
from physinfer.io import atomic_write_text
from physinfer.outputs import MANIFEST_FILE, folder_command
from physinfer.report.common import Content, read_json
from physinfer.report.diagnose_page import diagnose_content
from physinfer.report.infer_page import infer_content
from physinfer.report.markup import page
from physinfer.report.refine_page import refine_content

#: The page's file name inside the run directory.
REPORT_FILE = "report.html"

_BUILDERS = {"refine": refine_content, "diagnose": diagnose_content, "infer": infer_content}
_log = logging.getLogger(__name__)


@dataclass
class Report:
    """A built page.

    Attributes:
        kind: ``"refine"``, ``"diagnose"`` or ``"infer"``.
        run_dir: The run directory it describes.
        html: The whole document.
        path: Where it was written (``None`` until written).
    """

    kind: str
    run_dir: Path
    html: str
    path: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``physinfer report --json`` prints."""
        return {
            "report": str(self.path) if self.path else None,
            "kind": self.kind,
            "run_dir": str(self.run_dir),
            "bytes": len(self.html.encode("utf-8")),
        }


def run_kind(run_dir: str | Path) -> str:
    """Which workflow wrote ``run_dir``: ``"refine"``, ``"diagnose"`` or ``"infer"``.

    Raises:
        UserInputError: ``run_dir`` is not a directory, or holds none of the files that
            mark a run (``diagnosis.json``, ``posterior.json``, a ``run.json`` physinfer wrote).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UserInputError(
            f"{run_dir} is not a directory; give the --out folder of a refine, diagnose or infer run"
        )
    if (run_dir / "diagnosis.json").is_file():
        return "diagnose"
    if (run_dir / "posterior.json").is_file():
        return "infer"
    if (run_dir / "run.json").is_file():
        info = read_json(run_dir / "run.json")
        if isinstance(info, dict) and "plugin" in info:
            return "refine"
    raise UserInputError(
        f"{run_dir} is not a physinfer run (no diagnosis.json, posterior.json or run.json of a refinement); "
        "give the --out folder of a refine, diagnose or infer run"
    )


def build_report(run_dir: str | Path) -> Report:
    """The page of ``run_dir`` (not written).

    Raises:
        UserInputError: not a run directory, or one of its JSON files is damaged.
    """
    run_dir = Path(run_dir)
    kind = run_kind(run_dir)
    content: Content = _BUILDERS[kind](run_dir)
    footer = f"written by physinfer {__version__} from the files in {run_dir.resolve()}"
    return Report(kind, run_dir, page(content.title, content.subtitle, content.body, footer))


def check_owned_run(run_dir: str | Path) -> None:
    """Refuse a folder whose manifest does not say a refine, diagnose or infer wrote it.

    A ``posterior.json`` or ``run.json`` alone does not make a run: the folder may be the
    user's, and its ``report.html`` theirs.

    Raises:
        UserInputError: no manifest (:mod:`physinfer.outputs`), or another command's.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UserInputError(
            f"{run_dir} is not a directory; give the --out folder of a refine, diagnose or infer run"
        )
    command = folder_command(run_dir)
    if command is None:
        raise UserInputError(
            f"{run_dir} is not a physinfer run (it has no {MANIFEST_FILE}, which refine, diagnose and "
            "infer write into their --out); report writes report.html only into such a folder"
        )
    if command not in _BUILDERS:
        raise UserInputError(
            f"{run_dir} holds physinfer's {command} output, not a refine, diagnose or infer run; "
            "report draws pages of those runs only"
        )


def write_report(run_dir: str | Path, *, check_owner: bool = True) -> Report:
    """Build the page of ``run_dir`` and write it atomically to ``run_dir/report.html``.

    Non-ASCII text is written as character references, so the file reads the same under
    any locale's encoding.

    Args:
        run_dir: The run's folder.
        check_owner: Refuse a folder physinfer's manifest does not name as a refine, diagnose
            or infer run (:func:`check_owned_run`); a run writing its own page at its end
            passes ``False``.
    """
    if check_owner:
        check_owned_run(run_dir)
    report = build_report(run_dir)
    report.path = Path(run_dir) / REPORT_FILE
    report.html = report.html.encode("ascii", "xmlcharrefreplace").decode("ascii")
    atomic_write_text(report.path, report.html)
    return report


def write_report_quietly(run_dir: str | Path) -> Path | None:
    """:func:`write_report` for the end of a run: any failure is one warning line, not an error.

    The run has just written its own files into ``run_dir``, which it checked and claimed.

    Returns:
        The page's path, or ``None`` when it could not be written.
    """
    try:
        return write_report(run_dir, check_owner=False).path
    except Exception as exc:  # noqa: BLE001 - the run's results are written; the page is a convenience
        _log.warning("warning: %s not written in %s: %s", REPORT_FILE, run_dir, exc)
        return None
