"""The measurement wizard: the operator's path from connecting to exporting.

Steps: connect → dark → white background → chart under all LEDs → calibrate
(Table 1 with a pass/fail threshold) → sample target → estimate (Table 2 when
references are given) → export. Each step shows its progress and the time remaining,
can be aborted (the LEDs go off) and taken again; retaking a step makes the steps
after it pending again. A measurement lives in a folder; an interrupted one is
reopened with :meth:`WizardPanel.open_measurement` and resumes at its first
unfinished step.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from PySide6.QtCore import Qt, Signal, Slot
from PySide6.QtGui import QAction, QBrush, QColor, QKeySequence
from PySide6.QtWidgets import (
    QFileDialog,
    QFrame,
    QHBoxLayout,
    QLabel,
    QListWidget,
    QListWidgetItem,
    QMenu,
    QPushButton,
    QStackedWidget,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from tunespec.app.gui.wizard.calibrate_page import CalibratePage
from tunespec.app.gui.wizard.capture_page import CapturePage
from tunespec.app.gui.wizard.connect_page import ConnectPage
from tunespec.app.gui.wizard.estimate_page import EstimatePage
from tunespec.app.gui.wizard.export_page import ExportPage
from tunespec.app.gui.wizard.sample_page import SamplePage
from tunespec.app.gui.wizard.step_page import StepPage, StepState

__all__ = ["WizardPanel"]

log = logging.getLogger(__name__)

_STATE_MARK = {
    StepState.PENDING: ("○", QColor(120, 120, 120)),
    StepState.RUNNING: ("▶", QColor(0, 90, 200)),
    StepState.DONE: ("✔", QColor(0, 128, 0)),
    StepState.FAILED: ("✖", QColor(192, 0, 0)),
    StepState.ABORTED: ("■", QColor(176, 96, 0)),
}


class WizardPanel(QWidget):
    """Step list, the current step's page, Back/Next and the measurement folder.

    Parameters
    ----------
    measurement
        The :class:`~tunespec.app.gui.wizard.measurement.Measurement` the steps work on.
    """

    #: The current step changed: its index.
    step_changed = Signal(int)

    def __init__(self, measurement: Any, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.measurement = measurement
        self.pages: list[StepPage] = self._build_pages(measurement)
        self._build_folder_row()
        self._build_steps_and_prompt()
        self._build_navigation()
        top = QHBoxLayout()
        top.addWidget(QLabel("Measurement:"))
        top.addWidget(self.folder_label, 1)
        top.addWidget(self.resume_button)
        top.addWidget(self.recent_button)
        top.addWidget(self.new_button)
        top.addWidget(self.open_button)
        nav = QHBoxLayout()
        nav.addStretch(1)
        nav.addWidget(self.back_button)
        nav.addWidget(self.next_button)
        right = QVBoxLayout()
        right.addWidget(self.prompt_frame)
        right.addWidget(self.stack, 1)
        right.addLayout(nav)
        middle = QHBoxLayout()
        middle.addWidget(self.step_list)
        middle.addLayout(right, 1)
        layout = QVBoxLayout(self)
        layout.addLayout(top)
        layout.addLayout(middle, 1)
        self._connect_signals()
        measurement.folder_chooser = self.ask_measurements_dir
        for i in range(len(self.pages)):
            self._show_state(i)
        self._show_no_folder()
        self.go_to(0)

    def _build_pages(self, m: Any) -> list[StepPage]:
        self.connect_page = ConnectPage(m)
        self.dark_page = CapturePage(
            m,
            "dark",
            "Dark frame",
            "Place the <b>white background board</b> in front of the camera and "
            "darken the room. With automatic exposure the exposure of every LED is "
            "metered on the board first; then the dark frame(s) are taken with all "
            "LEDs off (paper: dark-current correction).",
        )
        self.white_page = CapturePage(
            m,
            "white",
            "White background",
            "Keep the <b>white background board</b> in place, nothing on it. One "
            "frame per LED is taken for the flat field (Eq. 2).",
        )
        self.chart_page = CapturePage(
            m,
            "target",
            "Chart under all LEDs",
            "Put the <b>chart</b> (ColorChecker SG) flat on the board, fully in view. "
            "One frame per LED is taken. Check its corners in the target-layout "
            "editor while it runs.",
        )
        self.calibrate_page = CalibratePage(m)
        self.sample_page = SamplePage(m)
        self.estimate_page = EstimatePage(m)
        self.export_page = ExportPage(m)
        return [
            self.connect_page,
            self.dark_page,
            self.white_page,
            self.chart_page,
            self.calibrate_page,
            self.sample_page,
            self.estimate_page,
            self.export_page,
        ]

    def _build_folder_row(self) -> None:
        """The measurement in use, the last one to resume, recent ones, New, Open."""
        self.folder_label = QLabel("No measurement folder yet.")
        self.folder_label.setWordWrap(True)
        self.resume_button = QPushButton("Resume last")
        self.resume_button.setToolTip("Open the last measurement again")
        self.recent_menu = QMenu("Open &recent", self)
        self.recent_button = QToolButton()
        self.recent_button.setText("Recent")
        self.recent_button.setMenu(self.recent_menu)
        self.recent_button.setPopupMode(QToolButton.ToolButtonPopupMode.InstantPopup)
        self.new_button = QPushButton("New…")
        self.open_button = QPushButton("Open / resume…")

    def _build_steps_and_prompt(self) -> None:
        self.step_list = QListWidget()
        self.step_list.setMaximumWidth(230)
        self.stack = QStackedWidget()
        for page in self.pages:
            self.step_list.addItem(QListWidgetItem(page.title))
            self.stack.addWidget(page)
        # the hardware stage asks the operator through here (white board / target)
        self.prompt_label = QLabel()
        self.prompt_label.setWordWrap(True)
        self.prompt_button = QPushButton("Done — continue")
        self.prompt_frame = QFrame()
        self.prompt_frame.setObjectName("prompt_frame")
        self.prompt_frame.setStyleSheet(
            "#prompt_frame { background: #fff3cd; border: 2px solid #e0a800; }"
        )
        prompt_row = QHBoxLayout(self.prompt_frame)
        prompt_row.addWidget(self.prompt_label, 1)
        prompt_row.addWidget(self.prompt_button)
        self.prompt_frame.hide()

    def _build_navigation(self) -> None:
        self.back_button = QPushButton("◀ Back")
        self.next_button = QPushButton("Next ▶")
        # keyboard: Back/Next as a browser's, start (Take frames, Calibrate...) and
        # Abort; the main window also adds Abort to itself, so it works on every tab
        self.back_action = self._action("Back", ("Alt+Left", "Ctrl+PgUp"))
        self.next_action = self._action("Next", ("Alt+Right", "Ctrl+PgDown"))
        self.start_action = self._action(
            "Start / take frames", ("Ctrl+Return", "Ctrl+Enter")
        )
        self.abort_action = self._action("Abort", ("Escape",))
        self.back_button.setToolTip("Previous step (Alt+←)")
        self.next_button.setToolTip("Next step (Alt+→)")
        for page in self.pages:
            page.start_button.setToolTip(
                f"{page.start_button.toolTip() or 'Start this step'} (Ctrl+Enter)"
            )
            page.abort_button.setToolTip(f"{page.abort_button.toolTip()} (Esc)")

    def _connect_signals(self) -> None:
        m = self.measurement
        for i, page in enumerate(self.pages):
            page.state_changed.connect(
                lambda state, i=i: self._on_page_state_changed(i, state)
            )
            page.step_finished.connect(lambda _r, i=i: self._on_page_step_finished(i))
            page.warnings_changed.connect(lambda _w, i=i: self._show_state(i))
        for page in (self.dark_page, self.white_page, self.chart_page):
            page.shorter_exposure_requested.connect(self._on_shorter_exposure_requested)
        self.step_list.currentRowChanged.connect(self._on_step_list_row_changed)
        self.back_button.clicked.connect(self._on_back_button_clicked)
        self.next_button.clicked.connect(self._on_next_button_clicked)
        self.back_action.triggered.connect(self._on_back_action_triggered)
        self.next_action.triggered.connect(self._on_next_action_triggered)
        self.start_action.triggered.connect(self._on_start_action_triggered)
        self.abort_action.triggered.connect(self.abort)
        self.new_button.clicked.connect(self.ask_new_measurement)
        self.open_button.clicked.connect(self.ask_open_measurement)
        self.resume_button.clicked.connect(self._on_resume_button_clicked)
        self.recent_menu.aboutToShow.connect(self._fill_recent_menu)
        m.folder_changed.connect(self._on_measurement_folder_changed)
        m.controller.prompt_requested.connect(self._on_controller_prompt_requested)
        self.prompt_button.clicked.connect(self._on_prompt_button_clicked)

    def _action(self, text: str, keys: tuple[str, ...]) -> QAction:
        action = QAction(text, self)
        action.setShortcuts([QKeySequence(k) for k in keys])
        action.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
        self.addAction(action)
        return action

    # -- navigation -----------------------------------------------------------------
    @property
    def current_index(self) -> int:
        """Index of the page shown."""
        return self.stack.currentIndex()

    @property
    def current_page(self) -> StepPage:
        """The page shown."""
        return self.pages[self.current_index]

    def go_to(self, index: int) -> None:
        """Show step ``index``."""
        index = max(0, min(index, len(self.pages) - 1))
        if self.step_list.currentRow() != index:
            self.step_list.setCurrentRow(index)  # re-enters through the slot
            return
        self.stack.setCurrentIndex(index)
        self.pages[index].refresh()
        self._update_nav()
        self.step_changed.emit(index)

    def first_unfinished(self) -> int:
        """Index of the first step not done (the last step if all are)."""
        for i, page in enumerate(self.pages):
            if page.state != StepState.DONE:
                return i
        return len(self.pages) - 1

    def _update_nav(self) -> None:
        i = self.current_index
        running = self.running
        self.back_button.setEnabled(i > 0 and not running)
        self.next_button.setEnabled(
            i < len(self.pages) - 1
            and self.pages[i].state == StepState.DONE
            and not running
        )
        self.new_button.setEnabled(not running)
        self.open_button.setEnabled(not running)
        self.resume_button.setEnabled(not running)
        self.recent_button.setEnabled(not running)

    def _show_state(self, index: int) -> None:
        page = self.pages[index]
        mark, colour = _STATE_MARK[page.state]
        item = self.step_list.item(index)
        badge = f"  ⚠ {len(page.warnings)}" if page.warnings else ""
        item.setText(f"{mark}  {index + 1}. {page.title}{badge}")
        item.setForeground(QBrush(colour))
        item.setToolTip("\n".join(page.warnings))

    # -- measurement folder ---------------------------------------------------------
    @property
    def running(self) -> bool:
        """Whether a step is running."""
        return any(p.running for p in self.pages)

    def _refuse_while_running(self) -> bool:
        # the File menu reaches here too: a running step still writes to the folder
        if self.running:
            self._show_folder_error(
                RuntimeError("a step is running: abort it or let it finish first")
            )
            return True
        return False

    def new_measurement(self, folder: str | Path) -> bool:
        """Start a new measurement in ``folder``; False (with a message) if refused."""
        if self._refuse_while_running():
            return False
        try:
            self.measurement.new(folder)
        except Exception as exc:
            self._show_folder_error(exc)
            return False
        for page in self.pages[1:]:
            page.reset()
        self.go_to(0 if self.connect_page.state != StepState.DONE else 1)
        return True

    def open_measurement(self, folder: str | Path) -> bool:
        """Reopen a measurement; steps already done are restored, and the wizard goes
        to the first unfinished one."""
        if self._refuse_while_running():
            return False
        try:
            self.measurement.open(folder)
        except Exception as exc:
            self._show_folder_error(exc)
            return False
        for page in self.pages[1:]:
            page.reset()
            if not page.restore():
                break
        self.go_to(self.first_unfinished())
        log.info("measurement %s reopened at step %r", folder, self.current_page.title)
        return True

    def _show_folder_error(self, exc: Exception) -> None:
        from html import escape

        from tunespec.app.gui.panels.device_panel import format_error

        text = str(exc) if isinstance(exc, RuntimeError) else format_error(exc)
        html = f"<span style='color:#c00000'>{escape(text)}</span>"
        if self.measurement.folder is not None:
            # the measurement in use stays the one shown
            html += f"<br>{escape(str(self.measurement.folder))}"
        self.folder_label.setText(html)
        log.error("measurement folder: %s", exc)

    def abort(self) -> None:
        """Abort the running step, if any."""
        for page in self.pages:
            if page.running:
                page.abort()

    def shutdown(self) -> None:
        """Abort and wait for the pool jobs (window closing)."""
        self.abort()
        from PySide6.QtCore import QThreadPool

        QThreadPool.globalInstance().waitForDone(10_000)

    def retake_with_shorter_exposure(self) -> bool:
        """The chart session had clipped frames: keep it aside, shorten the
        exposure and take the chart again from the dark frame (False, and why on
        the page, if a step runs)."""
        if self._refuse_while_running():
            return False
        try:
            moved = self.measurement.shorten_exposure("chart")
        except Exception as exc:
            from tunespec.app.gui.panels.device_panel import format_error

            self.dark_page.result_label.setText(format_error(exc))
            return False
        for page in (self.chart_page, self.white_page, self.dark_page):
            page.reset()
        self.dark_page._show_options(self.measurement.capture_options)
        self.go_to(self.pages.index(self.dark_page))
        if moved is not None:
            log.info("retaking the chart with a shorter exposure (%s)", moved.name)
        self.dark_page.start()
        return True

    # -- slots ---------------------------------------------------------------------------
    @Slot()
    def _on_shorter_exposure_requested(self) -> None:
        self.retake_with_shorter_exposure()

    @Slot(str)
    def _on_controller_prompt_requested(self, message: str) -> None:
        self.prompt_label.setText(f"<b>{message}</b>")
        self.prompt_frame.show()
        self.prompt_button.setFocus()

    @Slot()
    def _on_prompt_button_clicked(self) -> None:
        self.prompt_frame.hide()
        self.measurement.controller.confirm_prompt()

    def _on_page_state_changed(self, index: int, state: str) -> None:
        self._show_state(index)
        if state != StepState.RUNNING:
            self.prompt_frame.hide()
        if state in (StepState.RUNNING, StepState.PENDING):
            # a retaken (or reset) step invalidates what was derived from it; a reset
            # page reports PENDING in turn, so this follows the whole chain
            for page in self.pages[index + 1 :]:
                if page.state != StepState.PENDING and page.depends_on(
                    self.pages[index]
                ):
                    page.reset()
        self._update_nav()

    def _on_page_step_finished(self, index: int) -> None:
        self._update_nav()

    @Slot(int)
    def _on_step_list_row_changed(self, row: int) -> None:
        if row >= 0:
            self.go_to(row)

    @Slot()
    def _on_back_button_clicked(self) -> None:
        self.go_to(self.current_index - 1)

    @Slot()
    def _on_next_button_clicked(self) -> None:
        self.go_to(self.current_index + 1)

    @Slot()
    def _on_back_action_triggered(self) -> None:
        if self.back_button.isEnabled():
            self.back_button.click()

    @Slot()
    def _on_next_action_triggered(self) -> None:
        if self.next_button.isEnabled():
            self.next_button.click()

    @Slot()
    def _on_start_action_triggered(self) -> None:
        button = self.current_page.start_button
        if button.isEnabled() and button.isVisible():
            button.click()

    # -- asking for folders (the File menu uses the same) ---------------------------
    def _ask_folder(self, caption: str) -> str:
        """A folder dialog starting where the measurements are ("" if cancelled)."""
        return QFileDialog.getExistingDirectory(
            self, caption, self.measurement.settings.measurements_dir()
        )

    def ask_new_measurement(self) -> bool:
        """Ask for the folder of a new measurement and start it there."""
        folder = self._ask_folder("Folder for the new measurement (an empty one)")
        return bool(folder) and self.new_measurement(folder)

    def ask_open_measurement(self) -> bool:
        """Ask for a measurement folder and open it (resume)."""
        folder = self._ask_folder("Open a measurement to resume")
        return bool(folder) and self.open_measurement(folder)

    def ask_measurements_dir(self) -> Path | None:
        """Where measurements go: asked once, when a step needs a folder and none was
        chosen (the measurement remembers the answer)."""
        folder = self._ask_folder(
            "Where should measurements be saved? (asked once; each measurement "
            "gets its own folder there)"
        )
        return Path(folder) if folder else None

    def _fill_recent_menu(self) -> None:
        self.recent_menu.clear()
        recent = self.measurement.settings.recent_measurements()
        for folder in recent:
            action = self.recent_menu.addAction(str(folder))
            action.triggered.connect(
                lambda _checked=False, f=folder: self.open_measurement(f)
            )
        if not recent:
            self.recent_menu.addAction("(no recent measurements)").setEnabled(False)

    def _show_no_folder(self) -> None:
        """Before a measurement is open: offer the last one."""
        last = self.measurement.settings.last_measurement()
        self.resume_button.setVisible(last is not None)
        if last is not None:
            self.resume_button.setToolTip(f"Open {last} again")
            self.folder_label.setText(f"None open. Last: {last}")
        self.recent_button.setEnabled(
            bool(self.measurement.settings.recent_measurements())
        )

    @Slot()
    def _on_resume_button_clicked(self) -> None:
        last = self.measurement.settings.last_measurement()
        if last is not None:
            self.open_measurement(last)

    @Slot(object)
    def _on_measurement_folder_changed(self, folder: Any) -> None:
        self.resume_button.hide()
        self.recent_button.setEnabled(True)
        self.folder_label.setText(str(folder))
        self.folder_label.setTextInteractionFlags(
            Qt.TextInteractionFlag.TextSelectableByMouse
        )
