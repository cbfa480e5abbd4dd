"""Fixtures for the GUI tests: offscreen Qt, temporary settings, no leaked threads."""

from __future__ import annotations

import gc
import os
import threading

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

from PySide6.QtCore import QSettings, QThreadPool

from tunespec.app.gui import workers

#: Collections of Python's cycle collector started on a thread other than the main
#: one: (thread name, generation). Such a collection may delete Qt objects there
#: (issue 27's segmentation faults); the GUI's collector keeps them on the GUI thread.
_OFF_THREAD_COLLECTIONS: list[tuple[str, int]] = []


def _watch_collections(phase: str, info: dict) -> None:
    if phase == "start" and threading.current_thread() is not threading.main_thread():
        _OFF_THREAD_COLLECTIONS.append(
            (threading.current_thread().name, info["generation"])
        )


gc.callbacks.append(_watch_collections)


@pytest.fixture(autouse=True)
def _no_leaked_threads(qapp) -> Iterator[None]:
    """Fail a test that leaves a device thread or a pool worker running (napari),
    or whose threads collected Python's garbage (where Qt objects may die)."""
    _OFF_THREAD_COLLECTIONS.clear()
    # as in the application: any thread may run Python (zarr's, the pool's)
    workers.collect_on_gui_thread()
    yield
    pool = QThreadPool.globalInstance()
    leaked_pool = pool.activeThreadCount()
    # a Worker that has sent `finished` may still be returning from run() on its pool
    # thread (under load, after the test's waitSignal): that one is not left running
    if leaked_pool and not workers.Worker.active_count() and pool.waitForDone(1_000):
        leaked_pool = 0
    if leaked_pool:
        pool.waitForDone(10_000)
    leaked_threads = workers.running_threads()
    for thread in leaked_threads:
        thread.quit()
        thread.wait(10_000)
    alive = workers.Worker.active_count()
    # back to automatic collection for what runs next (nothing of ours runs now)
    workers.restore_automatic_collection()
    off_thread = list(_OFF_THREAD_COLLECTIONS)
    assert not off_thread, f"garbage collected off the GUI thread: {off_thread}"
    assert not leaked_pool, f"{leaked_pool} pool worker(s) still running after the test"
    assert not leaked_threads, f"device thread(s) left running: {leaked_threads}"
    assert not alive, f"{alive} Worker(s) never finished"
    assert gc.isenabled(), "the GUI's collector still holds gc off"


@pytest.fixture(autouse=True)
def temp_settings(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """QSettings in a temporary INI location, never the user's."""
    folder = tmp_path_factory.mktemp("settings")
    QSettings.setDefaultFormat(QSettings.Format.IniFormat)
    for fmt in (QSettings.Format.IniFormat, QSettings.Format.NativeFormat):
        for scope in (QSettings.Scope.UserScope, QSettings.Scope.SystemScope):
            QSettings.setPath(fmt, scope, str(folder))
    yield folder


@pytest.fixture
def panel(qtbot) -> Iterator[object]:
    """A device panel on the simulated bench (small frames), shut down after."""
    from tests.app.helpers import device_panel

    sim = {"realtime": False, "resolution": (256, 192), "seed": 1}
    with device_panel(qtbot, sim) as panel:
        yield panel
