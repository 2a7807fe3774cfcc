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
    def stage(self, name: str, *, add: bool = False) -> Iterator[None]:
        """Time the block as ``name``; a stage a worker already timed keeps its time (the
        block only read it back), unless ``add``: the block's time adds to the name's (a
        later round of the same stage or label)."""
        start = time.perf_counter()
        yield
        elapsed = time.perf_counter() - start
        if add:
            self.seconds[name] = self.seconds.get(name, 0.0) + elapsed
        else:
            self.seconds.setdefault(name, elapsed)

    def add(self, seconds: dict[str, float]) -> None:
        """Times measured elsewhere (on workers), added to what each name has."""
        for name, value in seconds.items():
            self.seconds[name] = self.seconds.get(name, 0.0) + value
