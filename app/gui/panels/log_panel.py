"""Python ``logging`` shown in a widget.

:class:`QtLogHandler` is a :class:`logging.Handler` that may be called from any
thread; it only queues the formatted records, and :class:`LogPanel` appends them on
the GUI thread (at once for records of the GUI thread, every
:attr:`LogPanel.POLL_MS` for the others). No Qt object is touched off the GUI
thread: a signal object the handler emitted on could die with the window while the
device thread logs (issue 27).
"""

from __future__ import annotations

import collections
import contextlib
import logging
import threading
from collections.abc import Callable
from functools import partial

from PySide6.QtCore import QTimer, Slot
from PySide6.QtGui import QColor, QTextCharFormat, QTextCursor
from PySide6.QtWidgets import (
    QComboBox,
    QHBoxLayout,
    QLabel,
    QPlainTextEdit,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

__all__ = ["LogPanel", "QtLogHandler"]

_COLOURS = {
    logging.DEBUG: "#808080",
    logging.INFO: "#202020",
    logging.WARNING: "#b06000",
    logging.ERROR: "#c00000",
    logging.CRITICAL: "#c00000",
}


class QtLogHandler(logging.Handler):
    """A logging handler queueing ``(levelno, text)`` for the GUI (thread-safe).

    Parameters
    ----------
    level
        The lowest level queued.
    max_records
        Older records not yet shown are dropped beyond this.
    """

    def __init__(self, level: int = logging.DEBUG, max_records: int = 5000) -> None:
        super().__init__(level)
        self.pending: collections.deque[tuple[int, str]] = collections.deque(
            maxlen=max_records
        )
        #: Called (on the thread that made the handler) after a record of that
        #: thread was queued: shows it at once.
        self.on_own_thread: Callable[[], None] | None = None
        self._thread_id = threading.get_ident()
        self.setFormatter(
            logging.Formatter(
                "%(asctime)s %(levelname)-7s %(name)s: %(message)s", "%H:%M:%S"
            )
        )

    def emit(self, record: logging.LogRecord) -> None:
        """Format and queue one record."""
        self.pending.append((record.levelno, self.format(record)))
        sink = self.on_own_thread
        if sink is not None and threading.get_ident() == self._thread_id:
            # the widget may already be deleted with the window
            with contextlib.suppress(RuntimeError):
                sink()

    def take(self) -> list[tuple[int, str]]:
        """The records queued since the last call, oldest first."""
        out = []
        with contextlib.suppress(IndexError):
            while True:
                out.append(self.pending.popleft())
        return out


class LogPanel(QWidget):
    """The log of this session, newest at the bottom.

    Records logged on other threads appear within :attr:`POLL_MS`.

    Parameters
    ----------
    logger
        The logger to attach to (default: the ``tunespec`` logger, which every module
        of the project logs under).
    max_lines
        Older lines are dropped beyond this.
    """

    #: How often records of other threads are shown (ms).
    POLL_MS = 100

    def __init__(
        self,
        logger: logging.Logger | None = None,
        *,
        max_lines: int = 5000,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self._logger = logger or logging.getLogger("tunespec")
        self._records: list[tuple[int, str]] = []
        self._max_lines = max_lines
        self.text = QPlainTextEdit(readOnly=True)
        self.text.setMaximumBlockCount(max_lines)
        self.text.setObjectName("log_text")
        self.level_combo = QComboBox()
        for name in ("DEBUG", "INFO", "WARNING", "ERROR"):
            self.level_combo.addItem(name, logging.getLevelName(name))
        self.level_combo.setCurrentIndex(1)
        self.clear_button = QPushButton("Clear")
        top = QHBoxLayout()
        top.addWidget(QLabel("Show from"))
        top.addWidget(self.level_combo)
        top.addStretch(1)
        top.addWidget(self.clear_button)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addLayout(top)
        layout.addWidget(self.text)

        self.handler = QtLogHandler(max_records=max_lines)
        self.handler.on_own_thread = self._show_pending
        self._poll_timer = QTimer(self)
        self._poll_timer.setInterval(self.POLL_MS)
        self._poll_timer.timeout.connect(self._on_poll_timer_timeout)
        self._poll_timer.start()
        self._logger.addHandler(self.handler)
        if self._logger.level == logging.NOTSET or self._logger.level > logging.INFO:
            self._logger.setLevel(logging.INFO)
        self.level_combo.currentIndexChanged.connect(self._on_level_combo_changed)
        self.clear_button.clicked.connect(self._on_clear_button_clicked)
        # the logger outlives the widget: drop the handler with it
        self.destroyed.connect(partial(self._logger.removeHandler, self.handler))

    def detach(self) -> None:
        """Remove the handler from the logger (call before the widget goes away)."""
        self._logger.removeHandler(self.handler)
        self.handler.on_own_thread = None
        self._poll_timer.stop()

    @property
    def min_level(self) -> int:
        """The lowest level shown."""
        return int(self.level_combo.currentData())

    def plain_text(self) -> str:
        """Everything shown, as text."""
        return self.text.toPlainText()

    def _append(self, level: int, text: str) -> None:
        fmt = QTextCharFormat()
        fmt.setForeground(QColor(_COLOURS.get(level, "#202020")))
        cursor = self.text.textCursor()
        cursor.movePosition(QTextCursor.MoveOperation.End)
        if not self.text.document().isEmpty():
            cursor.insertBlock()
        cursor.insertText(text, fmt)
        self.text.ensureCursorVisible()

    def _show_pending(self) -> None:
        """Append the records queued by the handler (GUI thread)."""
        for level, text in self.handler.take():
            self._records.append((level, text))
            if level >= self.min_level:
                self._append(level, text)
        del self._records[: -self._max_lines]

    @Slot()
    def _on_poll_timer_timeout(self) -> None:
        self._show_pending()

    @Slot(int)
    def _on_level_combo_changed(self, _index: int) -> None:
        self.text.clear()
        for level, text in self._records:
            if level >= self.min_level:
                self._append(level, text)

    @Slot()
    def _on_clear_button_clicked(self) -> None:
        self._records.clear()
        self.text.clear()
