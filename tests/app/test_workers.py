"""Worker and DeviceController: threads, queued signals, abort, errors."""

from __future__ import annotations

import threading
from types import SimpleNamespace

import numpy as np
import pytest
from PySide6.QtCore import QThread

from tests.app.helpers import caught
from tunespec.app.gui.workers import DeviceController, DeviceJob, ProgressClock, Worker
from tunespec.core.progress import Cancelled, check_stop
from tunespec.devices.protocols import (
    Channel,
    DeviceIdentity,
    DeviceTimeoutError,
    LightStatus,
)


class _FakeLight:
    def __init__(self) -> None:
        self.identity = DeviceIdentity("Fake", "Light", "1")
        self._levels = np.zeros(2)
        self.thread = None

    def channels(self):
        return [Channel(0, "A", 450.0), Channel(1, "B", 550.0)]

    def set_levels(self, levels):
        self.thread = threading.current_thread()
        self._levels = np.asarray(levels, float)

    def levels(self):
        return self._levels.copy()

    def all_off(self):
        self._levels[:] = 0

    def status(self):
        return LightStatus(True, 25.0)

    def measure_spd(self):
        raise DeviceTimeoutError("the light source did not answer within 2 s")

    def close(self):
        self.all_off()


class _FakeCamera:
    identity = DeviceIdentity("Fake", "Camera", "2")
    exposure_s = 0.5
    iso = 100

    def close(self):
        pass


def _opener(light_spec, camera_spec, **options):
    return SimpleNamespace(light=_FakeLight(), camera=_FakeCamera())


@pytest.fixture
def controller(qtbot):
    c = DeviceController(_opener)
    yield c
    c.shutdown()


def test_worker_returns_and_reports_progress(qtbot):
    def job(n, *, progress, should_stop):
        for i in range(n):
            progress((i + 1) / n)
        return n * 2

    worker = Worker(job, 4)
    seen = []
    worker.signals.progressed.connect(seen.append)
    with caught(qtbot, worker.signals.returned, timeout=5000) as blocker:
        worker.start()
    assert blocker.args == [8]
    qtbot.waitUntil(lambda: seen == [0.25, 0.5, 0.75, 1.0])
    qtbot.waitUntil(lambda: Worker.active_count() == 0)


def test_worker_abort_raises_cancelled_inside(qtbot):
    started = threading.Event()

    def job(*, progress, should_stop):
        started.set()
        while True:
            check_stop(should_stop)
            QThread.msleep(1)

    worker = Worker(job)
    with caught(qtbot, worker.signals.errored, timeout=5000) as blocker:
        worker.start()
        started.wait(5)
        worker.abort()
    assert isinstance(blocker.args[0], Cancelled)
    qtbot.waitUntil(lambda: Worker.active_count() == 0)


def test_controller_runs_devices_on_its_own_thread(controller, qtbot):
    with caught(qtbot, controller.devices_opened, timeout=5000) as opened:
        controller.open_devices("fake", "fake")
    assert [c.name for c in opened.args[0].channels] == ["A", "B"]
    with caught(qtbot, controller.levels_changed, timeout=5000) as changed:
        controller.set_levels([0.5, 0.0])
    np.testing.assert_allclose(changed.args[0], [0.5, 0.0])
    # the device was called from the controller's thread, never the GUI thread
    assert controller._bench.light.thread is not threading.main_thread()


def test_controller_reports_device_errors(controller, qtbot):
    with caught(qtbot, controller.devices_opened, timeout=5000):
        controller.open_devices("fake", "fake")
    with caught(qtbot, controller.errored, timeout=5000) as err:
        controller.measure_spd()
    assert isinstance(err.args[0], DeviceTimeoutError)


def test_job_without_devices_fails_plainly(controller, qtbot):
    job = DeviceJob(lambda context, **kw: 1)
    with caught(qtbot, job.signals.errored, timeout=5000) as err:
        controller.submit(job)
    assert "connect" in str(err.args[0])


def test_progress_clock_estimates_remaining_time():
    clock = ProgressClock()
    assert np.isnan(clock.update(0.0))
    assert clock.update(1.0) == 0.0
    assert ProgressClock.format_s(65) == "1:05"
    assert ProgressClock.format_s(float("nan")) == "--"
