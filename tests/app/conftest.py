"""Fixtures for the GUI tests: offscreen Qt, temporary settings, no leaked threads."""

from __future__ import annotations

import os

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyqtgraph")

from PySide6.QtCore import QSettings, QThreadPool

from tunespec.app.gui import workers


@pytest.fixture(autouse=True)
def _no_leaked_threads(qapp) -> Iterator[None]:
    """Fail a test that leaves a device thread or a pool worker running (napari)."""
    yield
    pool = QThreadPool.globalInstance()
    leaked_pool = pool.activeThreadCount()
    if leaked_pool:
        pool.waitForDone(10_000)
    leaked_threads = workers.running_threads()
    for thread in leaked_threads:
        thread.quit()
        thread.wait(10_000)
    alive = workers.Worker.active_count()
    assert not leaked_pool, f"{leaked_pool} pool worker(s) still running after the test"
    assert not leaked_threads, f"device thread(s) left running: {leaked_threads}"
    assert not alive, f"{alive} Worker(s) never finished"


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
