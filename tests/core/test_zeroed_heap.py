"""glibc's heap is zero-filled while a video is written (libx264 reads bytes it never wrote)."""

import ctypes
import sys
import threading

import pytest

from physinfer.zeroed_heap import zero_filled_allocations

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")

SIZE = 64 * 1024  # from the heap (not tcache, not an mmap of fresh zero pages)


def _libc():
    libc = ctypes.CDLL("libc.so.6")
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    return libc


def _fresh_block(libc) -> bytes:
    block = libc.malloc(SIZE)
    try:
        return ctypes.string_at(block, SIZE)
    finally:
        libc.free(block)


def test_blocks_handed_out_inside_are_zeros_whatever_the_heap_held():
    libc = _libc()
    libc.mallopt(-6, 0x5A)  # the heap now hands out blocks full of 0xA5: memory nobody wrote
    try:
        assert set(_fresh_block(libc)) == {0xA5}
        with zero_filled_allocations():
            assert set(_fresh_block(libc)) == {0}
    finally:
        libc.mallopt(-6, 0)


def test_it_stays_on_until_the_last_writer_leaves():
    libc = _libc()
    libc.mallopt(-6, 0x5A)
    inside, leave, seen = threading.Event(), threading.Event(), []

    def other_writer():
        with zero_filled_allocations():
            inside.set()
            leave.wait(10)

    try:
        worker = threading.Thread(target=other_writer)
        worker.start()
        inside.wait(10)
        with zero_filled_allocations():
            pass  # this writer leaves first
        seen.append(set(_fresh_block(libc)))
        leave.set()
        worker.join()
        assert seen == [{0}]
        assert set(_fresh_block(libc)) != {0}  # off once both have left (glibc's default: no filling)
    finally:
        libc.mallopt(-6, 0)
