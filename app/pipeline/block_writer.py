"""Writing blocks of image rows on a thread of their own, while the next compute.

The per-pixel images are computed block of rows by block of rows
(:func:`tunespec.app.pipeline.image_session.estimate_block`); writing a block's
rows (the cube twice, the TIFFs) is as much work as computing them, most of it the
kernel's copying into the page cache. A :class:`BlockWriter` takes the writes off
the computing threads: a block hands its write to the writer's bounded queue and
goes on with the next block, so decode, compute and write overlap. The queue holds
at most ``depth`` blocks, and the blocks' cubes live in a pool of ``n_buffers``
reused buffers (a fresh 64 MB array per block costs a page fault per 4 kB, as much
as the arithmetic that fills it), so memory stays bounded whatever the image size.

A writer lives in one process: the pipeline uses it with Dask's local schedulers,
and writes on the computing thread on a ``dask.distributed`` cluster.
"""

from __future__ import annotations

import queue
import threading
import uuid
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["BlockWriter"]


class BlockWriter:
    """A thread that runs block writes in order, with a bounded queue.

    Parameters
    ----------
    depth
        Writes waiting in the queue at most (a block that finds it full waits).
    n_buffers
        Cube buffers in the pool (:meth:`buffer`): the computing threads' and the
        ones waiting or being written.

    Examples
    --------
    >>> got = []
    >>> with BlockWriter() as w:
    ...     buf = w.buffer((2, 3))
    ...     buf[:] = 1.0
    ...     w.put(lambda: got.append(float(buf.sum())), buf)
    >>> got
    [6.0]
    """

    def __init__(self, depth: int = 2, n_buffers: int = 4) -> None:
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=max(1, depth))
        self._free: queue.Queue[NDArray[np.float32]] = queue.Queue()
        self._lock = threading.Lock()
        self._n_buffers = max(1, n_buffers)
        self._made = 0
        self._error: BaseException | None = None
        self._token = uuid.uuid4().hex
        self._thread = threading.Thread(
            target=self._run, name="tunespec-block-writer", daemon=True
        )
        self._thread.start()

    def __dask_tokenize__(self) -> str:
        return self._token

    def __enter__(self) -> BlockWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close(raise_error=exc[0] is None)

    def buffer(self, shape: tuple[int, ...]) -> NDArray[np.float32]:
        """A float32 buffer of ``shape`` from the pool, waiting for one to be
        written if all are in use; :meth:`put` returns it to the pool."""
        size = int(np.prod(shape))
        with self._lock:
            make = self._free.empty() and self._made < self._n_buffers
            if make:
                self._made += 1
        buf = np.empty(size, dtype=np.float32) if make else self._free.get()
        if buf.size < size:
            buf = np.empty(size, dtype=np.float32)
        return buf[:size].reshape(shape)

    def put(
        self, write: Callable[[], None], buffer: NDArray[Any] | None = None
    ) -> None:
        """Queue ``write`` (waits while the queue is full); ``buffer`` (from
        :meth:`buffer`) goes back to the pool once it ran. Raises the error of an
        earlier write."""
        self._raise()
        self._queue.put((write, buffer))

    def flush(self) -> None:
        """Wait until every queued write ran; raises the first write's error."""
        self._queue.join()
        self._raise()

    def close(self, *, raise_error: bool = True) -> None:
        """Run what is queued, stop the thread, drop the pool."""
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        while not self._free.empty():
            self._free.get()
        if raise_error:
            self._raise()

    def _raise(self) -> None:
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            try:
                if item is None:
                    return
                write, _ = item
                if self._error is None:
                    write()
            except BaseException as exc:  # raised to the computing threads
                self._error = exc
            finally:
                if item is not None and item[1] is not None:
                    base = item[1]
                    while base.base is not None:
                        base = base.base
                    self._free.put(base)
                self._queue.task_done()
