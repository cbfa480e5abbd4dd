"""Freed memory reused while frames stream, instead of fresh pages from the kernel.

A 5760 x 3840 raw frame is a 44 MB buffer in LibRaw and 66 MB of float planes;
glibc serves allocations that large with ``mmap`` and returns them with
``munmap``, so every frame's buffers are fresh pages: about 11,000 page faults a
frame, each zeroed by the kernel. Decoding the 45 frames of a session spent half
of its system time on them (0.45 s of 0.9 s per 20 frames, measured). Within
:func:`reused_heap`, large blocks come from the heap and freed ones stay there
(``mallopt``: no ``mmap``, no trimming), so the next frame reuses the previous
one's pages (threads started inside share the main heap); on leaving, the defaults come back and the heap is trimmed
(``malloc_trim``), so a long-running GUI does not keep the memory.

Only with glibc (Linux); elsewhere it does nothing.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import threading
from collections.abc import Iterator

__all__ = ["reused_heap"]

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_M_MMAP_MAX = -4
_M_ARENA_MAX = -8
#: glibc's defaults, restored on leaving (arenas: 8 per core on 64-bit).
_DEFAULTS = (
    (_M_MMAP_MAX, 65536),
    (_M_MMAP_THRESHOLD, 128 * 1024),
    (_M_TRIM_THRESHOLD, 128 * 1024),
    (_M_ARENA_MAX, 8 * (os.cpu_count() or 1)),
)
#: One arena: a thread started inside (the read-ahead, Dask's workers) allocates
#: from the main heap too, whose freed blocks are kept; a thread's own arena is
#: made of mapped heaps that glibc shrinks again (measured: the read-ahead's
#: decoding cost 0.7 s more CPU per 45 frames with an arena of its own).
_REUSE = ((_M_MMAP_MAX, 0), (_M_TRIM_THRESHOLD, 1 << 30), (_M_ARENA_MAX, 1))
_LOCK = threading.Lock()
_DEPTH = 0


def _libc() -> ctypes.CDLL | None:
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt  # noqa: B018 - glibc's, not musl's or macOS's
        libc.malloc_trim  # noqa: B018
    except (OSError, AttributeError):
        return None
    return libc


@contextlib.contextmanager
def reused_heap() -> Iterator[None]:
    """Large freed blocks kept for reuse inside (nestable, any thread)."""
    global _DEPTH
    libc = _libc()
    if libc is None:
        yield
        return
    with _LOCK:
        _DEPTH += 1
        if _DEPTH == 1:
            for option, value in _REUSE:
                libc.mallopt(option, value)
    try:
        yield
    finally:
        with _LOCK:
            _DEPTH -= 1
            if _DEPTH == 0:
                for option, value in _DEFAULTS:
                    libc.mallopt(option, value)
                libc.malloc_trim(0)
