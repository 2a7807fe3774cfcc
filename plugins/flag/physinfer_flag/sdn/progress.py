"""Progress bars on stderr (rich), or silent stand-ins, for long SDN jobs.

stdout stays free for the one JSON object a ``--json`` command prints.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


class SilentProgress:
    """The subset of :class:`rich.progress.Progress` used here, doing nothing."""

    def add_task(self, description: str, total: float | None = None, **fields: Any) -> int:
        """Pretend to add a task."""
        return 0

    def advance(self, task: int, advance: float = 1) -> None:
        """Ignore progress."""

    def update(self, task: int, **kwargs: Any) -> None:
        """Ignore an update."""

    def reset(self, task: int, **kwargs: Any) -> None:
        """Ignore a reset."""


@contextmanager
def progress_bar(enabled: bool) -> Iterator[Any]:
    """A running rich ``Progress`` on stderr, or a :class:`SilentProgress`.

    Args:
        enabled: Show the bar.

    Yields:
        An object with ``add_task``, ``advance``, ``update`` and ``reset``.
    """
    if not enabled:
        yield SilentProgress()
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    columns = (
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        TextColumn("{task.fields[info]}"),
    )
    with Progress(*columns, console=Console(stderr=True)) as bar:
        yield bar
