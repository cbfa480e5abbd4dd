"""Wizard step 5: estimate the camera sensitivities from the chart (Table 1)."""

from __future__ import annotations

from typing import Any

from PySide6.QtWidgets import QComboBox, QDoubleSpinBox, QFormLayout, QWidget

from tunespec.app.gui.panels.stats_table_panel import show_table1, table1_panel
from tunespec.app.gui.processes import ProcessWorker
from tunespec.app.gui.wizard.measurement import (
    CALIBRATION_DIR,
    CHART_DIR,
    CalibrationResult,
)
from tunespec.app.gui.wizard.step_page import StepPage
from tunespec.app.gui.workers import Worker

__all__ = ["CalibratePage"]

CORNER_CHOICES = (
    ("found automatically in the images", "auto"),
    ("as set in the target-layout editor", "editor"),
)


def _methods() -> tuple[tuple[str, ...], str]:
    """The sensitivity methods and the library's default one."""
    from tunespec.app.pipeline.jobs import sensitivity_methods

    return sensitivity_methods()


class CalibratePage(StepPage):
    """Processes the chart session and estimates the sensitivities; shows Table 1
    with a pass/fail verdict on its RGB mean."""

    key = "calibrate"
    inputs = ("dark", "white", "target")
    produces = "calibration"

    step_title = "Calibrate"
    step_description = (
        "The chart frames are dark-corrected and flat-fielded, the patches "
        "located, and the camera sensitivities estimated. Table 1 compares the "
        "captured responses with those the sensitivities predict (Eq. 1)."
    )
    step_start_text = "Calibrate"
    step_retake_text = "Recalibrate"

    def __init__(self, measurement: Any, parent: QWidget | None = None) -> None:
        super().__init__(measurement)
        m = measurement
        self.corners_combo = QComboBox()
        for label, value in CORNER_CHOICES:
            self.corners_combo.addItem(label, value)
        self.method_combo = QComboBox()
        methods, default = _methods()
        for method in methods:
            label = f"{method} (default)" if method == default else method
            self.method_combo.addItem(label, method)
        i = self.method_combo.findData(m.method or default)
        self.method_combo.setCurrentIndex(max(0, i))
        self.threshold_spin = QDoubleSpinBox(
            decimals=4,
            minimum=0.0001,
            maximum=0.1,
            singleStep=0.0005,
            value=m.threshold,
        )
        self.threshold_spin.setToolTip(
            "Pass if Table 1's RGB mean error is at most this"
        )
        form = QFormLayout()
        form.addRow("Chart corners", self.corners_combo)
        form.addRow("Method", self.method_combo)
        form.addRow("Pass if RGB mean ≤", self.threshold_spin)
        self.body.addLayout(form)
        self.table_panel = table1_panel()
        self.body.addWidget(self.table_panel, 1)
        m.calibrated.connect(self._on_measurement_calibrated)
        m.result_cleared.connect(self._on_measurement_result_cleared)
        m.folder_changed.connect(self._on_measurement_folder_changed)

    def refresh(self) -> None:
        """The editor shows the chart."""
        self.measurement.edit_target("chart")

    def can_start(self) -> str | None:
        """The chart session must be complete."""
        if not self.measurement.phase_complete("chart", None):
            return "Take the dark, white and chart frames first (steps 2-4)."
        return None

    def make_job(self) -> Worker:
        """A pool worker processing the chart and estimating the sensitivities."""
        m = self.measurement
        m.method = self.method_combo.currentData()
        m.threshold = self.threshold_spin.value()
        m.save()
        from tunespec.app.pipeline.jobs import CalibrateInputs, calibrate_job

        return ProcessWorker(
            calibrate_job,
            CalibrateInputs(
                m.path(CHART_DIR),
                m.path(CALIBRATION_DIR),
                m.chart_layout,
                corners=self.corners_combo.currentData(),
                method=m.method,
                threshold=m.threshold,
            ),
        )

    def accept_result(self, result: CalibrationResult) -> str:
        """Store the calibration, show Table 1 and the found corners."""
        m = self.measurement
        m.calibration = result
        m.chart_layout = result.layout
        m.save()
        m.layout_needed.emit(result.layout)
        m.calibrated.emit(result)
        outcome, why = result.verdict_reason
        text = (
            f"{outcome}: {why}; {result.table1.n_stimuli} stimuli, "
            f"{result.elapsed_s:.1f} s."
        )
        if outcome == "FAIL":
            text += " Check the corners and the saturation, then recalibrate."
        return text  # the warnings are in the page's badge

    def restore(self) -> bool:
        """Done if the measurement folder holds a calibration."""
        result = self.measurement.restore_calibration()
        if result is None:
            return False
        self.mark_done(
            f"Calibration restored: RGB mean error {result.rgb_mean:.4f} "
            f"({result.verdict}).",
            result,
        )
        return True

    def _on_measurement_calibrated(self, result: CalibrationResult) -> None:
        show_table1(self.table_panel, result)

    def _on_measurement_result_cleared(self, which: str) -> None:
        if which == "calibration":
            self.table_panel.clear_table("Not calibrated yet.")

    def _on_measurement_folder_changed(self, _folder: object) -> None:
        # the method and threshold of the measurement opened, not of the last one
        m = self.measurement
        i = self.method_combo.findData(m.method or _methods()[1])
        self.method_combo.setCurrentIndex(max(0, i))
        self.threshold_spin.setValue(m.threshold)
