"""Small helpers shared by the GUI tests."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from PySide6.QtCore import QEvent, QObject, QPoint, QPointF, Qt, SignalInstance
from PySide6.QtGui import QMouseEvent
from PySide6.QtWidgets import QApplication, QWidget
from pytestqt.qtbot import QtBot


def _send(
    widget: QWidget,
    kind: QEvent.Type,
    pos: QPointF,
    button: Qt.MouseButton,
    buttons: Qt.MouseButton,
) -> None:
    global_pos = QPointF(widget.mapToGlobal(pos.toPoint()))
    event = QMouseEvent(
        kind, pos, global_pos, button, buttons, Qt.KeyboardModifier.NoModifier
    )
    QApplication.sendEvent(widget, event)


def mouse_drag(
    widget: QWidget, start: QPoint | QPointF, end: QPoint | QPointF, steps: int = 10
) -> None:
    """Press the left button at ``start``, move to ``end`` in ``steps``, release.

    ``QTest.mouseMove`` does not carry pressed buttons, which pyqtgraph needs to see a
    drag, so the events are built by hand and sent to ``widget`` (a viewport).
    """
    left = Qt.MouseButton.LeftButton
    none = Qt.MouseButton.NoButton
    a, b = QPointF(start), QPointF(end)
    _send(widget, QEvent.Type.MouseMove, a, none, none)
    _send(widget, QEvent.Type.MouseButtonPress, a, left, left)
    for i in range(1, steps + 1):
        p = a + (b - a) * (i / steps)
        _send(widget, QEvent.Type.MouseMove, p, none, left)
    _send(widget, QEvent.Type.MouseButtonRelease, b, left, none)


class SignalCatcher(QObject):
    """Receives a signal on the GUI thread (a queued connection for signals sent from
    worker threads; pytest-qt's ``waitSignal`` would run its slot, and stop its
    timer, on the sending thread)."""

    def __init__(self, signal: SignalInstance) -> None:
        super().__init__()
        self.count = 0
        self.args: list[object] = []
        signal.connect(self._on_signal)

    def _on_signal(self, *args: object) -> None:
        self.count += 1
        self.args = list(args)


@contextmanager
def caught(
    qtbot: QtBot, signal: SignalInstance, timeout: int = 10_000
) -> Iterator[SignalCatcher]:
    """``with caught(qtbot, obj.sig) as c: ...`` waits for ``sig`` after the block."""
    catcher = SignalCatcher(signal)
    yield catcher
    qtbot.waitUntil(lambda: catcher.count > 0, timeout=timeout)


def ini_settings(folder: Path, name: str = "settings") -> Any:
    """``AppSettings`` in ``folder/NAME.ini`` (never the user's)."""
    from PySide6.QtCore import QSettings

    from tunespec.app.gui.settings import AppSettings

    return AppSettings(
        QSettings(str(folder / f"{name}.ini"), QSettings.Format.IniFormat)
    )


def new_main_window(
    qtbot: QtBot, folder: Path, sim_options: dict[str, Any], *, show: bool = True
) -> Any:
    """A ``MainWindow`` on the simulated bench with :func:`ini_settings`, shown."""
    from tunespec.app.gui.main_window import MainWindow

    w = MainWindow(ini_settings(folder), sim_options=sim_options)
    qtbot.addWidget(w)
    if show:
        w.show()
    return w


@contextmanager
def main_window(
    qtbot: QtBot,
    folder: Path,
    sim_options: dict[str, Any],
    *,
    show: bool = True,
    exposed: bool = False,
) -> Iterator[Any]:
    """:func:`new_main_window`, waited for until exposed if asked, closed after."""
    w = new_main_window(qtbot, folder, sim_options, show=show)
    if exposed:
        qtbot.waitExposed(w)
    try:
        yield w
    finally:
        w.close()


@contextmanager
def device_panel(qtbot: QtBot, sim_options: dict[str, Any]) -> Iterator[Any]:
    """A ``DevicePanel`` on its own controller, shut down after."""
    from tunespec.app.gui.panels.device_panel import DevicePanel
    from tunespec.app.gui.workers import DeviceController

    controller = DeviceController()
    panel = DevicePanel(controller, sim_options=sim_options)
    qtbot.addWidget(panel)
    try:
        yield panel
    finally:
        controller.shutdown()
