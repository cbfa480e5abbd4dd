"""Background execution for the GUI: pool workers for numerics, one thread per bench.

Two mechanisms, following STYLE 4.3:

- :class:`Worker` runs a pure function (sensitivity estimation, Wiener estimation,
  session processing, export) on the global :class:`~PySide6.QtCore.QThreadPool`. It
  passes ``progress=`` and ``should_stop=`` to the function, so every long-running
  ``core`` function can report progress and be cancelled.
- :class:`DeviceController` owns the light source and the camera. It lives on its own
  :class:`~PySide6.QtCore.QThread` (devices are blocking and confined to one thread);
  the GUI asks it for things through queued signals and it answers with signals.
  Longer device sequences (a chart capture) are submitted as :class:`DeviceJob` and run
  on the same thread, so the devices are never touched from two threads.

Signals emitted from a worker thread reach GUI objects through queued connections, so
slots always run on the GUI thread. Numerics that run in a process of their own
(:class:`~tunespec.app.gui.processes.ProcessWorker`) are in
:mod:`tunespec.app.gui.processes`.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import tempfile
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from PySide6.QtCore import (
    QCoreApplication,
    QObject,
    QRunnable,
    QThread,
    QThreadPool,
    QTimer,
    Signal,
    Slot,
)

import tunespec.app.gui.qt_compat  # noqa: F401 (before any signal)

__all__ = [
    "BenchInfo",
    "DeviceContext",
    "DeviceController",
    "DeviceJob",
    "ProgressClock",
    "Throttle",
    "Worker",
    "WorkerSignals",
    "collect_on_gui_thread",
    "gc_paused",
    "restore_automatic_collection",
    "running_threads",
]

log = logging.getLogger(__name__)

#: Every QThread this module started and has not yet joined (for the tests' leak check).
_THREADS: weakref.WeakSet[QThread] = weakref.WeakSet()


def running_threads() -> list[QThread]:
    """The device threads started by this module that are still running."""
    return [t for t in list(_THREADS) if t.isRunning()]


class _GuiThreadCollector(QObject):
    """Python's cycle collector, run on the GUI thread only.

    CPython collects cycles in whichever thread happens to allocate when a
    generation's count passes its threshold. A cycle holding a Qt object (a widget,
    a :class:`Throttle` and its timer, a page of a closed window) then has its C++
    object deleted on the device thread, a pool thread or a library's own thread
    (zarr's ``zarr_io``) while the GUI thread uses it: the segmentation faults of
    issue 27, the device thread reading a spectra file (allocating) while the main
    thread crashed in its event loop. (Reproduced: 50 widgets in cycles collected
    by a second thread crash the event loop at once.) So while the GUI is in use
    the automatic collection is off and this object collects on a GUI-thread timer
    instead, with CPython's own thresholds (pyqtgraph's ``GarbageCollector`` does
    the same).
    """

    #: How often the counts are checked (ms).
    PERIOD_MS = 250
    #: Full collections at most this often (s). CPython's own collector skips a
    #: full one until a quarter of the oldest generation is new, which Python
    #: code cannot see; walking the whole heap at every tenth gen-1 collection
    #: stalled the dark frame step (tools/gui_timing.py: 107 ms median, 69 ms
    #: with CPython's collector), while garbage that old grows slowly.
    FULL_PERIOD_S = 60.0

    _instance: ClassVar[_GuiThreadCollector | None] = None

    def __init__(self, app: QCoreApplication) -> None:
        super().__init__(app)
        self._last_full_s = time.monotonic()
        self._timer = QTimer(self)
        self._timer.setInterval(self.PERIOD_MS)
        self._timer.timeout.connect(self._on_timer_timeout)

    @classmethod
    def instance(cls) -> _GuiThreadCollector | None:
        """The collector of the running application (made on its thread), or None
        where there is no application or this is not its thread."""
        app = QCoreApplication.instance()
        if app is None or QThread.currentThread() is not app.thread():
            return None
        me = cls._instance
        try:
            if me is not None and me.parent() is app:
                return me
        except RuntimeError:  # the application it belonged to is gone
            pass
        cls._instance = me = cls(app)
        return me

    @property
    def active(self) -> bool:
        """Whether it collects (and the automatic collection is off)."""
        return self._timer.isActive()

    def start(self) -> None:
        """Collect on the GUI thread only from now on."""
        global _GC_HELD
        _GC_HELD = True
        gc.disable()
        if not self._timer.isActive():
            self._timer.start()

    def stop(self) -> None:
        """Back to CPython's automatic collection."""
        global _GC_HELD
        self._timer.stop()
        _GC_HELD = False
        if not _GC_PAUSES:
            gc.enable()

    def collect(self) -> int:
        """Collect the generations whose counts passed their thresholds (as CPython
        would have); returns the number of unreachable objects found."""
        (n0, n1, n2), (t0, t1, t2) = gc.get_count(), gc.get_threshold()
        if n0 <= t0 or _GC_PAUSES:
            return 0
        generation = 2 if n1 > t1 and n2 > t2 else 1 if n1 > t1 else 0
        if generation == 2:
            now = time.monotonic()
            if now - self._last_full_s < self.FULL_PERIOD_S:
                generation = 1
            else:
                self._last_full_s = now
        return gc.collect(generation)

    @Slot()
    def _on_timer_timeout(self) -> None:
        self.collect()


#: Open :func:`gc_paused` blocks (no collection at all while one is open).
_GC_PAUSES: list[object] = []
#: Whether :class:`_GuiThreadCollector` keeps the automatic collection off.
_GC_HELD = False


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """``with gc_paused(): ...`` runs with the cycle collector off, then leaves it
    as the rest of the program wants it (on, unless the GUI's own collector holds
    it off), whatever thread it ends on."""
    token = object()
    _GC_PAUSES.append(token)
    gc.disable()
    try:
        yield
    finally:
        _GC_PAUSES.remove(token)
        if not _GC_PAUSES and not _GC_HELD:
            gc.enable()


def collect_on_gui_thread() -> _GuiThreadCollector | None:
    """From now on collect cycles on the GUI thread only (call on the GUI thread,
    before starting anything that runs Python on another thread). Returns the
    collector, None without an application."""
    collector = _GuiThreadCollector.instance()
    if collector is not None:
        collector.start()
    return collector


def restore_automatic_collection() -> None:
    """Collect now and go back to CPython's automatic collection (GUI thread, once
    no thread of ours runs: the tests call it after each test)."""
    collector = _GuiThreadCollector.instance()
    if collector is not None and collector.active:
        gc.collect()
        collector.stop()


class WorkerSignals(QObject):
    """Signals of a :class:`Worker` or :class:`DeviceJob`.

    Created on the GUI thread, so connections to GUI slots are queued. The job's
    thread may drop the last Python reference to the job; so that this object is
    never deleted there (while the GUI thread still delivers its signals), the
    application owns it and the GUI thread deletes it after :attr:`finished`.
    """

    started = Signal()
    progressed = Signal(float)
    #: What the job is doing now, in the operator's words ("metering LED495, 7 of 22").
    stage_changed = Signal(str)
    #: Something the operator must know about the result (e.g. a weak LED).
    warned = Signal(str)
    #: The job's own estimate of the seconds it has left (NaN: not known yet).
    remaining_changed = Signal(float)
    returned = Signal(object)
    errored = Signal(object)
    finished = Signal()
    #: Sent after :attr:`finished`: the job will send nothing more.
    _released = Signal()

    def __init__(self) -> None:
        app = QCoreApplication.instance()
        on_gui = app is not None and QThread.currentThread() is app.thread()
        super().__init__(app if on_gui else None)
        if on_gui:
            # queued to the GUI thread behind every signal the job sent before, so
            # their slots have all run (deleting it earlier drops them)
            self._released.connect(self.deleteLater)


class _Job:
    """What :class:`Worker` and :class:`DeviceJob` share: signals, a stop flag and
    the started / returned or errored / finished protocol."""

    def _init_job(self, fn: Callable[..., Any]) -> None:
        self.signals = WorkerSignals()
        self._stop = threading.Event()
        self.name = getattr(fn, "__name__", "job")

    def abort(self) -> None:
        """Ask the function to stop (it raises ``Cancelled`` at its next check)."""
        self._stop.set()

    @property
    def aborted(self) -> bool:
        """Whether :meth:`abort` was called."""
        return self._stop.is_set()

    def _deliver(self, call: Callable[[], Any]) -> None:
        """Run ``call`` and report its outcome through :attr:`signals`."""
        self.signals.started.emit()
        try:
            result = call()
        except Exception as exc:  # passed on to the GUI, which shows it
            log.debug("%s failed", self.name, exc_info=True)
            self.signals.errored.emit(exc)
        else:
            self.signals.returned.emit(result)
        finally:
            self.signals.finished.emit()
            self.signals._released.emit()


class Worker(QRunnable, _Job):
    """Run ``fn(*args, progress=..., should_stop=..., **kwargs)`` on the global pool.

    Parameters
    ----------
    fn
        The function; it must accept ``progress`` and ``should_stop`` keywords
        (``core.progress`` conventions) unless ``hooks=False``.
    *args, **kwargs
        Passed on to ``fn``.
    hooks
        Pass ``progress`` and ``should_stop``; ``False`` for plain functions.
    warns
        Pass ``warn`` too: each line it is given reaches
        :attr:`WorkerSignals.warned`.
    """

    _alive: ClassVar[set[Worker]] = set()

    def __init__(
        self,
        fn: Callable[..., Any],
        /,
        *args: Any,
        hooks: bool = True,
        warns: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__()
        self.setAutoDelete(False)
        self._init_job(fn)
        if hooks:
            kwargs = {
                "progress": self.signals.progressed.emit,
                "should_stop": self._stop.is_set,
                **kwargs,
            }
        if warns:
            kwargs = {"warn": self.signals.warned.emit, **kwargs}
        self._call = partial(fn, *args, **kwargs)

    def start(self) -> Worker:
        """Queue the worker on the global pool; returns ``self`` for chaining."""
        Worker._alive.add(self)
        collect_on_gui_thread()
        self.signals.finished.connect(lambda: Worker._alive.discard(self))
        QThreadPool.globalInstance().start(self)
        return self

    def run(self) -> None:
        """Qt entry point, on a pool thread."""
        self._deliver(self._call)

    @classmethod
    def active_count(cls) -> int:
        """Workers started and not yet finished."""
        return len(cls._alive)


class Throttle(QObject):
    """Call ``fn`` with the latest arguments at most once per ``period_ms``.

    Device signals can arrive faster than a plot can redraw; drawing only the newest
    one at about 20 Hz keeps the event loop free (STYLE 4.3, ScopeFoundry's
    ``display_update_period``). Use it as a slot: ``signal.connect(throttle)``.
    """

    def __init__(
        self, fn: Callable[..., Any], period_ms: int = 50, parent: QObject | None = None
    ) -> None:
        # give it the widget ``fn`` draws on as parent: it then dies with it, and
        # a pending call never reaches a deleted widget
        super().__init__(parent)
        self._fn = fn
        self._args: tuple[Any, ...] | None = None
        self._timer = QTimer(self)
        self._timer.setSingleShot(True)
        self._timer.setInterval(period_ms)
        self._timer.timeout.connect(self._on_timer_timeout)

    def __call__(self, *args: Any) -> None:
        """Remember ``args``; ``fn`` gets the newest when the period is over."""
        self._args = args
        if not self._timer.isActive():
            self._timer.start()

    def flush(self) -> None:
        """Call ``fn`` now with the pending arguments, if any."""
        self._timer.stop()
        self._on_timer_timeout()

    @Slot()
    def _on_timer_timeout(self) -> None:
        args, self._args = self._args, None
        if args is not None:
            self._fn(*args)


class ProgressClock:
    """Turns progress fractions into an estimate of the time remaining.

    The estimate is the elapsed time scaled by the remaining fraction, which is what
    an operator expects from equal-length capture steps.
    """

    def __init__(self) -> None:
        self.restart()

    def restart(self) -> None:
        """Start timing now."""
        self._t0 = time.monotonic()
        self.fraction = 0.0

    @property
    def elapsed_s(self) -> float:
        """Seconds since :meth:`restart`."""
        return time.monotonic() - self._t0

    def update(self, fraction: float) -> float:
        """Record ``fraction`` done; returns the seconds remaining (NaN if unknown)."""
        self.fraction = float(fraction)
        if self.fraction <= 0.0:
            return float("nan")
        return self.elapsed_s * (1.0 - self.fraction) / self.fraction

    @staticmethod
    def format_s(seconds: float) -> str:
        """``"1:05"`` style text, ``"--"`` for unknown."""
        if not np.isfinite(seconds):
            return "--"
        s = round(seconds)
        return (
            f"{s // 60}:{s % 60:02d}" if s < 3600 else f"{s // 3600}h{s // 60 % 60:02d}"
        )


@dataclass
class BenchInfo:
    """What the GUI needs to know about the opened devices.

    Parameters
    ----------
    light_identity, camera_identity
        :class:`~tunespec.devices.protocols.DeviceIdentity` objects.
    channels
        The light source's :class:`~tunespec.devices.protocols.Channel` list.
    exposure_s, iso
        The camera's current settings.
    light_spec, camera_spec
        The spec strings the devices were opened from.
    simulated
        True when both are simulators.
    """

    light_identity: Any
    camera_identity: Any
    channels: list[Any]
    exposure_s: float
    iso: int
    light_spec: str
    camera_spec: str
    simulated: bool = False
    extra: dict[str, Any] = field(default_factory=dict)


class DeviceJob(_Job):
    """A device sequence to run on a :class:`DeviceController`'s thread.

    ``fn(context, *args, progress=..., should_stop=..., **kwargs)`` runs on the device
    thread; ``context`` is a :class:`DeviceContext` (``context.bench`` is the open
    bench). :attr:`signals` are those of a :class:`Worker`. Connect to them, then
    hand the job to :meth:`DeviceController.submit` (the device thread may start it
    at once). :meth:`abort` is safe from any thread.
    """

    def __init__(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> None:
        self._init_job(fn)
        self._fn, self._args, self._kwargs = fn, args, kwargs

    def execute(self, context: DeviceContext) -> None:
        """Run on the device thread (called by the controller)."""

        def call() -> Any:
            if context.bench is None:
                from tunespec.devices.protocols import DeviceConnectionError

                raise DeviceConnectionError("no devices connected: connect them first")
            return self._fn(
                context,
                *self._args,
                progress=self.signals.progressed.emit,
                should_stop=self._stop.is_set,
                **self._kwargs,
            )

        self._deliver(call)


class DeviceContext:
    """What a :class:`DeviceJob` may use on the device thread.

    Parameters
    ----------
    controller
        The controller running the job.
    """

    #: Live frames during a sequence are shown at most this often (s).
    FRAME_PERIOD_S = 0.5

    def __init__(
        self, controller: DeviceController, job: DeviceJob | None = None
    ) -> None:
        self._controller = controller
        self._job = job
        self._last_frame_s = self._last_spd_s = -1e9

    def set_stage(self, text: str) -> None:
        """Say what the job does now (progress text and the log)."""
        log.info("%s", text)
        if self._job is not None:
            self._job.signals.stage_changed.emit(text)

    def set_remaining(self, seconds: float) -> None:
        """Say how many seconds the job has left (the page shows it)."""
        if self._job is not None:
            self._job.signals.remaining_changed.emit(float(seconds))

    def warn(self, text: str) -> None:
        """Pass a warning on to the GUI at once (the page logs and shows it)."""
        if self._job is not None:
            self._job.signals.warned.emit(text)
        else:
            log.warning("%s", text)

    @property
    def bench(self) -> Any:
        """The open bench (``.light``, ``.camera``, ``.stage``, ``.truth``)."""
        return self._controller._bench

    @property
    def options(self) -> dict[str, Any]:
        """The options the bench was opened with."""
        return dict(self._controller._open_args[2])

    def replace_bench(self, bench: Any) -> Any:
        """Make ``bench`` the controller's bench (e.g. a simulated camera looking at
        another target); the old camera is closed unless the new bench shares it."""
        old = self._controller._bench
        self._controller._bench = bench
        if old is not None and old.camera is not bench.camera:
            try:
                old.camera.close()
            except Exception as exc:
                log.warning("closing the replaced camera failed: %s", exc)
        return bench

    def prompt(self, message: str) -> None:
        """Ask the operator and wait for the confirmation."""
        self._controller._prompt(message)

    def show_frame(self, path: Any, *, force: bool = False) -> None:
        """Show a raw file as the live view (throttled to :attr:`FRAME_PERIOD_S`)."""
        now = time.monotonic()
        if not force and now - self._last_frame_s < self.FRAME_PERIOD_S:
            return
        self._last_frame_s = now
        from tunespec.app.gui.plots.frame_plot import build_preview
        from tunespec.core.io.raw import load_raw

        try:
            preview = build_preview(load_raw(path))
        except Exception as exc:
            log.warning("cannot show %s: %s", path, exc)
            return
        self._controller.frame_acquired.emit(preview)

    def show_spd(self, read_spd: Callable[[], Any], levels: Any) -> None:
        """Show an SPD the light source reported (with the levels it was set to).

        ``read_spd()`` gives it; it is called only when the last one shown is
        :attr:`FRAME_PERIOD_S` old (reading and drawing one per frame would keep
        the device thread busy in Python, and the GUI waiting for the GIL).
        """
        now = time.monotonic()
        if now - self._last_spd_s < self.FRAME_PERIOD_S:
            return
        self._last_spd_s = now
        self._controller.spd_measured.emit(read_spd(), levels)


class DeviceController(QObject):
    """Owns the bench (light source + camera + stage) on a dedicated thread.

    Every public method may be called from the GUI thread; it only emits a private
    request signal, which Qt queues to the device thread. Results come back as signals.

    Parameters
    ----------
    opener
        ``opener(light_spec, camera_spec, **options) -> bench``; the bench has
        ``.light``, ``.camera`` and optionally ``.stage`` and ``.close()``. Defaults to
        :func:`default_opener`, which uses ``tunespec.devices.registry``.
    """

    #: Devices are open: a :class:`BenchInfo`.
    devices_opened = Signal(object)
    #: Devices were closed.
    devices_closed = Signal()
    #: Channel levels now set, (n_channels,) in [0, 1].
    levels_changed = Signal(object)
    #: A preview frame: a :class:`~tunespec.app.gui.plots.frame_plot.FramePreview`.
    frame_acquired = Signal(object)
    #: The light source's reported SPD (``Spectra``) and the levels it was taken at.
    spd_measured = Signal(object, object)
    #: A ``LightStatus``.
    status_changed = Signal(object)
    #: Camera settings now in effect: exposure in s, ISO.
    camera_changed = Signal(float, int)
    #: A device call failed: the exception.
    errored = Signal(object)
    #: A job started (True) or ended (False).
    busy_changed = Signal(bool)
    #: The operator must change what the camera sees (hardware stage): the message.
    #: Answer with :meth:`confirm_prompt`; the device thread waits until then.
    prompt_requested = Signal(str)

    _open_requested = Signal(str, str, object)
    _close_requested = Signal()
    _shutdown_requested = Signal()
    _levels_requested = Signal(object)
    _all_off_requested = Signal()
    _camera_requested = Signal(object, object)
    _snap_requested = Signal()
    _spd_requested = Signal()
    _status_requested = Signal()
    _job_submitted = Signal(object)

    def __init__(self, opener: Callable[..., Any] | None = None) -> None:
        super().__init__()
        self._opener = opener or default_opener
        self._bench: Any = None
        self._open_args: tuple[str, str, dict[str, Any]] = ("", "", {})
        self._current_job: DeviceJob | None = None
        self._prompt_event = threading.Event()
        self._preview_dir = tempfile.TemporaryDirectory(prefix="tunespec-preview-")
        self._thread = QThread()
        self._thread.setObjectName("tunespec-devices")
        self.moveToThread(self._thread)
        self._open_requested.connect(self._on_open_requested)
        self._close_requested.connect(self._on_close_requested)
        self._shutdown_requested.connect(self._on_shutdown_requested)
        self._levels_requested.connect(self._on_levels_requested)
        self._all_off_requested.connect(self._on_all_off_requested)
        self._camera_requested.connect(self._on_camera_requested)
        self._snap_requested.connect(self._on_snap_requested)
        self._spd_requested.connect(self._on_spd_requested)
        self._status_requested.connect(self._on_status_requested)
        self._job_submitted.connect(self._on_job_submitted)
        _THREADS.add(self._thread)
        # the device thread runs Python from now on: cycles are collected on the
        # GUI thread only (see _GuiThreadCollector)
        collect_on_gui_thread()
        self._thread.start()
        self.is_open = False  # GUI-side view, updated from the signals
        self.devices_opened.connect(self._on_self_devices_opened)
        self.devices_closed.connect(self._on_self_devices_closed)

    # -- GUI-thread API -------------------------------------------------------------
    def open_devices(self, light_spec: str, camera_spec: str, **options: Any) -> None:
        """Open (replacing any open) devices from their specs."""
        self._open_requested.emit(light_spec, camera_spec, options)

    def close_devices(self) -> None:
        """Switch the light off and close both devices."""
        self._close_requested.emit()

    def set_levels(self, levels: Any) -> None:
        """Set every channel level, (n_channels,) in [0, 1]."""
        self._levels_requested.emit(np.asarray(levels, dtype=np.float64).copy())

    def all_off(self) -> None:
        """Switch every channel off (also aborts the running job)."""
        if self._current_job is not None:
            self._current_job.abort()
        self._all_off_requested.emit()

    def set_camera(
        self, exposure_s: float | None = None, iso: int | None = None
    ) -> None:
        """Change exposure and/or ISO."""
        self._camera_requested.emit(exposure_s, iso)

    def snap_preview(self) -> None:
        """Take one frame and emit it as :attr:`frame_acquired`."""
        self._snap_requested.emit()

    def measure_spd(self) -> None:
        """Ask the light source for its SPD; answered by :attr:`spd_measured`."""
        self._spd_requested.emit()

    def refresh_status(self) -> None:
        """Ask for the light source status; answered by :attr:`status_changed`."""
        self._status_requested.emit()

    def submit(self, job: DeviceJob) -> DeviceJob:
        """Queue ``job`` on the device thread (connect to its signals first)."""
        self._job_submitted.emit(job)
        return job

    def confirm_prompt(self) -> None:
        """The operator did what :attr:`prompt_requested` asked (any thread)."""
        self._prompt_event.set()

    def shutdown(self, timeout_ms: int = 10_000) -> None:
        """Abort any job, close the devices and stop the thread (blocks)."""
        if self._current_job is not None:
            self._current_job.abort()
        self._prompt_event.set()
        if self._thread.isRunning():
            # closed and stopped by the device thread itself, after what is queued
            self._shutdown_requested.emit()
            if not self._thread.wait(timeout_ms):
                log.error("device thread did not stop within %d ms", timeout_ms)
        self._preview_dir.cleanup()

    @property
    def thread_running(self) -> bool:
        """Whether the device thread is alive."""
        return self._thread.isRunning()

    @Slot(object)
    def _on_self_devices_opened(self, info: BenchInfo) -> None:
        self.is_open = True

    @Slot()
    def _on_self_devices_closed(self) -> None:
        self.is_open = False

    # -- device thread --------------------------------------------------------------
    def _guard(self, what: str, fn: Callable[[], Any]) -> Any:
        try:
            return fn()
        except Exception as exc:
            log.error("%s failed: %s", what, exc)
            self.errored.emit(exc)
            return None

    @Slot(str, str, object)
    def _on_open_requested(
        self, light_spec: str, camera_spec: str, options: Any
    ) -> None:
        self._on_close_requested()
        bench = self._guard(
            "opening the devices",
            lambda: self._opener(
                light_spec, camera_spec, prompt=self._prompt, **(options or {})
            ),
        )
        if bench is None:
            return
        self._bench = bench
        self._open_args = (light_spec, camera_spec, dict(options or {}))

        def info() -> BenchInfo:
            light, camera = bench.light, bench.camera
            return BenchInfo(
                light_identity=light.identity,
                camera_identity=camera.identity,
                channels=list(light.channels()),
                exposure_s=float(camera.exposure_s),
                iso=int(camera.iso),
                light_spec=light_spec,
                camera_spec=camera_spec,
                simulated=bool(getattr(bench, "simulated", False)),
                extra={"truth": getattr(bench, "truth", {}) or {}},
            )

        result = self._guard("reading the device identities", info)
        if result is None:
            self._on_close_requested()
            return
        log.info(
            "connected: %s %s and %s %s",
            result.light_identity.vendor,
            result.light_identity.model,
            result.camera_identity.vendor,
            result.camera_identity.model,
        )
        self.devices_opened.emit(result)
        self._emit_levels()
        self._on_status_requested()

    @Slot()
    def _on_shutdown_requested(self) -> None:
        self._on_close_requested()
        self._thread.quit()

    @Slot()
    def _on_close_requested(self) -> None:
        bench, self._bench = self._bench, None
        if bench is None:
            return
        close = getattr(bench, "close", None)
        if close is None:

            def close() -> None:
                bench.light.close()
                bench.camera.close()

        self._guard("closing the devices", close)
        log.info("devices closed")
        self.devices_closed.emit()

    def _emit_levels(self) -> None:
        if self._bench is not None:
            levels = self._guard("reading the levels", self._bench.light.levels)
            if levels is not None:
                self.levels_changed.emit(np.asarray(levels, dtype=np.float64).copy())

    @Slot(object)
    def _on_levels_requested(self, levels: Any) -> None:
        if self._require():
            self._guard(
                "setting the levels", lambda: self._bench.light.set_levels(levels)
            )
            self._emit_levels()

    @Slot()
    def _on_all_off_requested(self) -> None:
        if self._bench is not None:
            self._guard("switching all channels off", self._bench.light.all_off)
            self._emit_levels()

    @Slot(object, object)
    def _on_camera_requested(self, exposure_s: Any, iso: Any) -> None:
        if not self._require():
            return
        camera = self._bench.camera
        if exposure_s is not None:
            self._guard("setting the exposure", lambda: camera.set_exposure(exposure_s))
        if iso is not None:
            self._guard("setting the ISO", lambda: camera.set_iso(int(iso)))
        self.camera_changed.emit(float(camera.exposure_s), int(camera.iso))

    @Slot()
    def _on_snap_requested(self) -> None:
        if not self._require():
            return

        def snap() -> Any:
            from tunespec.app.gui.plots.frame_plot import build_preview
            from tunespec.core.io.raw import load_raw

            stem = Path(self._preview_dir.name) / "preview"
            path = self._bench.camera.capture(stem)
            try:
                # built here so the GUI thread only uploads a small image
                return build_preview(load_raw(path))
            finally:
                Path(path).unlink(missing_ok=True)

        frame = self._guard("taking a preview frame", snap)
        if frame is not None:
            self.frame_acquired.emit(frame)

    @Slot()
    def _on_spd_requested(self) -> None:
        if not self._require():
            return
        light = self._bench.light
        spd = self._guard("measuring the SPD", light.measure_spd)
        if spd is not None:
            levels = self._guard("reading the levels", light.levels)
            self.spd_measured.emit(spd, levels)

    @Slot()
    def _on_status_requested(self) -> None:
        if self._bench is not None:
            status = self._guard("reading the status", self._bench.light.status)
            if status is not None:
                self.status_changed.emit(status)

    @Slot(object)
    def _on_job_submitted(self, job: DeviceJob) -> None:
        self._current_job = job
        self.busy_changed.emit(True)
        try:
            job.execute(DeviceContext(self, job))
        finally:
            self._current_job = None
            self.busy_changed.emit(False)
            self._emit_levels()

    def _prompt(self, message: str) -> None:
        """Ask the operator (on the GUI) and wait for the answer; device thread."""
        from tunespec.core.progress import Cancelled

        self._prompt_event.clear()
        log.info("operator: %s", message)
        self.prompt_requested.emit(message)
        while not self._prompt_event.wait(0.05):
            job = self._current_job
            if job is not None and job.aborted:
                raise Cancelled("cancelled by the operator")
        if not self._thread.isRunning() or (
            self._current_job is not None and self._current_job.aborted
        ):
            raise Cancelled("cancelled by the operator")

    def _require(self) -> bool:
        if self._bench is None:
            from tunespec.devices.protocols import DeviceConnectionError

            self.errored.emit(DeviceConnectionError("no devices connected"))
            return False
        return True


def default_opener(light_spec: str, camera_spec: str, **options: Any) -> Any:
    """Open a bench through :func:`tunespec.devices.registry.open_bench`.

    ``"sim"`` for both opens the simulated bench (one scene and clock shared by the
    simulated light and camera); ``options`` are ``open_bench``'s keywords
    (``layout``, ``resolution``, ``seed``, ``realtime``, ``prompt``...).
    """
    from tunespec.devices.registry import open_bench

    return open_bench(light_spec, camera_spec or None, **options)
