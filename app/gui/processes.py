"""The GUI's numerics in processes of their own: :class:`ProcessWorker`.

A :class:`~tunespec.app.gui.workers.Worker` whose function runs in a separate process
(a fork server that imported the pipeline once, on POSIX), at a lower priority and with
one BLAS thread, so the numerics share neither the GIL nor the cores' first claim with
the GUI's event loop. Split from :mod:`tunespec.app.gui.workers` (the threads: pool
workers, the device thread); this module is the processes.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import pickle
import queue
import time
from collections.abc import Callable
from typing import Any

from tunespec.app.gui.workers import Worker
from tunespec.app.pipeline.engine import limit_blas_threads

__all__ = [
    "BACKGROUND_NICE",
    "PROCESS_PRELOAD",
    "ProcessWorker",
    "lower_priority",
    "process_context",
    "start_process_server",
]

log = logging.getLogger(__name__)

#: Modules a :class:`ProcessWorker`'s process server imports once, before it forks
#: the first job (the numerics, the export and the report; imported in every job
#: otherwise, 1.5 s each).
PROCESS_PRELOAD = (
    "tunespec.app.gui.wizard.measurement",
    "tunespec.app.pipeline.steps",
    "tunespec.app.report.report",
    "colour",
)


#: The niceness of the numerics' processes: on a busy machine the scheduler gives the
#: GUI's process (event loop and devices) the cores first (``tools/gui_timing.py``:
#: with the load of other programs, the fork server's imports and a calibration at
#: normal priority stalled the event loop up to 130 ms).
BACKGROUND_NICE = 10


def lower_priority(pid: int = 0) -> None:
    """Make process ``pid`` (0: this one) at least :data:`BACKGROUND_NICE` nice; a
    no-op where priorities cannot be set (Windows)."""
    try:
        now = os.getpriority(os.PRIO_PROCESS, pid)
        os.setpriority(os.PRIO_PROCESS, pid, max(now, BACKGROUND_NICE))
    except (AttributeError, OSError) as exc:
        log.debug("priority of %s not lowered: %s", pid or "this process", exc)


def process_context() -> Any:
    """The multiprocessing context of :class:`ProcessWorker`: a fork server that
    imported :data:`PROCESS_PRELOAD` (POSIX), else fresh interpreters (Windows)."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(list(PROCESS_PRELOAD))
        return ctx
    return multiprocessing.get_context("spawn")  # pragma: no cover (Windows)


def start_process_server() -> None:
    """Start the fork server now (it imports in its own process), so the first
    :class:`ProcessWorker` need not wait for it; a no-op without one."""
    ctx = process_context()
    if ctx.get_start_method() == "forkserver":
        from multiprocessing import forkserver

        forkserver.ensure_running()
        # its imports, and the jobs it forks, yield the cores to the GUI's process
        pid = getattr(getattr(forkserver, "_forkserver", None), "_forkserver_pid", None)
        if pid:
            lower_priority(pid)


def _process_main(
    fn: Callable[..., Any],
    args: tuple[Any, ...],
    kwargs: dict[str, Any],
    messages: Any,
    stop: Any,
    log_level: int,
) -> None:
    """A :class:`ProcessWorker`'s process: run ``fn``, send what happens to
    ``messages`` (``("progress", f)``, ``("log", record)``, then ``("returned",
    value)`` or ``("errored", exc)``)."""
    import logging.handlers

    class Relay(logging.handlers.QueueHandler):
        def enqueue(self, record: logging.LogRecord) -> None:
            messages.put(("log", record))

    root = logging.getLogger()
    root.handlers[:] = [Relay(messages)]
    root.setLevel(log_level)
    lower_priority()
    limit_blas_threads()
    try:
        result = fn(
            *args,
            progress=lambda f: messages.put(("progress", float(f))),
            should_stop=stop.is_set,
            **kwargs,
        )
    except BaseException as exc:  # passed on to the GUI, which shows it
        try:
            pickle.loads(pickle.dumps(exc))
        except Exception:  # e.g. an exception whose arguments do not pickle
            exc = RuntimeError(f"{type(exc).__name__}: {exc}")
        messages.put(("errored", exc))
    else:
        messages.put(("returned", result))


class ProcessWorker(Worker):
    """A :class:`Worker` whose function runs in a separate process.

    Numerics and the report (matplotlib) are Python bytecode most of the time; on a
    pool thread they hold the GIL, and the GUI thread waits for it at every return
    from Qt into Python (up to 5 ms each, ``sys.getswitchinterval``): the export
    stalled the event loop 65-190 ms (``tools/gui_timing.py``). In a process of its
    own the function shares no GIL with the GUI. ``fn``, its arguments and its
    result must pickle; its progress, log records (shown in the log panel) and
    outcome come back through a queue read on a pool thread, which emits
    :attr:`signals` as a :class:`Worker` does. :meth:`abort` makes ``should_stop()``
    true in the process; one that has not stopped :attr:`KILL_AFTER_S` later is
    terminated.
    """

    #: Seconds an aborted process gets to stop by itself.
    KILL_AFTER_S = 10.0

    def __init__(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> None:
        super().__init__(fn, *args, hooks=False, **kwargs)
        self._fn, self._args, self._kwargs = fn, args, kwargs

    def run(self) -> None:
        """Qt entry point, on a pool thread: start the process and relay it."""
        self._deliver(self._relay)

    def _relay(self) -> Any:
        ctx = process_context()
        messages, stop = ctx.Queue(), ctx.Event()
        level = logging.getLogger().getEffectiveLevel()
        process = ctx.Process(
            target=_process_main,
            args=(self._fn, self._args, self._kwargs, messages, stop, level),
            name=f"tunespec-{self.name}",
            daemon=True,
        )
        process.start()
        stopped_at: float | None = None
        try:
            while True:
                if self._stop.is_set() and stopped_at is None:
                    stop.set()
                    stopped_at = time.monotonic()
                try:
                    kind, value = messages.get(timeout=0.1)
                except queue.Empty:
                    if stopped_at is not None and (
                        time.monotonic() - stopped_at > self.KILL_AFTER_S
                    ):
                        process.terminate()
                        from tunespec.core.progress import Cancelled

                        raise Cancelled(f"{self.name} terminated") from None
                    if not process.is_alive() and messages.empty():
                        raise RuntimeError(
                            f"{self.name}: its process ended (exit code "
                            f"{process.exitcode}) without a result"
                        ) from None
                    continue
                if kind == "progress":
                    self.signals.progressed.emit(value)
                elif kind == "log":
                    logger = logging.getLogger(value.name)
                    if logger.isEnabledFor(value.levelno):
                        logger.handle(value)
                elif kind == "errored":
                    raise value
                else:
                    return value
        finally:
            process.join(self.KILL_AFTER_S)
            if process.is_alive():  # pragma: no cover (a process ignoring stop)
                process.kill()
                process.join()
            messages.close()
