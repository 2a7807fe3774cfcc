"""Heap memory zero-filled while native code runs that reads bytes it never wrote.

libx264 reads heap memory it allocated and never wrote, so the same frames gave another
H.264 stream whenever that memory held other bytes (:func:`physinfer.video.write_video`).
glibc can fill every block malloc hands out with one byte (``mallopt(M_PERTURB)``); with it
on while a video is written, every write of the same frames is the same file.
"""

from __future__ import annotations

import ctypes
import functools
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

#: glibc's mallopt parameter that fills each block malloc hands out with ``value ^ 0xFF``.
_M_PERTURB = -6
_perturbing = threading.Lock()
_writers = 0


@functools.cache
def _glibc() -> Any:
    """glibc's ``mallopt``, or ``None`` elsewhere (macOS, musl's stub does nothing either)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL("libc.so.6")
    except OSError:
        return None
    return libc.mallopt if hasattr(libc, "mallopt") else None


@contextmanager
def zero_filled_allocations() -> Iterator[None]:
    """While inside, glibc fills every block malloc hands out with zeros (and every freed one
    with 0xFF).

    Why: libx264 reads heap memory it allocated and never wrote, so the same frames gave
    another stream whenever that memory held something else — the ball on a string's
    frames, written in fresh processes, gave two streams in one test run (2026-11-27), and
    a diagnosis' self-consistency targets moved its null scale by 6 %. With the blocks
    zeroed every write is the same, at about 6 % more time (three writes of 150 frames
    of 550 × 310: 1.23–1.33 s with, 1.15–1.28 s without). Writers in other threads keep it on
    until the last one leaves.
    """
    global _writers
    mallopt = _glibc()
    if mallopt is None:
        yield
        return
    with _perturbing:
        if _writers == 0:
            mallopt(_M_PERTURB, 0xFF)
        _writers += 1
    try:
        yield
    finally:
        with _perturbing:
            _writers -= 1
            if _writers == 0:
                mallopt(_M_PERTURB, 0)
