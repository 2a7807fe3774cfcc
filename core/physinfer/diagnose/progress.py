"""Progress of a diagnosis: one bar per stage on stderr, and the time each stage took.

Stages that run side by side on workers (:mod:`physinfer.diagnose.parallel`) show their
bars together; the workflow's stages one after another. Without ``enabled`` nothing is
drawn, but :class:`StageClock` still times the stages for ``diagnosis.json``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


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

            from physinfer.console import err_console

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


class StageClock:
    """Wall seconds per stage of this invocation (a stage resumed from disk takes ~0)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the block as ``name``; a stage a worker already timed keeps its time."""
        start = time.perf_counter()
        yield
        self.seconds.setdefault(name, time.perf_counter() - start)

    def add(self, seconds: dict[str, float]) -> None:
        """Times measured elsewhere (on workers)."""
        self.seconds.update(seconds)
