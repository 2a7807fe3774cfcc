"""``physinfer report RUN_DIR``: rebuild a run's self-contained ``report.html``.

A thin shell over :mod:`physinfer.report`: every ``refine``, ``diagnose`` and ``infer`` run
already writes the page at its end; this command writes it again (after the run's files
changed, or for a run made before the page existed) and can open it in a browser.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from physinfer.cli.app import JsonOpt, emit_json, err_console, handle_errors


@handle_errors()
def report_cmd(
    run_dir: Annotated[
        Path,
        typer.Argument(
            help="The --out folder of a refine, diagnose or infer run.", show_default=False
        ),
    ],
    open_page: Annotated[
        bool, typer.Option("--open", help="Open the page in the default web browser.")
    ] = False,
    as_json: JsonOpt = False,
) -> None:
    """Write RUN_DIR/report.html: parameters, intervals, plots, the video and settings in one file."""
    # Imported here: --help imports every command module, and the report's page builders
    # would add ~15 % to that start-up.
    from physinfer.report import write_report

    report = write_report(run_dir)
    opened = _open(report.path) if open_page else None
    if as_json:
        emit_json({**report.to_dict(), **({"opened": opened} if open_page else {})})
        return
    size = report.to_dict()["bytes"] / 1024
    err_console.print(f"wrote {report.path} ({report.kind} run, {size:.0f} kB)", markup=False, highlight=False)
    if opened is False:
        err_console.print(f"no web browser found; open {report.path} yourself", markup=False, highlight=False)


def _open(path: Path | None) -> bool:
    """Open ``path`` in the default browser; whether one was found (``$BROWSER`` is honoured)."""
    import webbrowser

    return bool(path) and webbrowser.open(Path(path).resolve().as_uri())
