"""The models a worker thread builds once and keeps: one cache for every workflow's jobs.

A job sent to a worker process or a Dask worker carries plain data (a spec of the model it
needs) and rebuilds the model on the worker — a phenomenon's simulator and renderer, an
embedder with its weights, an OpenGL context. Building costs seconds, so each worker thread
keeps what it built, keyed by that spec. The cache is per thread because EGL contexts belong
to the thread that made them, and a Dask worker runs tasks on several.

Each workflow keeps its models under its own ``kind`` (refine's trial pipelines, diagnose's
baseline and effect models, the dataset engine's generator), so that keys of one never meet
another's.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

T = TypeVar("T")

_local = threading.local()


def thread_cached(
    kind: str,
    key: Hashable,
    build: Callable[[], T],
    *,
    only_latest: bool = False,
    close: Callable[[Any], None] | None = None,
) -> T:
    """This thread's model of ``kind`` for ``key``, built by ``build()`` on first use.

    ``only_latest``: keep one model of this kind per thread — a new key first drops (and
    ``close``\\ s) the ones built before (the dataset engine's generators hold renderers and
    files, and a worker needs one at a time).
    """
    cache: dict[Hashable, Any] = _local.__dict__.setdefault(kind, {})
    if key not in cache:
        if only_latest:
            for old in cache.values():
                if close is not None:
                    close(old)
            cache.clear()
        cache[key] = build()
    return cache[key]
