"""The gonio run view: run a plan, watch it geometry by geometry, see the result.

A plan (a file from Edit > Gonio plan…, or the default in-plane scan) runs on the
simulated gonio bench or on devices by spec, as ``tunespec gonio-demo`` /
``gonio-run`` do (:func:`tunespec.app.pipeline.gonio_view.run_gonio_plan`, in a
process of its own: :class:`~tunespec.app.gui.processes.ProcessWorker`). The table
has a row per geometry (angles, spectral or fused, HDR) whose frames column counts
what is on disk (:func:`~tunespec.app.pipeline.gonio_view.geometry_progress`, read
a few times a second: the live progress); a failure marks the geometry it names.
When done, the selected geometry's spectrum of the chosen patch is plotted with its
95 % band (+-1.96 u), and L*, a*, b* of that patch against theta_r with error bars
(+-1.96 u) for the geometries in the plane of incidence.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QTimer, Signal, Slot
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QComboBox,
    QFileDialog,
    QFormLayout,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QSpinBox,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from tunespec.app.gui.processes import ProcessWorker
from tunespec.core.intervals import COVERAGE_FACTOR_95

__all__ = ["COLUMNS", "GonioPanel"]

#: The geometry table's columns.
COLUMNS = ("#", "theta_i", "theta_r", "phi_r", "kind", "HDR", "frames", "state")
#: Where a message names a geometry (gonio_process.geometry_label, gonio._naming_geometry).
_GEOMETRY_RE = re.compile(r"geometry (\d+)")
#: L*, a*, b* pens.
_LAB_PENS = {"L*": "k", "a*": (200, 0, 0), "b*": (0, 90, 220)}


class GonioPanel(QWidget):
    """Run a gonio plan with live progress per geometry and show its fused result.

    ``finished(ok)`` when a run ends. :attr:`result` holds the last result
    (:func:`~tunespec.app.pipeline.gonio_view.load_gonio_result`).
    """

    finished = Signal(bool)

    #: The worker the run goes to (a process: the fusion is Python bytecode).
    worker_class: Any = ProcessWorker

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.worker: Any = None
        self.result: dict[str, Any] | None = None
        self.failed_geometry: int | None = None

        self.folder_edit = QLineEdit()
        self.folder_edit.setPlaceholderText("session folder (a started one resumes)")
        self.folder_button = QPushButton("…")
        self.plan_edit = QLineEdit()
        self.plan_edit.setPlaceholderText("empty: the default in-plane scan")
        self.plan_button = QPushButton("…")
        self.n_spin = QSpinBox()
        self.n_spin.setRange(4, 14)
        self.n_spin.setValue(14)
        self.n_spin.setToolTip(
            "geometries of the default plan (gonio-demo --geometries)"
        )
        self.bench_combo = QComboBox()
        self.bench_combo.addItems(["Simulated gonio bench", "Devices"])
        self.light_edit = QLineEdit("sim")
        self.camera_edit = QLineEdit("sim")
        self.gonio_edit = QLineEdit("sim")
        self.gonio_edit.setToolTip(
            "sim | zaber:///dev/ttyUSB0 | zaber+socket://HOST:PORT"
        )
        self.sens_edit = QLineEdit()
        self.sens_edit.setPlaceholderText("calibration CSV (tunespec calibrate)")
        self.layout_edit = QLineEdit()
        self.layout_edit.setPlaceholderText("sample target layout JSON")
        self.run_button = QPushButton("Run")
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.setEnabled(False)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.status = QLabel("Choose a session folder and run the plan.")
        self.status.setWordWrap(True)

        form = QFormLayout()
        row = QHBoxLayout()
        row.addWidget(self.folder_edit)
        row.addWidget(self.folder_button)
        form.addRow("Session folder", row)
        row = QHBoxLayout()
        row.addWidget(self.plan_edit)
        row.addWidget(self.plan_button)
        row.addWidget(QLabel("default plan geometries"))
        row.addWidget(self.n_spin)
        form.addRow("Plan", row)
        form.addRow("Run on", self.bench_combo)
        self.device_rows = QWidget()
        dev = QFormLayout(self.device_rows)
        dev.setContentsMargins(0, 0, 0, 0)
        dev.addRow("Light", self.light_edit)
        dev.addRow("Camera", self.camera_edit)
        dev.addRow("Goniometer", self.gonio_edit)
        dev.addRow("Sensitivities", self.sens_edit)
        dev.addRow("Layout", self.layout_edit)
        self.device_rows.hide()
        form.addRow(self.device_rows)
        buttons = QHBoxLayout()
        buttons.addWidget(self.run_button)
        buttons.addWidget(self.cancel_button)
        buttons.addWidget(self.progress, 1)

        self.table = QTableWidget(0, len(COLUMNS))
        self.table.setHorizontalHeaderLabels(COLUMNS)
        self.table.verticalHeader().hide()
        self.table.setSelectionBehavior(QTableWidget.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QTableWidget.SelectionMode.SingleSelection)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.table.horizontalHeader().setStretchLastSection(True)

        self.patch_combo = QComboBox()
        self._build_plots()
        self._lay_out(form, buttons)
        self._connect()

    def _build_plots(self) -> None:
        self.spectrum_plot = pg.PlotWidget(background="w")
        self.spectrum_plot.showGrid(x=True, y=True, alpha=0.25)
        self.spectrum_plot.getAxis("bottom").enableAutoSIPrefix(False)
        self.spectrum_plot.setLabel("bottom", "wavelength", units="nm")
        self.spectrum_plot.getAxis("left").enableAutoSIPrefix(False)
        self.spectrum_plot.setLabel("left", "reflectance factor")
        self.spectrum_plot.setXRange(380.0, 730.0, padding=0.02)
        self.spectrum_plot.setYRange(0.0, 1.0, padding=0.02)
        self.spectrum_curve = self.spectrum_plot.plot(pen=pg.mkPen("k", width=2))
        self.spectrum_upper = self.spectrum_plot.plot(pen=pg.mkPen(None))
        self.spectrum_lower = self.spectrum_plot.plot(pen=pg.mkPen(None))
        self.spectrum_plot.addItem(
            pg.FillBetweenItem(
                self.spectrum_lower, self.spectrum_upper, brush=(100, 100, 255, 70)
            )
        )
        self.lab_plot = pg.PlotWidget(background="w")
        self.lab_plot.showGrid(x=True, y=True, alpha=0.25)
        self.lab_plot.getAxis("bottom").enableAutoSIPrefix(False)
        self.lab_plot.setLabel("bottom", "theta_r (deg), plane of incidence")
        self.lab_plot.getAxis("left").enableAutoSIPrefix(False)
        self.lab_plot.setLabel("left", "CIELAB (D50)")
        self.lab_plot.setXRange(0.0, 70.0, padding=0.02)
        self.lab_plot.setYRange(-50.0, 100.0, padding=0.02)
        self.lab_plot.addLegend(offset=(-10, 10))
        self.lab_curves: dict[str, Any] = {}
        self.lab_bars: dict[str, Any] = {}
        for name, colour in _LAB_PENS.items():
            pen = pg.mkPen(colour, width=2)
            self.lab_curves[name] = self.lab_plot.plot(
                pen=pen, symbol="o", symbolSize=6, symbolBrush=colour, name=name
            )
            self.lab_bars[name] = pg.ErrorBarItem(beam=1.0, pen=pen)
            self.lab_plot.addItem(self.lab_bars[name])
        self.result_label = QLabel("")
        self.result_label.setWordWrap(True)
        self.legend_label = QLabel(
            "spectrum: reflectance factor of the selected geometry with its 95 % band "
            "(±1.96 u); L*a*b*: bars ±1.96 u"
        )

    def _lay_out(self, form: QFormLayout, buttons: QHBoxLayout) -> None:
        plots = QHBoxLayout()
        plots.addWidget(self.spectrum_plot, 1)
        plots.addWidget(self.lab_plot, 1)
        patch_row = QHBoxLayout()
        patch_row.addWidget(QLabel("Patch"))
        patch_row.addWidget(self.patch_combo)
        patch_row.addWidget(self.result_label, 1)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addLayout(buttons)
        layout.addWidget(self.status)
        layout.addWidget(self.table, 2)
        layout.addLayout(patch_row)
        layout.addLayout(plots, 3)
        layout.addWidget(self.legend_label)

    def _connect(self) -> None:
        self.poll_timer = QTimer(self)
        self.poll_timer.setInterval(300)
        self.poll_timer.timeout.connect(self._on_poll_timer_timeout)
        self.run_button.clicked.connect(self._on_run_button_clicked)
        self.cancel_button.clicked.connect(self._on_cancel_button_clicked)
        self.folder_button.clicked.connect(self._on_folder_button_clicked)
        self.plan_button.clicked.connect(self._on_plan_button_clicked)
        self.bench_combo.currentIndexChanged.connect(self._on_bench_combo_changed)
        self.patch_combo.currentIndexChanged.connect(self._on_selection_changed)
        self.table.itemSelectionChanged.connect(self._on_selection_changed)

    # -- running ---------------------------------------------------------------------
    def start(self, folder: str | Path | None = None) -> Any:
        """Run (or resume) the session in ``folder`` (else the folder field)."""
        from tunespec.app.pipeline.gonio_view import DeviceSpecs, run_gonio_plan

        if folder is not None:
            self.folder_edit.setText(str(folder))
        text = self.folder_edit.text().strip()
        if not text:
            self.status.setText("Choose a session folder first.")
            return None
        devices = None
        if self.bench_combo.currentIndex() == 1:
            fields = (self.light_edit, self.camera_edit, self.gonio_edit,
                      self.sens_edit, self.layout_edit)  # fmt: skip
            values = [f.text().strip() for f in fields]
            if not all(values):
                self.status.setText(
                    "Devices need the light, camera and goniometer specs, the "
                    "sensitivities and the layout."
                )
                return None
            devices = DeviceSpecs(*values)
        plan = self.plan_edit.text().strip() or None
        self.result, self.failed_geometry = None, None
        self.folder = Path(text)
        self.worker = self.worker_class(
            run_gonio_plan, self.folder, plan=plan, n_geometries=self.n_spin.value(),
            devices=devices,
        )  # fmt: skip
        self.worker.signals.progressed.connect(self._on_worker_progressed)
        self.worker.signals.returned.connect(self._on_worker_returned)
        self.worker.signals.errored.connect(self._on_worker_errored)
        self.worker.signals.finished.connect(self._on_worker_finished)
        self.run_button.setEnabled(False)
        self.cancel_button.setEnabled(True)
        self.progress.setValue(0)
        self.status.setText(f"running the plan in {self.folder} …")
        self.poll_timer.start()
        return self.worker.start()

    @property
    def running(self) -> bool:
        return self.worker is not None

    def refresh_geometries(self) -> None:
        """The table's rows and frame counts from the session on disk."""
        from tunespec.app.pipeline.gonio import GonioPlan
        from tunespec.app.pipeline.gonio_view import geometry_progress

        folder = getattr(self, "folder", None)
        if folder is None or not (folder / "plan.json").exists():
            return
        try:
            counts = geometry_progress(folder)
            plan = GonioPlan.load(folder / "plan.json")
        except Exception as exc:  # a file half-written elsewhere: next tick
            self.status.setText(f"cannot read the session: {exc}")
            return
        if counts is None:
            return
        if self.table.rowCount() != len(plan.steps):
            self.table.setRowCount(len(plan.steps))
        for i, (step, (have, total)) in enumerate(zip(plan.steps, counts, strict=True)):
            g = step.geometry
            if i == self.failed_geometry:
                state = "failed"
            elif self.result is not None:
                state = "spectral" if step.spectral else "fused"
            elif have == total:
                state = "captured"
            else:
                state = "capturing" if have else "waiting"
            values = (i + 1, f"{g.theta_i:g}", f"{g.theta_r:g}", f"{g.phi_r:g}",
                      "spectral" if step.spectral else "single shot",
                      "yes" if step.hdr else "", f"{have}/{total}", state)  # fmt: skip
            for c, v in enumerate(values):
                item = self.table.item(i, c)
                if item is None:
                    item = QTableWidgetItem()
                    self.table.setItem(i, c, item)
                if item.text() != str(v):
                    item.setText(str(v))
                colour = (
                    QColor(255, 200, 200) if state == "failed" else QColor(0, 0, 0, 0)
                )
                item.setBackground(QBrush(colour))

    def geometry_state(self, index: int) -> str:
        """The state column of geometry ``index`` (0-based)."""
        item = self.table.item(index, COLUMNS.index("state"))
        return "" if item is None else item.text()

    # -- the result ------------------------------------------------------------------
    def show_result(self, result: dict[str, Any]) -> None:
        """Show a :func:`~tunespec.app.pipeline.gonio_view.load_gonio_result`."""
        self.result = result
        self.patch_combo.blockSignals(True)
        self.patch_combo.clear()
        self.patch_combo.addItems(result["patches"])
        self.patch_combo.blockSignals(False)
        self.refresh_geometries()
        for plot in (self.spectrum_plot, self.lab_plot):  # from the empty ranges
            plot.enableAutoRange()
        if self.table.rowCount() and not self.table.selectedItems():
            self.table.selectRow(0)
        self._on_selection_changed()

    def selected_geometry(self) -> int:
        rows = {i.row() for i in self.table.selectedItems()}
        return min(rows) if rows else 0

    def lab_series(self, patch: int) -> dict[str, np.ndarray]:
        """theta_r, L*a*b* and their bars (1.96 u) of a patch at the in-plane
        geometries (phi_r 180), by theta_r."""
        r = self.result
        assert r is not None
        idx = np.flatnonzero(np.isclose(np.abs(r["phi_r"]), 180.0, atol=0.5))
        idx = idx[np.argsort(r["theta_r"][idx], kind="stable")]
        return {
            "geometry": idx,
            "theta_r": r["theta_r"][idx],
            "lab": r["lab"][patch, idx],
            "bar": COVERAGE_FACTOR_95 * r["u_lab"][patch, idx],
        }

    @Slot()
    def _on_selection_changed(self, *_args: Any) -> None:
        r = self.result
        if r is None or not r["patches"]:
            return
        p = max(0, self.patch_combo.currentIndex())
        g = self.selected_geometry()
        wl = r["wavelength_nm"]
        R, u = r["reflectance"][p, g], r["u_reflectance"][p, g]
        self.spectrum_curve.setData(wl, R)
        self.spectrum_upper.setData(wl, R + COVERAGE_FACTOR_95 * u)
        self.spectrum_lower.setData(wl, R - COVERAGE_FACTOR_95 * u)
        self.spectrum_plot.setTitle(
            f"{r['patches'][p]}, geometry {g + 1} (theta_i {r['theta_i'][g]:.3g}, "
            f"theta_r {r['theta_r'][g]:.3g}, phi_r {r['phi_r'][g]:.3g}): "
            + ("spectral" if r["spectral"][g] else "fused")
        )
        s = self.lab_series(p)
        for k, name in enumerate(_LAB_PENS):
            y, bar = s["lab"][:, k], s["bar"][:, k]
            self.lab_curves[name].setData(s["theta_r"], y)
            self.lab_bars[name].setData(x=s["theta_r"], y=y, height=2 * bar)
        L, a, b = r["lab"][p, g]
        uL, ua, ub = r["u_lab"][p, g]
        self.result_label.setText(
            f"geometry {g + 1}: L*a*b* {L:.2f} ± {uL:.2f}, {a:.2f} ± {ua:.2f}, "
            f"{b:.2f} ± {ub:.2f} (u, k = 1)"
        )

    # -- slots -------------------------------------------------------------------------
    @Slot()
    def _on_run_button_clicked(self) -> None:
        self.start()

    @Slot()
    def _on_cancel_button_clicked(self) -> None:
        if self.worker is not None:
            self.worker.abort()
            self.status.setText("cancelling … (the frames taken stay: Run resumes)")

    @Slot()
    def _on_folder_button_clicked(self) -> None:
        folder = QFileDialog.getExistingDirectory(self, "Gonio session folder")
        if folder:
            self.folder_edit.setText(folder)

    @Slot()
    def _on_plan_button_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self, "Gonio plan", "", "Gonio plan (*.json)"
        )
        if path:
            self.plan_edit.setText(path)

    @Slot(int)
    def _on_bench_combo_changed(self, index: int) -> None:
        self.device_rows.setVisible(index == 1)
        self.n_spin.setEnabled(index == 0)

    @Slot()
    def _on_poll_timer_timeout(self) -> None:
        self.refresh_geometries()

    @Slot(float)
    def _on_worker_progressed(self, fraction: float) -> None:
        self.progress.setValue(round(1000 * fraction))

    @Slot(object)
    def _on_worker_returned(self, result: object) -> None:
        self.progress.setValue(1000)
        assert isinstance(result, dict)
        self.show_result(result)
        n = len(result["spectral"])
        said = "".join(f"\nwarning: {w}" for w in result["warnings"])
        self.status.setText(
            f"done: {n} geometries ({int(np.sum(result['spectral']))} spectral, the "
            f"others fused) in {self.folder}{said}"
        )

    @Slot(object)
    def _on_worker_errored(self, exc: object) -> None:
        from tunespec.core.progress import Cancelled

        if isinstance(exc, Cancelled):
            self.status.setText("cancelled: the frames taken stay, Run resumes")
            return
        m = _GEOMETRY_RE.search(str(exc))
        self.failed_geometry = int(m.group(1)) - 1 if m else None
        self.status.setText(f"gonio run failed: {exc}")

    @Slot()
    def _on_worker_finished(self) -> None:
        ok = self.result is not None
        self.poll_timer.stop()
        self.refresh_geometries()
        self.run_button.setEnabled(True)
        self.cancel_button.setEnabled(False)
        self.worker = None
        self.finished.emit(ok)
