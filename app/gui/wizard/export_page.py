"""Wizard step 8: write the exports and the report."""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import QUrl, Slot
from PySide6.QtGui import QDesktopServices
from PySide6.QtWidgets import QListWidget, QPushButton, QWidget

from tunespec.app.gui.processes import ProcessWorker
from tunespec.app.gui.wizard.measurement import (
    EXPORT_DIR,
    ExportResult,
)
from tunespec.app.gui.wizard.step_page import StepPage
from tunespec.app.gui.workers import Worker

__all__ = ["ExportPage"]


class ExportPage(StepPage):
    """Writes sensitivities, reflectances, responses, Tables 1-2 and the report."""

    key = "export"
    inputs = ("calibrate", "estimate")
    produces = "export"

    step_title = "Export"
    step_description = (
        "Writes the sensitivities (CSV, rawtoaces JSON), the reflectances (CSV, "
        "CGATS .ti3), the responses, Tables 1 and 2 and an HTML/PDF report into "
        "the measurement's <i>export</i> folder."
    )
    step_start_text = "Export"
    step_retake_text = "Export again"

    def __init__(self, measurement: Any, parent: QWidget | None = None) -> None:
        super().__init__(measurement)
        self.files_list = QListWidget()
        self.open_button = QPushButton("Open the folder")
        self.open_button.setEnabled(False)
        self.body.addWidget(self.files_list, 1)
        self.body.addWidget(self.open_button)
        self.open_button.clicked.connect(self._on_open_button_clicked)
        measurement.result_cleared.connect(self._on_measurement_result_cleared)

    def can_start(self) -> str | None:
        """Needs the calibration and the estimate."""
        m = self.measurement
        if m.calibration is None or m.estimate is None:
            return "Calibrate and estimate first (steps 5 and 7)."
        return None

    def make_job(self) -> Worker:
        """A pool worker writing the exports."""
        m = self.measurement
        session = m.session("sample") or m.session("chart")
        devices = session.devices if session is not None else {}
        simulated = devices.get("light", {}).get("vendor") == "TuneSpec"
        sim = m.sim_options if simulated else {}
        provenance = {
            k: str(v) if k != "resolution" else "x".join(map(str, v))
            for k, v in sim.items()
            if k in ("seed", "resolution")
        }
        from tunespec.app.pipeline.jobs import ExportInputs, export_job

        return ProcessWorker(
            export_job,
            ExportInputs(
                m.path(EXPORT_DIR),
                m.require_folder(),
                m.calibration,
                m.estimate,
                devices,
                provenance=provenance,
                input_files=tuple(p for p in (m.reference_path,) if p is not None),
            ),
        )

    def accept_result(self, result: ExportResult) -> str:
        """List the files written."""
        self.measurement.export = result
        self._show_files(result)
        return f"{len(result.paths)} file(s) written to {result.folder}."

    def restore(self) -> bool:
        """Done if the exports are on disk."""
        if self.measurement.estimate is None:
            return False
        result = self.measurement.restore_export()
        if result is None:
            return False
        self._show_files(result)
        self.mark_done(f"Exports restored from {result.folder}.", result)
        return True

    def _show_files(self, result: ExportResult) -> None:
        self.files_list.clear()
        self.files_list.addItems([p.name for p in result.paths.values()])
        self.open_button.setEnabled(result.folder is not None)

    def _on_measurement_result_cleared(self, which: str) -> None:
        if which == "export":
            self.files_list.clear()
            self.open_button.setEnabled(False)

    @Slot()
    def _on_open_button_clicked(self) -> None:
        folder = self.measurement.export.folder if self.measurement.export else None
        if folder is not None:
            QDesktopServices.openUrl(QUrl.fromLocalFile(str(folder)))
