"""What every ``physinfer`` command shares: the plugin registry, JSON output, and the CLI's one
error path (:func:`handle_errors`).

A user mistake ends with one line on stderr (and ``{"error": ...}`` on stdout with ``--json``)
and exit status 2; anything else is a bug and ends with one line naming it and the file its
traceback was saved to (in the system's temporary directory, never in ``--out``), exit status 1.
"""

from __future__ import annotations

import errno
import functools
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import BrokenExecutor
from pathlib import Path
from typing import Any, NoReturn

import typer
from typer.core import TyperGroup
from typer.exceptions import TyperException

try:  # typer 0.20+ carries its own click
    from typer._click.exceptions import ClickException, UsageError
    from typer._click.globals import get_current_context
except ImportError:  # pragma: no cover - a typer on the click package
    from click import get_current_context  # type: ignore[no-redef]
    from click.exceptions import ClickException, UsageError  # type: ignore[no-redef]

from physinfer.console import err_console
from physinfer.errors import PhysinferError, UserInputError
from physinfer.io import to_jsonable
from physinfer.plugins import load_registry
from physinfer.settings import check_seed


@functools.cache
def registry_and_infos() -> tuple[Any, Any]:
    """The registry of all installed plugins, built once per process."""
    return load_registry()


def emit_json(obj: Any) -> None:
    """Print one JSON object on stdout."""
    sys.stdout.write(json.dumps(to_jsonable(obj), allow_nan=False) + "\n")
    sys.stdout.flush()


#: Exceptions typer uses for control flow (exit codes, usage errors): never internal errors.
_TYPER_FLOW = (typer.Exit, typer.Abort, TyperException)
#: Sub-folder of the system's temporary directory that holds saved tracebacks.
TRACEBACK_DIR = "physinfer-errors"


def handle_errors(
    as_json_param: str = "as_json",
    interrupted: str | None = None,
    *,
    kept: str | None = None,
) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Give a command the one error path of the CLI.

    A user error (:class:`UserInputError`, :class:`PhysinferError`) is one clear line and
    exit status 2; any other exception is one line naming it and a saved traceback, exit
    status 1 (:func:`report_internal_error`). With ``--json`` either prints one
    ``{"error": ...}`` object on stdout. A command's ``seed`` (``--seed``) is checked here,
    before the command runs, for every command alike, plugins' included
    (:func:`physinfer.settings.check_seed`).

    A worker process that died (killed, most often for want of memory) is one line too, exit
    status 1: what happened, the memory left, fewer ``--workers``, and ``kept``.

    Args:
        as_json_param: The command's keyword argument that is ``--json``.
        interrupted: What to say on Ctrl-C (exit status 130; ``None``: ``interrupted`` and ``kept``).
        kept: What an interrupted run keeps and how to continue it (``refine``: its trials,
            ``--resume``); ``None``: the command keeps nothing to continue from.
    """
    stopped = interrupted or "; ".join(filter(None, ("interrupted", kept)))

    def decorate(func: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            as_json = bool(kwargs.get(as_json_param)) or _json_given()
            try:
                if "seed" in kwargs:
                    check_seed(kwargs["seed"])
                return func(*args, **kwargs)
            except (UserInputError, PhysinferError) as exc:
                _fail(str(exc), as_json, 2)
            except OSError as exc:
                if exc.errno not in DISK_FULL:
                    report_internal_error(exc, as_json=as_json)
                    raise typer.Exit(1) from None
                _fail(disk_full_message(exc), as_json, 2)
            except KeyboardInterrupt:
                err_console.print(stopped, highlight=False)
                raise typer.Exit(130) from None
            except _TYPER_FLOW:
                raise
            except Exception as exc:
                if isinstance(exc, BrokenExecutor) or type(exc).__name__ == "KilledWorker":  # Dask's word
                    _fail(worker_died_message(exc, kept), as_json, 1)  # killed (memory), not a bug of ours
                report_internal_error(exc, as_json=as_json)  # a bug: one line and a saved traceback
                raise typer.Exit(1) from None

        wrapper._physinfer_errors = True  # type: ignore[attr-defined]
        return wrapper

    return decorate


#: ``errno`` of a write that found no room: a full disk, a file-size limit (``ulimit -f``), a quota.
DISK_FULL = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)


def disk_full_message(exc: OSError) -> str:
    """One line for a write that found no room, naming the file when the error does."""
    what = {errno.ENOSPC: "no space left on the device", errno.EFBIG: "file too large for this system's "
            "limit (ulimit -f)", errno.EDQUOT: "disk quota exceeded"}.get(exc.errno or 0, str(exc))  # fmt: skip
    where = f" writing {exc.filename}" if exc.filename else ""
    return f"{what}{where}; free space (or raise the limit) and run the command again"


def _fail(message: str, as_json: bool, status: int) -> NoReturn:
    """Say ``message`` as the one error line (and as ``{"error": ...}`` with ``--json``); exit."""
    say_error(message)
    if as_json:
        emit_json({"error": message})
    raise typer.Exit(status) from None


def worker_died_message(exc: BaseException, kept: str | None) -> str:
    """One line for a worker process that stopped abruptly: most often the kernel killed it
    for memory, which the parent cannot see; the memory available now is the clue."""
    available = available_memory_gib()
    memory = f"{available:.1f} GiB of memory available now" if available is not None else "memory unknown"
    parts = [
        f"a worker process stopped abruptly ({type(exc).__name__}); the machine may have run out of "
        f"memory ({memory})",
        "give fewer --workers (--workers 0 runs in this process) or free memory",
    ]
    return "; ".join([*parts, kept] if kept else parts)


def available_memory_gib() -> float | None:
    """``MemAvailable`` of ``/proc/meminfo`` in GiB (``None`` where there is none)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 2**20
    except (OSError, ValueError, IndexError):
        return None
    return None


def _json_given() -> bool:
    """Whether the running command was given ``--json``, whatever its parameter is named."""
    ctx = get_current_context(silent=True)
    if ctx is None:
        return False
    return any(
        "--json" in getattr(param, "opts", ()) and bool(ctx.params.get(param.name or ""))
        for param in ctx.command.params
    )


class JsonAwareGroup(TyperGroup):
    """The root command group: under ``--json`` a parse error (a bad value, a missing or
    unknown option) is one ``error:`` line and one ``{"error": ...}`` object, exit status 2,
    instead of typer's usage box. Without ``--json`` the box stays (it shows the usage)."""

    def main(  # type: ignore[override]
        self, args: Any = None, prog_name: str | None = None, complete_var: str | None = None,
        standalone_mode: bool = True, **extra: Any,
    ) -> Any:  # fmt: skip
        argv = list(sys.argv[1:] if args is None else args)
        if not standalone_mode or "--json" not in argv:
            return super().main(argv, prog_name, complete_var, standalone_mode, **extra)
        try:
            code = super().main(argv, prog_name, complete_var, False, **extra)
        except ClickException as exc:
            message = " ".join(exc.format_message().split())
            ctx = getattr(exc, "ctx", None)
            if ctx is not None:
                message += f"; see `{ctx.command_path} --help`"
            say_error(message)
            emit_json({"error": message})
            sys.exit(2 if isinstance(exc, UsageError) else exc.exit_code)
        except typer.Abort:
            say_error("aborted")
            emit_json({"error": "aborted"})
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


def say_error(message: str) -> None:
    """``error: MESSAGE`` on stderr, one line. The message is printed as it is: its square
    brackets (a path such as ``[bold]flag[/bold].mp4``) are text, never rich markup."""
    from rich.markup import escape

    err_console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)


def report_internal_error(exc: BaseException, *, as_json: bool) -> None:
    """Say ``error: internal error (ExcType: msg); traceback saved to PATH`` on one line.

    The traceback goes to ``<temp dir>/physinfer-errors/`` (``$TMPDIR`` or the system's), a
    place every command may write and none of them reads; with ``as_json`` the same message
    and the path are printed as one JSON object on stdout.
    """
    import traceback

    text = " ".join(str(exc).split())
    summary = f"{type(exc).__name__}: {text[:300]}" if text else type(exc).__name__
    path: Path | None = None
    try:
        folder = Path(tempfile.gettempdir()) / TRACEBACK_DIR
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"traceback-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.txt"
        path.write_text("".join(traceback.format_exception(exc)))
        where = f"traceback saved to {path}"
    except OSError as write_error:
        where = f"the traceback could not be saved ({write_error.strerror or write_error})"
    message = f"internal error ({summary}); {where}"
    say_error(message)
    if as_json:
        emit_json({"error": message, "traceback": str(path) if path else None})
