"""Per-thread scratch buffers: large arrays faulted in once and reused.

A fresh array of a block's or a frame's size costs a page fault per page on its first
touch (and the kernel zeroes every page), as much as the arithmetic that fills it;
the per-pixel images' stages keep one buffer per thread and name instead
(:mod:`tunespec.core.image`, :mod:`tunespec.app.pipeline.image_session`).
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["SCRATCH_ALIGN", "release_scratch", "scratch"]

_SCRATCH: dict[tuple[int, str], NDArray[Any]] = {}
_SCRATCH_LOCK = threading.Lock()


#: The alignment :func:`scratch`'s ``phase`` refers to (direct I/O's, a page).
SCRATCH_ALIGN = 4096


def scratch(
    name: str,
    shape: tuple[int, ...],
    dtype: Any = np.float32,
    *,
    phase: int | None = None,
) -> NDArray[Any]:
    """A scratch array of ``shape`` for this thread, reused across calls.

    Large fresh arrays cost a page fault per page on first touch (and the kernel
    zeroes them), as much as the arithmetic that fills them; a block or frame
    buffer kept per thread is faulted once. The contents are undefined and the next
    call with the same ``name`` on this thread overwrites them;
    :func:`release_scratch` drops the buffers when the work is done.

    ``phase``: the array starts ``phase`` bytes past a multiple of
    :data:`SCRATCH_ALIGN` (a multiple of the item size): written to a file offset
    with that remainder, its aligned middle can go to the disk directly, without a
    copy into an aligned buffer
    (:func:`tunespec.core.io.image_formats.pwrite_direct`).
    """
    dt = np.dtype(dtype)
    size = math.prod(shape)
    pad = 0 if phase is None else SCRATCH_ALIGN // dt.itemsize
    key = (threading.get_ident(), f"{name}:{dt.str}")
    with _SCRATCH_LOCK:
        buf = _SCRATCH.get(key)
    if buf is None or buf.size < size + pad:
        buf = np.empty(size + pad, dtype=dt)
        with _SCRATCH_LOCK:
            _SCRATCH[key] = buf
    start = 0
    if phase is not None:
        if phase % dt.itemsize:
            raise ValueError(f"scratch: phase {phase} is not a multiple of the item")
        start = (phase - buf.ctypes.data) % SCRATCH_ALIGN // dt.itemsize
    return buf[start : start + size].reshape(shape)


def release_scratch() -> int:
    """Forget every thread's :func:`scratch` buffers (arrays still in use stay
    valid); returns the bytes released to the allocator."""
    with _SCRATCH_LOCK:
        n = sum(b.nbytes for b in _SCRATCH.values())
        _SCRATCH.clear()
    return n
