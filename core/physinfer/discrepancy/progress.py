"""The time each stage of a diagnosis took, for ``diagnosis.json`` and the printed summary.

(Its progress bars are :class:`physinfer.progress.StageProgress`, one per stage: stages
that run side by side on workers show their bars together.)
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager


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
