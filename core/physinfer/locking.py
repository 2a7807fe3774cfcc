"""One writer per output directory: an exclusive ``flock`` on ``DIR/.physinfer.lock``.

``refine``, ``diagnose`` and ``dataset generate`` hold the lock for their whole run, so a
second process writing the same ``--out`` (a resume, an ``--overwrite`` or a new run) is
refused instead of interleaving its files with the first one's. The kernel releases a
``flock`` when its holder dies, so a run killed with ``kill -9`` leaves no stale lock: the
file stays, the lock does not. The holder writes its PID into the file for the message.
``flock`` is local to a machine (not reliable over NFS).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from physinfer.errors import UserInputError

LOCK_FILE = ".physinfer.lock"


class DirectoryLock:
    """An exclusive advisory lock on ``root/.physinfer.lock``.

    Args:
        root: The directory to lock; created if missing.
    """

    def __init__(self, root: str | Path) -> None:
        self.path = Path(root) / LOCK_FILE
        self._fd: int | None = None

    def acquire(self) -> bool:
        """Take the lock and record this process's PID; ``False`` if another process holds it."""
        import fcntl

        self.path.parent.mkdir(parents=True, exist_ok=True)
        # Opened without truncating: the holder's PID must survive a refused attempt.
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            return False
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._fd = fd
        return True

    def release(self) -> None:
        """Release the lock (the file stays: removing it would race with a waiting process)."""
        if self._fd is not None:
            import fcntl

            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def holder(self) -> int | None:
        """The PID recorded by the process holding the lock, ``None`` if unreadable."""
        try:
            return int(self.path.read_text().split()[0])
        except (OSError, ValueError, IndexError):
            return None


@contextmanager
def exclusive_directory(root: str | Path, option: str = "--out") -> Iterator[None]:
    """Hold ``root``'s lock for the duration of the block.

    A directory the lock created is removed again when the block ends with nothing in it.

    Args:
        root: The output directory (created if missing).
        option: The CLI option that named it, for the message.

    Raises:
        UserInputError: ``root`` is a file or cannot be created, or another process holds
            the lock (the message names its PID).
    """
    root = Path(root)
    if root.exists() and not root.is_dir():
        raise UserInputError(f"{option} {root} is a file; give a directory")
    created = not root.exists()
    lock = DirectoryLock(root)
    try:
        acquired = lock.acquire()
    except OSError as exc:  # a read-only place, /proc, a missing permission
        raise UserInputError(f"cannot write {option} {root} ({exc.strerror or exc}); choose another {option}") from None
    if not acquired:
        pid = lock.holder()
        who = f"process {pid}" if pid is not None else "another process"
        raise UserInputError(
            f"{option} {root} is being written by physinfer {who}; wait for it to finish "
            "(or stop it), or choose another " + option
        )
    try:
        yield
    finally:
        if created and [p.name for p in root.iterdir()] == [LOCK_FILE]:
            # Refused before writing anything (a target too short, say): leave no directory.
            # Removed while still held, so no other process can have taken this lock file.
            lock.path.unlink()
            root.rmdir()
        lock.release()
