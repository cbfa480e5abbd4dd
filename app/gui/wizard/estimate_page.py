"""Wizard step 7: estimate the sample's reflectances (Wiener) and Table 2."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from PySide6.QtCore import Slot
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLineEdit,
    QPushButton,
    QWidget,
)

from tunespec.app.gui.panels.stats_table_panel import show_table2, table2_panel
from tunespec.app.gui.processes import ProcessWorker
from tunespec.app.gui.wizard.calibrate_page import CORNER_CHOICES
from tunespec.app.gui.wizard.measurement import (
    ESTIMATE_DIR,
    SAMPLE_DIR,
    EstimateResult,
)
from tunespec.app.gui.wizard.step_page import StepPage
from tunespec.app.gui.workers import Worker

__all__ = ["EstimatePage"]


class EstimatePage(StepPage):
    """Estimates reflectances from the sample's responses; Table 2 when references
    (a spectral CSV named by patch) are given."""

    key = "estimate"
    inputs = ("calibrate", "sample")
    produces = "estimate"

    step_title = "Estimate reflectances"
    step_description = (
        "The sample frames are processed like the chart, and each patch's "
        "reflectance is estimated from its responses under all LEDs (Wiener, "
        "Eq. 5-6). Give reference reflectances to see Table 2."
    )
    step_start_text = "Estimate"
    step_retake_text = "Estimate again"

    def __init__(self, measurement: Any, parent: QWidget | None = None) -> None:
        super().__init__(measurement)
        m = measurement
        self.reference_edit = QLineEdit(str(m.reference_path or ""))
        self.reference_edit.setPlaceholderText(
            "reference CSV (the simulated bench uses its true reflectances)"
        )
        self.reference_button = QPushButton("Browse…")
        self.corners_combo = QComboBox()
        for label, value in CORNER_CHOICES:
            self.corners_combo.addItem(label, value)
        row = QHBoxLayout()
        row.addWidget(self.reference_edit, 1)
        row.addWidget(self.reference_button)
        form = QFormLayout()
        form.addRow("References", row)
        form.addRow("Sample corners", self.corners_combo)
        self.body.addLayout(form)
        self.table_panel = table2_panel()
        self.body.addWidget(self.table_panel, 1)
        self.reference_button.clicked.connect(self._on_reference_button_clicked)
        m.estimated.connect(self._on_measurement_estimated)
        m.result_cleared.connect(self._on_measurement_result_cleared)
        m.folder_changed.connect(self._on_measurement_folder_changed)

    def refresh(self) -> None:
        """The editor shows the sample."""
        self.measurement.edit_target("sample")

    def can_start(self) -> str | None:
        """Needs a calibration and a complete sample session."""
        m = self.measurement
        if m.calibration is None:
            return "Calibrate first (step 5)."
        if not m.phase_complete("sample", None):
            return "Capture the sample first (step 6)."
        return None

    def make_job(self) -> Worker:
        """A pool worker processing the sample and estimating reflectances."""
        m = self.measurement
        text = self.reference_edit.text().strip()
        m.reference_path = Path(text) if text else None
        m.save()
        from tunespec.app.pipeline.jobs import EstimateInputs, estimate_job

        return ProcessWorker(
            estimate_job,
            EstimateInputs(
                m.path(SAMPLE_DIR),
                m.path(ESTIMATE_DIR),
                m.calibration.sensitivity,
                m.sample_layout,
                corners=self.corners_combo.currentData(),
                reference=m.reference(),
                calibration=getattr(m.calibration.calibration, "estimate", None),
            ),
        )

    def accept_result(self, result: EstimateResult) -> str:
        """Store the estimate; show Table 2."""
        m = self.measurement
        m.estimate = result
        if result.layout is not None:
            m.sample_layout = result.layout
            m.save()
            m.layout_needed.emit(result.layout)
        m.estimated.emit(result)
        n = len(result.reflectance.names)
        text = f"{n} reflectance(s) estimated in {result.elapsed_s:.1f} s."
        t = result.table2
        if t is not None:
            text += (
                f" Table 2: average CIEDE2000 {t.mean_delta_e00:.2f}, spectral RMS "
                f"{t.mean_spectral_rms:.4f}."
            )
        if result.clipped:
            text += f" {len(result.clipped)} estimate(s) clipped to 0..1."
        return text

    def restore(self) -> bool:
        """Done if the measurement folder holds an estimate."""
        if self.measurement.calibration is None:
            return False
        result = self.measurement.restore_estimate()
        if result is None:
            return False
        self.mark_done(
            f"Estimate restored: {len(result.reflectance.names)} patches.", result
        )
        return True

    @Slot()
    def _on_reference_button_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self, "Reference reflectances", "", "Spectral CSV (*.csv)"
        )
        if path:
            self.reference_edit.setText(path)

    def _on_measurement_estimated(self, result: EstimateResult) -> None:
        show_table2(self.table_panel, result)

    def _on_measurement_result_cleared(self, which: str) -> None:
        if which == "estimate":
            self.table_panel.clear_table("Not estimated yet.")

    def _on_measurement_folder_changed(self, _folder: object) -> None:
        # the references of the measurement opened (make_job stores the field's text)
        self.reference_edit.setText(str(self.measurement.reference_path or ""))
