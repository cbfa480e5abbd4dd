"""The Qt binding work-around keeps ``None`` and ``True`` alive whatever is called."""

from __future__ import annotations

import sys

from PySide6.QtCore import QObject, Signal

from tunespec.app.gui import qt_compat


class _Emitter(QObject):
    ticked = Signal(float)


def test_many_calls_and_signals_leave_the_singletons_alive():
    emitter = _Emitter()
    leaky = qt_compat.leaked_singletons()
    for _ in range(20_000):
        emitter.ticked.emit(0.5)  # PySide6 6.12.0 on 3.11 loses a True here
        emitter.setObjectName("x")  # ... and a None here
    # without the work-around the interpreter would abort ("none_dealloc") by now
    assert sys.getrefcount(None) > 1000
    assert sys.getrefcount(True) > 1000
    if leaky and sys.version_info < (3, 12):
        assert qt_compat._applied
