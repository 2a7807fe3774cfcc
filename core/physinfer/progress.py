"""Rich progress bars, one per stage of a long job, on stderr (stdout stays for ``--json``).

Used by the diagnosis (stages side by side on workers show their bars together), by
``posterior train`` (embedding, training) and ``evaluate calibration`` (embedding, sampling),
and by :mod:`physinfer.api` when a caller asks for ``progress=True``.
"""

from __future__ import annotations

import threading
from typing import Any

from physinfer.console import err_console


class StageProgress:
    """Rich progress bars, one per stage, added as stages report their first trial count."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self._bar: Any = None
        self._tasks: dict[str, Any] = {}
        self._lock = threading.Lock()

    def __enter__(self) -> StageProgress:
        if self.enabled:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
            )

            self._bar = Progress(
                TextColumn("{task.description:<28}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                console=err_console, transient=False,
            )  # fmt: skip
            self._bar.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)
            self._bar = None

    def update(self, stage: str, done: int, total: int) -> None:
        """Show ``done`` of ``total`` trials for ``stage`` (thread-safe)."""
        if self._bar is None:
            return
        with self._lock:
            if stage not in self._tasks:
                self._tasks[stage] = self._bar.add_task(stage, total=total)
            self._bar.update(self._tasks[stage], completed=done, total=total)
