"""Python ``logging`` shown in a widget.

:class:`QtLogHandler` is a :class:`logging.Handler` that may be called from any
thread; it forwards formatted records through a Qt signal, so the text is appended
on the GUI thread. :class:`LogPanel` shows them with a level filter.
"""

from __future__ import annotations

import contextlib
import logging
from functools import partial

from PySide6.QtCore import QObject, Signal, Slot
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


class _Bridge(QObject):
    record_emitted = Signal(int, str)


class QtLogHandler(logging.Handler):
    """A logging handler emitting ``record_emitted(levelno, text)`` (thread-safe)."""

    def __init__(self, level: int = logging.DEBUG) -> None:
        super().__init__(level)
        self.bridge = _Bridge()
        self.setFormatter(
            logging.Formatter(
                "%(asctime)s %(levelname)-7s %(name)s: %(message)s", "%H:%M:%S"
            )
        )

    def emit(self, record: logging.LogRecord) -> None:
        """Format and forward one record."""
        # the bridge may already be deleted with the window
        with contextlib.suppress(RuntimeError):
            self.bridge.record_emitted.emit(record.levelno, self.format(record))


class LogPanel(QWidget):
    """The log of this session, newest at the bottom.

    Parameters
    ----------
    logger
        The logger to attach to (default: the ``tunespec`` logger, which every module
        of the project logs under).
    max_lines
        Older lines are dropped beyond this.
    """

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

        self.handler = QtLogHandler()
        self.handler.bridge.record_emitted.connect(self._on_handler_record_emitted)
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

    @Slot(int, str)
    def _on_handler_record_emitted(self, level: int, text: str) -> None:
        self._records.append((level, text))
        del self._records[: -self._max_lines]
        if level >= self.min_level:
            self._append(level, text)

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
