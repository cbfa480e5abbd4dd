"""The one Dask engine of the pipeline: spectral images and gonio sessions compute on it.

:func:`connect` picks the scheduler -- Dask's local one by default (nothing to
install or start), or a ``dask.distributed`` cluster by address or ``Client`` -- and
:func:`compute` runs graphs on it with progress and cancel. Tasks that do linear
algebra run under :func:`one_blas_thread`; the CLI and the GUI limit their whole
process with :func:`limit_blas_threads` (the one BLAS-thread policy).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from typing import Any

from tunespec.core.errors import InputError
from tunespec.core.progress import Cancelled, ProgressFn, StopFn, report

__all__ = [
    "LOCAL_SCHEDULERS",
    "compute",
    "connect",
    "limit_blas_threads",
    "one_blas_thread",
]

#: Dask's local schedulers, by the names ``dask.compute(scheduler=...)`` takes.
LOCAL_SCHEDULERS = ("threads", "processes", "sync", "synchronous")


def limit_blas_threads() -> None:
    """One BLAS thread for this process, unless the user set ``OPENBLAS_NUM_THREADS``.

    The numerics are many small factorisations (a 2 nm calibration's 176 x 176
    systems, 66 x 66 Wiener solves); OpenBLAS's spinning threads make them several
    times slower on a loaded two-core machine (the demo took 2 min 12 s instead of
    17 s; in the GUI the 2 nm calibration took 139 s instead of 4 s with the event
    loop stalled up to 228 ms). Parallel work (spectral images) runs in Dask tasks
    instead. BLAS libraries loaded later (scipy's own OpenBLAS) read the variables;
    those loaded already (numpy's) are limited by threadpoolctl, so call it again
    after importing scipy.
    """
    import os

    from threadpoolctl import threadpool_limits

    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    if os.environ["OPENBLAS_NUM_THREADS"] == "1":
        threadpool_limits(limits=1, user_api="blas")


def one_blas_thread(func: Any, *args: Any, **kwargs: Any) -> Any:
    """``func(*args, **kwargs)`` with BLAS limited to one thread: Dask already runs
    a task per core, and a second BLAS thread per task only contends (measured on
    the 2-core machine: a block's product 32 ms with one thread, 56 ms with two)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        return func(*args, **kwargs)


@contextlib.contextmanager
def connect(scheduler: Any) -> Iterator[Any]:
    """The scheduler to compute on: one of :data:`LOCAL_SCHEDULERS` (``None``:
    ``"threads"``), or a connected ``distributed.Client`` (an address such as
    ``tcp://host:8786`` is connected to, and closed again, here) -- before any work
    is planned, so a wrong address fails at once."""
    if scheduler is None or scheduler in LOCAL_SCHEDULERS:
        yield scheduler or "threads"
        return
    if isinstance(scheduler, str) and "://" not in scheduler:
        raise InputError(
            f"--scheduler {scheduler}: expected one of {', '.join(LOCAL_SCHEDULERS)} "
            "or a dask.distributed address such as tcp://HOST:8786"
        )
    try:
        from distributed import Client
    except ImportError:
        raise InputError(
            f"--scheduler {scheduler}: a Dask cluster needs the distributed package"
        ) from None

    if isinstance(scheduler, Client):
        yield scheduler
        return
    try:
        client = Client(str(scheduler), timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise InputError(
            f"--scheduler {scheduler}: cannot connect to a dask.distributed "
            f"scheduler ({exc})"
        ) from None
    try:
        yield client
    finally:
        client.close()


def compute(
    graphs: Sequence[tuple[Any, list[Any]]],
    scheduler: Any,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> list[Any]:
    """Compute ``(final, parts)`` graphs locally or on a ``dask.distributed`` client;
    returns the finals' results. On a cluster, progress counts the parts (the blocks
    of rows) as they finish."""
    if isinstance(scheduler, str):
        finals = [g for g, _ in graphs]
        return _compute_local(finals, scheduler, progress, should_stop)
    from distributed import as_completed

    client = scheduler
    finals = [g for g, _ in graphs]
    parts = [p for _, ps in graphs for p in ps]
    futures = client.compute([*finals, *parts])
    results: list[Any] = [None] * len(finals)
    try:
        for done, fut in enumerate(as_completed(futures), start=1):
            if should_stop is not None and should_stop():
                raise Cancelled()
            i = futures.index(fut)
            if i < len(finals):
                results[i] = fut.result()
            else:
                fut.result()  # raises the task's error here
            report(progress, done / len(futures))
    except BaseException:
        client.cancel(futures)
        raise
    return results


def _compute_local(
    graphs: Sequence[Any],
    scheduler: str,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> list[Any]:
    import dask
    from dask.callbacks import Callback

    class _Progress(Callback):  # type: ignore[misc]
        def _start_state(self, dsk: Any, state: Any) -> None:
            self.total = max(1, len(dsk))
            self.done = 0

        def _pretask(self, key: Any, dsk: Any, state: Any) -> None:
            if should_stop is not None and should_stop():
                raise Cancelled()

        def _posttask(
            self, key: Any, result: Any, dsk: Any, state: Any, worker_id: Any
        ) -> None:
            self.done += 1
            report(progress, self.done / self.total)

    with _Progress():
        return list(dask.compute(*graphs, scheduler=_local_get(scheduler)))


def _local_get(name: str) -> Any:
    """The get function of a local scheduler (one of :data:`LOCAL_SCHEDULERS`).

    Given the name, ``dask.compute`` imports ``dask.distributed`` to look for a
    client first: 0.2 s before the first task starts, on every local run."""
    if name == "threads":
        from dask.threaded import get
    elif name == "processes":
        from dask.multiprocessing import get
    else:
        from dask.local import get_sync as get
    return get
