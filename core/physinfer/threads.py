"""Thread limits for the refinement loop.

A refinement calls torch (the embedder, the optimizer's GP) on small pieces of work,
interleaved with the simulator and the renderer. torch's OpenMP threads spin-wait after
each parallel region, so they steal the cores the simulator and the renderer run on next,
and on a machine shared with other jobs a barrier can wait for a descheduled thread. On
the 2-core reference machine under load, one SDN embedding took 3.7 s with torch's default
2 threads and 0.08–0.15 s with 1, and a simulation 3.2 s instead of 0.65 s next to
spinning threads. Work this small gains little from a second thread even on an idle
machine, so the loop runs torch single-threaded unless ``PHYSINFER_TORCH_THREADS`` says
otherwise (GPU work is unaffected).
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

from physinfer.errors import UserInputError

ENV_VAR = "PHYSINFER_TORCH_THREADS"


def refinement_torch_threads() -> int:
    """The torch intra-op thread count for refinements (``PHYSINFER_TORCH_THREADS``, default 1)."""
    value = os.environ.get(ENV_VAR, "1")
    try:
        threads = int(value)
    except ValueError:
        threads = 0
    if threads < 1:
        raise UserInputError(f"{ENV_VAR}={value!r}: give a positive number of threads")
    return threads


@contextmanager
def torch_threads(threads: int) -> Iterator[None]:
    """Run the block with torch limited to ``threads`` intra-op threads, then restore.

    Imports torch if it is installed but not yet imported: the optimizer (Ax's GP) may
    import it inside the block, after the limit would have been set. Does nothing without
    torch.
    """
    torch = sys.modules.get("torch")
    if torch is None:
        try:
            import torch
        except ImportError:
            yield
            return
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


F = TypeVar("F", bound=Callable[..., Any])


def with_refinement_threads(fn: F) -> F:
    """Run ``fn`` under :func:`refinement_torch_threads`: a command's torch work outside the
    loop too (the amortized posterior's sampling, the ζ estimate's embedding, the refined
    posterior's GP). Sampling 5,000 draws of the flag's estimator took 13–17 s with torch's
    2 threads on the loaded 2-core machine and 4 s with 1 (the same draws, bit for bit)."""

    @functools.wraps(fn)
    def limited(*args: Any, **kwargs: Any) -> Any:
        with torch_threads(refinement_torch_threads()):
            return fn(*args, **kwargs)

    return limited  # type: ignore[return-value]
