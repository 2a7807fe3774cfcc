"""Executors that run a dataset's work units: in this process, in local processes, on Dask.

:func:`open_executor` opens one :class:`concurrent.futures.Executor` for
:func:`~physinfer.datasets.engine.generate_dataset`: ``workers=0`` runs in this process
(:class:`InlineExecutor`), ``workers=K`` in ``K`` spawned local processes, and a Dask
scheduler address through ``distributed.Client.get_executor()``. :class:`ExecutorInfo`
records which ran the units. A local worker process starts with :func:`start_worker`: it dies
with its parent and caps its threads (:func:`limit_threads`, which every job that runs in a
worker calls too).

The refinement's trial workers (:mod:`physinfer.trial_workers`) and the diagnosis' workers run
on these executors as well.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Executor, Future
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing.context import SpawnContext, SpawnProcess
from typing import Any

from physinfer.errors import UserInputError

_THREAD_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS", "LP_NUM_THREADS")
_threads_limited: list[int] = []


#: Seconds between a worker's checks that the process that started it is alive.
PARENT_POLL_S = 0.25


def start_worker(threads: int, parent_pid: int) -> None:
    """Initializer of a local worker process: :func:`die_with_parent`, then :func:`limit_threads`."""
    die_with_parent(parent_pid)
    limit_threads(threads)


def die_with_parent(parent_pid: int) -> None:
    """End this worker process soon after the process that started it dies (``kill -9`` too).

    A process pool's workers would otherwise outlive a killed parent, each waiting for ever
    on a job queue whose writing end it holds itself (or finishing its job first). A daemon
    thread polls the parent's PID: when it is gone (the worker was re-parented) the worker
    exits at once. ``prctl(PR_SET_PDEATHSIG)`` would be quicker but fires when the *thread*
    that started the worker ends, which need not be the parent's main thread.
    """

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(PARENT_POLL_S)
        os._exit(1)

    threading.Thread(target=watch, name="physinfer-parent-watch", daemon=True).start()


def limit_threads(n: int) -> None:
    """Cap the threads of BLAS, OpenMP, torch, numba and llvmpipe in this process (once).

    One thread per worker keeps results independent of how many workers run (parallel
    reductions sum in a thread-dependent order) and keeps ``K`` workers from
    oversubscribing ``K`` cores; Mesa's llvmpipe (``LP_NUM_THREADS``) would otherwise
    start a rasteriser thread per core in every worker. Environment variables cover
    libraries loaded later (the renderer's EGL context is created after this).
    """
    if _threads_limited:
        return
    for name in _THREAD_ENV:
        os.environ[name] = str(n)
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(n)
    except ImportError:  # optional: env variables still cover libraries loaded later
        pass
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(n)
    if "numba" in sys.modules:
        try:
            sys.modules["numba"].set_num_threads(n)
        except ValueError:  # numba was started with fewer threads than n
            pass
    _threads_limited.append(n)


class InlineExecutor(Executor):
    """An executor that runs each call at once in this process (``--workers 0``, debugging)."""

    def submit(self, fn: Any, /, *args: Any, **kwargs: Any) -> Future:
        """Run ``fn(*args, **kwargs)`` now; return a finished future."""
        future: Future = Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except Exception as exc:
            future.set_exception(exc)
        return future


@dataclass(frozen=True)
class ExecutorInfo:
    """What ran the units.

    Attributes:
        kind: ``"inline"``, ``"processes"``, ``"dask"``, ``"none"`` (nothing left to run) or
            the class name of an executor passed in.
        workers: Worker processes (Dask: workers known to the scheduler at start).
        threads: Thread cap per worker for numerical libraries (``None``: untouched).
        address: The Dask scheduler address, if any.
    """

    kind: str
    workers: int
    threads: int | None
    address: str | None = None


def default_workers() -> int:
    """Worker processes used when none are asked for: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


@contextmanager
def open_executor(
    *, workers: int | None = None, scheduler: str | None = None, threads_per_worker: int = 1
) -> Iterator[tuple[Executor, ExecutorInfo]]:
    """An executor for the units, closed on exit.

    Args:
        workers: Local worker processes; 0 runs in this process; ``None`` uses
            :func:`default_workers`. Ignored with ``scheduler``.
        scheduler: Address of a Dask scheduler (``tcp://host:8786``); its workers must
            have physinfer and the plugin installed and see the output directory.
        threads_per_worker: Thread cap per worker process for numerical libraries.

    Raises:
        UserInputError: for a negative worker count or an unreachable scheduler.
    """
    if scheduler:
        yield from _dask_executor(scheduler, threads_per_worker)
        return
    workers = default_workers() if workers is None else workers
    if workers < 0:
        raise UserInputError(f"--workers must be 0 (in this process) or more, got {workers}")
    if workers == 0:
        yield InlineExecutor(), ExecutorInfo("inline", 1, None)
        return
    from concurrent.futures import ProcessPoolExecutor

    # spawn, not fork: EGL contexts and torch's thread pools do not survive a fork. The
    # workers die with this process, even when it is killed (start_worker).
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=worker_context(),
        initializer=start_worker,
        initargs=(threads_per_worker, os.getpid()),
    )
    try:
        yield pool, ExecutorInfo("processes", workers, threads_per_worker)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


_hiding = threading.local()
_stdlib_preparation_data: Any = None


def _preparation_data(name: str) -> dict[str, Any]:
    data = _stdlib_preparation_data(name)
    if getattr(_hiding, "main", False):
        # The worker must not run the user's script again: spawn imports the parent's
        # __main__ by path (or module name) in every child, and a script without an
        # ``if __name__ == "__main__":`` guard would start its refine or diagnose once more
        # in each worker. physinfer's jobs are physinfer functions; they need no __main__.
        data.pop("init_main_from_path", None)
        data.pop("init_main_from_name", None)
    return data


def _launch_without_main(process_obj: Any) -> Any:
    """``SpawnProcess._Popen`` with the parent's ``__main__`` left out of what the child
    prepares (only for this launch: the flag is per thread)."""
    from multiprocessing import popen_spawn_posix, spawn

    global _stdlib_preparation_data
    if spawn.get_preparation_data is not _preparation_data:
        _stdlib_preparation_data = spawn.get_preparation_data
        spawn.get_preparation_data = _preparation_data
    _hiding.main = True
    try:
        return popen_spawn_posix.Popen(process_obj)
    finally:
        _hiding.main = False


class _WorkerProcess(SpawnProcess):
    """A spawned process that does not import the parent's ``__main__``."""

    _start_method = "spawn"

    @staticmethod
    def _Popen(process_obj: Any) -> Any:
        return _launch_without_main(process_obj)


class _WorkerContext(SpawnContext):
    Process = _WorkerProcess


def worker_context() -> SpawnContext:
    """The multiprocessing context of physinfer's local worker processes: spawn (EGL
    contexts and torch's thread pools do not survive a fork), whose children start from a
    fresh interpreter without importing the parent's ``__main__`` (the user's script), so a
    script that calls the library at its top level runs once."""
    return _WorkerContext()


def _dask_executor(address: str, threads_per_worker: int) -> Iterator[tuple[Executor, ExecutorInfo]]:
    try:
        from distributed import Client
    except ImportError:
        raise UserInputError("--scheduler needs Dask: pip install 'dask[distributed]'") from None
    try:
        client = Client(address, timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise UserInputError(
            f"cannot reach the Dask scheduler at {address!r} ({type(exc).__name__}: {exc}); "
            "start one with `dask scheduler` and workers with `dask worker ADDRESS`"
        ) from None
    try:
        n_workers = len(client.scheduler_info().get("workers", {}))
        executor = client.get_executor(pure=False)
        yield executor, ExecutorInfo("dask", n_workers, threads_per_worker, address)
        executor.shutdown(wait=False)
    finally:
        client.close()
