"""The base of every measurement-wizard page: run, show progress, abort, retake.

A page runs one job (a :class:`~tunespec.app.gui.workers.DeviceJob` on the device thread
for captures, a :class:`~tunespec.app.gui.workers.Worker` on the pool for numerics),
shows its progress with the time remaining, and can be aborted (the light is
switched off) and taken again. Subclasses say what job to make
(:meth:`StepPage.make_job`) and what to do with its result
(:meth:`StepPage.accept_result`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from typing import Any

from PySide6.QtCore import Qt, QTimer, Signal, Slot
from PySide6.QtWidgets import (
    QHBoxLayout,
    QLabel,
    QProgressBar,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from tunespec.app.gui.panels.device_panel import format_error
from tunespec.app.gui.workers import DeviceJob, ProgressClock, Throttle, Worker
from tunespec.core.progress import Cancelled

__all__ = ["StepPage", "StepState", "devices_connected"]

log = logging.getLogger(__name__)


def devices_connected(measurement: Any) -> str | None:
    """``None`` if the measurement's devices are open, else what the operator must
    do first (a capture page's :meth:`StepPage.can_start`)."""
    if not measurement.controller.is_open:
        return "Connect the devices first (step 1)."
    return None


class StepState:
    """The states a step can be in (plain strings, for signals and tests)."""

    PENDING = "pending"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"
    ABORTED = "aborted"


class StepPage(QWidget):
    """One step of the measurement wizard.

    Parameters
    ----------
    measurement
        The :class:`~tunespec.app.gui.wizard.measurement.Measurement` shared by all pages.
    title
        Short name in the step list ("Dark frame").
    description
        What the operator should do before starting, in plain words.
    start_text
        Label of the start button.
    retake_text
        Its label once the step has run, saying what is taken again ("Retake dark
        frames"); default "Retake".
    """

    #: The step changed state: one of :class:`StepState`.
    state_changed = Signal(str)
    #: The step finished successfully: its result.
    step_finished = Signal(object)
    #: The step's warnings changed: the list of them.
    warnings_changed = Signal(list)
    #: What the running job does now ("metering LED495, 7 of 22").
    stage_changed = Signal(str)

    #: Update the remaining-time text at most this often (ms).
    ETA_PERIOD_MS = 500
    #: Redraw the progress bar at most this often (ms): a simulated capture reports
    #: a step every few ms, and each redraw is a paint the event loop waits for.
    PROGRESS_PERIOD_MS = 100
    #: This step's name for :attr:`inputs` of later steps.
    key = ""
    #: Keys of the steps whose results this one uses: retaking one of them makes
    #: this step pending again.
    inputs: tuple[str, ...] = ()
    #: The :class:`Measurement` result this step makes (``"calibration"``...), which
    #: is dropped when the step is reset, so later steps cannot use a stale one.
    produces: str | None = None
    #: The defaults of the constructor's texts: a page sets them once as class
    #: attributes instead of repeating the constructor call.
    step_title = ""
    step_description = ""
    step_start_text = "Start"
    step_retake_text = "Retake"

    def __init__(
        self,
        measurement: Any,
        title: str | None = None,
        description: str | None = None,
        *,
        start_text: str | None = None,
        retake_text: str | None = None,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        title = self.step_title if title is None else title
        description = self.step_description if description is None else description
        start_text = self.step_start_text if start_text is None else start_text
        retake_text = self.step_retake_text if retake_text is None else retake_text
        self.measurement = measurement
        self.title = title
        self.state = StepState.PENDING
        self.job: Worker | DeviceJob | None = None
        self._job_remaining = None
        self._shown_remaining_s = float("inf")
        self.result: Any = None
        self.clock = ProgressClock()
        self._finish_state = StepState.FAILED
        #: What the pipeline warned about in this step's last run (or its result).
        self.warnings: list[str] = []
        self.stage = ""

        self.title_label = QLabel(title)
        self.title_label.setStyleSheet("font-size: 15pt; font-weight: bold")
        self.description_label = QLabel(description)
        self.description_label.setWordWrap(True)
        self.description_label.setTextFormat(Qt.TextFormat.RichText)
        self.body = QVBoxLayout()
        self.progress_bar = QProgressBar()
        self.progress_bar.setRange(0, 1000)
        self.progress_bar.setValue(0)
        self.progress_bar.setFormat("%p %")
        self.remaining_label = QLabel("")
        self.start_button = QPushButton(start_text)
        self.start_button.setDefault(True)
        self.abort_button = QPushButton("Abort")
        self.abort_button.setToolTip("Stop this step now; the light is switched off")
        self.result_label = QLabel("")
        self.result_label.setWordWrap(True)
        self.result_label.setTextInteractionFlags(
            Qt.TextInteractionFlag.TextSelectableByMouse
        )
        # the badge: every warning of the step, visible until the step is retaken
        self.warning_label = QLabel("")
        self.warning_label.setObjectName("warning_badge")
        self.warning_label.setWordWrap(True)
        self.warning_label.setTextInteractionFlags(
            Qt.TextInteractionFlag.TextSelectableByMouse
        )
        self.warning_label.setStyleSheet(
            "#warning_badge { background: #fff3cd; border: 1px solid #e0a800; "
            "border-radius: 4px; padding: 4px; color: #5c3c00; }"
        )
        self.warning_label.hide()
        buttons = QHBoxLayout()
        buttons.addWidget(self.start_button)
        buttons.addWidget(self.abort_button)
        buttons.addStretch(1)
        progress = QHBoxLayout()
        progress.addWidget(self.progress_bar, 1)
        progress.addWidget(self.remaining_label)
        # the buttons are the last row, so they sit at the same place on every page
        # whatever the length of the description or the result message above them;
        # the start button is wide enough for both its labels, so "Abort" does not
        # move when "Take frames" turns into "Retake dark frames"
        layout = QVBoxLayout(self)
        layout.addWidget(self.title_label)
        layout.addWidget(self.description_label)
        layout.addLayout(self.body, 1)
        layout.addWidget(self.warning_label)
        layout.addWidget(self.result_label)
        layout.addLayout(progress)
        layout.addLayout(buttons)
        self._start_text = start_text
        self._retake_text = retake_text
        metrics = self.start_button.fontMetrics()
        widest = max(metrics.horizontalAdvance(t) for t in (start_text, retake_text))
        self.start_button.setMinimumWidth(widest + 32)
        self._progress_display = Throttle(
            self._show_progress, self.PROGRESS_PERIOD_MS, parent=self
        )
        self.eta_timer = QTimer(self)
        self.eta_timer.setInterval(self.ETA_PERIOD_MS)
        self.eta_timer.timeout.connect(self._on_eta_timer_timeout)
        self.start_button.clicked.connect(self._on_start_button_clicked)
        self.abort_button.clicked.connect(self._on_abort_button_clicked)
        self._update_buttons()

    # -- for subclasses -------------------------------------------------------------
    def make_job(self) -> Worker | DeviceJob:
        """The job this step runs (not yet started). Raise to refuse with a message."""
        raise NotImplementedError

    def accept_result(self, result: Any) -> str:
        """Store ``result`` in the measurement; returns the line shown to the operator."""
        return "Done."

    def can_start(self) -> str | None:
        """``None`` if the step may start now, else why not (shown to the operator)."""
        return None

    def refresh(self) -> None:
        """Update the page from the measurement (called when the page is shown)."""

    def depends_on(self, other: StepPage) -> bool:
        """Whether this step uses ``other``'s result."""
        return other.key in self.inputs

    def restore(self) -> bool:
        """Mark the step done from results already on disk (resume); True if it was."""
        return False

    # -- running -----------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """Whether the step's job is running."""
        return self.state == StepState.RUNNING

    def start(self) -> Worker | DeviceJob | None:
        """Start (or retake) the step; returns the job, or None if it cannot start."""
        if self.running:
            return self.job
        why = self.can_start()
        if why is None:
            try:
                job = self.make_job()
            except Exception as exc:
                why = format_error(exc)
        if why is not None:
            self.result_label.setStyleSheet("color: #c00000")
            self.result_label.setText(why)
            return None
        self.job = job
        self.set_warnings(())
        self._set_stage("")
        job.signals.progressed.connect(self._on_job_progressed)
        job.signals.stage_changed.connect(self._on_job_stage_changed)
        job.signals.warned.connect(self._on_job_warned)
        job.signals.remaining_changed.connect(self._on_job_remaining_changed)
        job.signals.returned.connect(self._on_job_returned)
        job.signals.errored.connect(self._on_job_errored)
        job.signals.finished.connect(self._on_job_finished)
        self.clock.restart()
        self._job_remaining: tuple[float, float] | None = None
        self._shown_remaining_s = float("inf")
        self.progress_bar.setValue(0)
        self.remaining_label.setText("starting…")
        self.result_label.setStyleSheet("")
        self.result_label.setText("")
        self._set_state(StepState.RUNNING)
        self.eta_timer.start()
        log.info("step %r started", self.title)
        if isinstance(job, DeviceJob):
            self.measurement.controller.submit(job)
        else:
            job.start()
        return job

    def abort(self) -> None:
        """Stop the running job and switch the light off."""
        if self.job is not None and self.running:
            log.warning("step %r aborted by the operator", self.title)
            self.job.abort()
            self.remaining_label.setText("aborting…")
        controller = getattr(self.measurement, "controller", None)
        if controller is not None and controller.is_open:
            controller.all_off()

    def mark_done(
        self, text: str, result: Any = None, warnings: Sequence[str] | None = None
    ) -> None:
        """Mark the step done without running it (e.g. restored on resume); its
        warnings are ``warnings``, else those of ``result``."""
        self.result = result
        self.set_warnings(
            getattr(result, "warnings", ()) if warnings is None else warnings
        )
        self.progress_bar.setValue(1000)
        self.remaining_label.setText("")
        self.result_label.setStyleSheet("")
        self.result_label.setText(text)
        self._set_state(StepState.DONE)

    def reset(self) -> None:
        """Back to pending (a previous step was retaken)."""
        if self.running:
            return
        self.result = None
        if self.produces is not None:
            self.measurement.forget(self.produces)
        self.set_warnings(())
        self._reset_progress()
        self.remaining_label.setText("")
        self.result_label.setStyleSheet("")
        self.result_label.setText("")
        self._set_state(StepState.PENDING)

    # -- warnings and progress ------------------------------------------------------
    def add_warnings(self, warnings: Sequence[str]) -> None:
        """Show (and log) the warnings not shown yet."""
        new = [w for w in dict.fromkeys(warnings) if w not in self.warnings]
        if not new:
            return
        for w in new:
            log.warning("%s: %s", self.title, w)
        self.warnings.extend(new)
        self._show_warnings()

    def set_warnings(self, warnings: Sequence[str]) -> None:
        """Replace the warnings shown (a restored step shows its result's)."""
        self.warnings = []
        self._show_warnings()
        self.add_warnings(warnings)

    def _show_warnings(self) -> None:
        n = len(self.warnings)
        if n:
            from html import escape

            head = f"⚠ {n} warning{'s' if n > 1 else ''}"
            items = "".join(f"<li>{escape(w)}</li>" for w in self.warnings)
            self.warning_label.setText(
                f"<b>{head}</b><ul style='margin:0'>{items}</ul>"
            )
        self.warning_label.setVisible(bool(n))
        self.warnings_changed.emit(list(self.warnings))

    def _set_stage(self, text: str) -> None:
        self.stage = text
        self.progress_bar.setFormat(f"{text} \u2014 %p %" if text else "%p %")

    def _show_progress(self) -> None:
        """The newest fraction and stage on the bar (throttled while running)."""
        if self.running:
            self._set_stage(self.stage)
            self.progress_bar.setValue(round(1000 * self.clock.fraction))

    def _reset_progress(self) -> None:
        self._set_stage("")
        self.progress_bar.setValue(0)

    def _set_state(self, state: str) -> None:
        self.state = state
        self._update_buttons()
        self.state_changed.emit(state)

    def _update_buttons(self) -> None:
        running = self.running
        self.start_button.setEnabled(not running)
        self.abort_button.setEnabled(running)
        done = self.state in (StepState.DONE, StepState.FAILED, StepState.ABORTED)
        self.start_button.setText(self._retake_text if done else self._start_text)

    # -- slots ---------------------------------------------------------------------------
    @Slot()
    def _on_start_button_clicked(self) -> None:
        self.start()

    @Slot()
    def _on_abort_button_clicked(self) -> None:
        self.abort()

    @Slot(float)
    def _on_job_progressed(self, fraction: float) -> None:
        if not self.running:
            return  # queued from a job that was already aborted
        # never backwards, whatever a job reports
        fraction = max(self.clock.fraction, min(1.0, float(fraction)))
        self.clock.update(fraction)
        self._progress_display()

    @Slot(str)
    def _on_job_stage_changed(self, text: str) -> None:
        if self.running:
            self.stage = text
            self.stage_changed.emit(text)
            self._progress_display()

    @Slot(str)
    def _on_job_warned(self, text: str) -> None:
        self.add_warnings([text])

    @Slot(float)
    def _on_job_remaining_changed(self, seconds: float) -> None:
        if self.running:
            self._job_remaining = (float(seconds), time.monotonic())

    def remaining_s(self) -> float:
        """The seconds left as shown: the job's own estimate (taken from what it
        will do, e.g. the exposures chosen) counted down since it came, else the
        elapsed time scaled by the fraction left; never more than shown before,
        so the operator sees it only go down (NaN while unknown)."""
        if self._job_remaining is not None:
            seconds, at = self._job_remaining
            estimate = seconds - (time.monotonic() - at)
        else:
            estimate = self.clock.update(self.clock.fraction)
        if not math.isfinite(estimate):
            return float("nan")
        self._shown_remaining_s = min(self._shown_remaining_s, max(0.0, estimate))
        return self._shown_remaining_s

    @Slot()
    def _on_eta_timer_timeout(self) -> None:
        if self.running:
            remaining = self.remaining_s()
            self.remaining_label.setText(
                f"{ProgressClock.format_s(self.clock.elapsed_s)} elapsed, "
                f"{ProgressClock.format_s(remaining)} left"
            )

    @Slot(object)
    def _on_job_returned(self, result: Any) -> None:
        try:
            text = self.accept_result(result)
        except Exception as exc:
            log.exception("step %r: cannot use its result", self.title)
            self._fail(format_error(exc))
            return
        self.result = result
        self.add_warnings(getattr(result, "warnings", ()))
        self.progress_bar.setValue(1000)
        self.result_label.setStyleSheet("")
        self.result_label.setText(text)
        log.info("step %r done in %.1f s", self.title, self.clock.elapsed_s)
        self._finish_state = StepState.DONE

    @Slot(object)
    def _on_job_errored(self, exc: BaseException) -> None:
        if isinstance(exc, Cancelled) or (self.job is not None and self.job.aborted):
            self.result_label.setStyleSheet("color: #b06000")
            self.result_label.setText("Aborted; the light is off. Retake when ready.")
            self._finish_state = StepState.ABORTED
            return
        log.error("step %r failed: %s", self.title, exc)
        self._fail(format_error(exc))

    def _fail(self, text: str) -> None:
        self.result_label.setStyleSheet("color: #c00000")
        self.result_label.setText(f"Failed: {text}")
        self._finish_state = StepState.FAILED

    @Slot()
    def _on_job_finished(self) -> None:
        self.eta_timer.stop()
        state = self._finish_state
        self._finish_state = StepState.FAILED
        elapsed = ProgressClock.format_s(self.clock.elapsed_s)
        self.remaining_label.setText(f"{elapsed} elapsed")
        self._set_stage("")
        if state != StepState.DONE:
            # an aborted or failed step has not done any fraction of its work
            self._reset_progress()
            self.remaining_label.setText(f"stopped after {elapsed}")
        self.job = None
        self._set_state(state)
        if state == StepState.DONE:
            self.step_finished.emit(self.result)
