"""Edit a gonio session's geometry list: the plan JSON that ``gonio-demo --plan`` reads.

One row per geometry: incidence and viewing angles (theta_i, phi_i, theta_r, phi_r,
degrees), a full 22-LED spectral capture or not, HDR brackets or not
(:data:`~tunespec.app.pipeline.gonio.HDR_EXPOSURES`), plus the session's single-shot
mix. The editor holds no rules of its own: every edit rebuilds the plan document and
hands it to :meth:`GonioPlan.from_dict`, the validator the CLI uses, so the GUI
accepts exactly what the command line accepts. An invalid entry is marked in the
table and its one-line message shown under it; Save and OK stay disabled until it
is fixed.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path
from typing import Any

from PySide6.QtCore import Qt, Signal, Slot
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFileDialog,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from tunespec.app.pipeline.gonio import (
    HDR_EXPOSURES,
    MIX_KINDS,
    GeometryStep,
    GonioPlan,
    default_plan,
)
from tunespec.core.errors import TuneSpecError
from tunespec.devices.goniometer import ANGLE_AXES, Geometry

__all__ = ["COLUMNS", "GonioPlanEditor"]

#: Table columns: the four angles, then the two flags.
COLUMNS = (*ANGLE_AXES, "spectral", "hdr")
_HEADERS = ("θi (°)", "φi (°)", "θr (°)", "φr (°)", "22-LED spectral",
            f"HDR ({len(HDR_EXPOSURES)} brackets)")  # fmt: skip
_BAD = QBrush(QColor(255, 190, 190))
_ROW = re.compile(r"geometries\[(\d+)\](?:\.(\w+))?")


class GonioPlanEditor(QDialog):
    """A dialog editing a :class:`GonioPlan` (default: the 14-geometry default plan).

    ``plan()`` is the current plan, or None while an entry is invalid (then
    ``error_label`` says which row and what is expected).
    """

    plan_changed = Signal(object)

    def __init__(
        self, plan: GonioPlan | None = None, parent: QWidget | None = None
    ) -> None:
        super().__init__(parent)
        self.setWindowTitle("Gonio plan")
        self._plan: GonioPlan | None = None
        self._leds: tuple[str, ...] = ()
        self._loading = False
        self.path: Path | None = None
        self.table = QTableWidget(0, len(COLUMNS), self)
        self.table.setHorizontalHeaderLabels(list(_HEADERS))
        self.table.horizontalHeader().setSectionResizeMode(
            QHeaderView.ResizeMode.ResizeToContents
        )
        self.table.horizontalHeader().setStretchLastSection(True)
        self.mix_combo = QComboBox(self)
        self.mix_combo.addItems(list(MIX_KINDS))
        self.mix_combo.setToolTip(
            "single-shot LED mix: d50 = plain D50 match, camera = tuned for the "
            "calibrated camera (D50 chromaticity kept)"
        )
        self.add_button = QPushButton("&Add geometry", self)
        self.remove_button = QPushButton("&Remove", self)
        self.load_button = QPushButton("&Load…", self)
        self.save_button = QPushButton("&Save…", self)
        self.error_label = QLabel(self)
        self.error_label.setObjectName("gonioPlanError")
        self.error_label.setStyleSheet("color: #c00000")
        self.error_label.setWordWrap(True)
        self.summary_label = QLabel(self)
        self.buttons = QDialogButtonBox(
            QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel,
            self,
        )
        self._build_layout()
        self.table.itemChanged.connect(self._on_table_item_changed)
        self.mix_combo.currentTextChanged.connect(self._on_mix_combo_changed)
        self.add_button.clicked.connect(self._on_add_button_clicked)
        self.remove_button.clicked.connect(self._on_remove_button_clicked)
        self.load_button.clicked.connect(self._on_load_button_clicked)
        self.save_button.clicked.connect(self._on_save_button_clicked)
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)
        self.set_plan(plan if plan is not None else default_plan())

    def _build_layout(self) -> None:
        row = QHBoxLayout()
        for w in (self.add_button, self.remove_button):
            row.addWidget(w)
        row.addStretch(1)
        row.addWidget(QLabel("Single-shot mix:", self))
        row.addWidget(self.mix_combo)
        row.addStretch(1)
        for w in (self.load_button, self.save_button):
            row.addWidget(w)
        box = QVBoxLayout(self)
        box.addLayout(row)
        box.addWidget(self.table, 1)
        box.addWidget(self.error_label)
        box.addWidget(self.summary_label)
        box.addWidget(self.buttons)
        self.resize(720, 520)

    # -- model ------------------------------------------------------------------------
    def plan(self) -> GonioPlan | None:
        """The plan as edited, or None while an entry is invalid."""
        return self._plan

    def set_plan(self, plan: GonioPlan) -> None:
        """Show ``plan`` (its LED channel list is kept as it is)."""
        self._loading = True
        try:
            self._leds = plan.leds
            self.table.setRowCount(0)
            for step in plan.steps:
                self._append_row(step)
            self.mix_combo.setCurrentText(plan.mix)
        finally:
            self._loading = False
        self._revalidate()

    def load(self, path: str | Path) -> None:
        """Read a plan JSON (the CLI's validator); raises InputError on a bad file."""
        self.set_plan(GonioPlan.load(path))
        self.path = Path(path)

    def save(self, path: str | Path) -> None:
        """Write the plan JSON; raises InputError while an entry is invalid."""
        from tunespec.core.errors import InputError

        if self._plan is None:
            raise InputError(f"the plan is not valid: {self.error_label.text()}")
        self._plan.save(path)
        self.path = Path(path)

    def document(self) -> dict[str, Any]:
        """The plan document the table shows (what :meth:`GonioPlan.from_dict` gets)."""
        rows = []
        for r in range(self.table.rowCount()):
            row: dict[str, Any] = {}
            for c, key in enumerate(COLUMNS):
                item = self.table.item(r, c)
                if key in ANGLE_AXES:
                    row[key] = _number(item.text() if item is not None else "")
                else:
                    checked = item is not None and item.checkState()
                    row[key] = checked == Qt.CheckState.Checked
            rows.append(row)
        return {
            "format": "tunespec-gonio-plan",
            "version": 1,
            "geometries": rows,
            "leds": list(self._leds),
            "mix": self.mix_combo.currentText(),
        }

    def _append_row(self, step: GeometryStep) -> None:
        r = self.table.rowCount()
        self.table.insertRow(r)
        for c, value in enumerate(step.geometry.as_dict().values()):
            self.table.setItem(r, c, QTableWidgetItem(f"{value:g}"))
        for c, flag in ((4, step.spectral), (5, step.hdr)):
            item = QTableWidgetItem()
            item.setFlags(
                Qt.ItemFlag.ItemIsUserCheckable
                | Qt.ItemFlag.ItemIsEnabled
                | Qt.ItemFlag.ItemIsSelectable
            )
            item.setCheckState(
                Qt.CheckState.Checked if flag else Qt.CheckState.Unchecked
            )
            self.table.setItem(r, c, item)

    def _revalidate(self) -> None:
        """Rebuild the plan through the CLI's validator; mark what it rejects."""
        self._loading = True
        try:
            for r in range(self.table.rowCount()):
                for c in range(len(COLUMNS)):
                    item = self.table.item(r, c)
                    if item is not None:
                        item.setBackground(QBrush())
            try:
                plan = GonioPlan.from_dict(self.document())
            except TuneSpecError as exc:
                plan = None
                self._mark(str(getattr(exc, "message", exc)))
        finally:
            self._loading = False
        self._plan = plan
        ok = plan is not None
        self.summary_label.clear()
        if ok:
            self.error_label.clear()
            n_s = sum(s.spectral for s in plan.steps)
            n_h = sum(s.hdr for s in plan.steps)
            self.summary_label.setText(
                f"{len(plan.steps)} geometries, {n_s} with the full 22-LED capture, "
                f"{n_h} with HDR brackets; {plan.mix} mix"
            )
        self.save_button.setEnabled(ok)
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setEnabled(ok)
        self.plan_changed.emit(plan)

    def _mark(self, message: str) -> None:
        """Show the validator's message, naming the row, and colour the entry."""
        m = _ROW.search(message)
        if m is None:
            self.error_label.setText(message)
            return
        r = int(m.group(1))
        key = m.group(2) or next(
            (a for a in COLUMNS if re.search(rf"\b{a}\b", message)), None
        )
        cols = [COLUMNS.index(key)] if key in COLUMNS else range(len(COLUMNS))
        for c in cols:
            item = self.table.item(r, c)
            if item is not None:
                item.setBackground(_BAD)
        rest = message[m.end() :].lstrip(":. ")
        self.error_label.setText(f"Row {r + 1}: {rest}")

    # -- slots ------------------------------------------------------------------------
    @Slot(QTableWidgetItem)
    def _on_table_item_changed(self, _item: QTableWidgetItem) -> None:
        if not self._loading:
            self._revalidate()

    @Slot(str)
    def _on_mix_combo_changed(self, _text: str) -> None:
        if not self._loading:
            self._revalidate()

    @Slot()
    def _on_add_button_clicked(self) -> None:
        """A new row: the last geometry 5 deg further in theta_r (if that is free)."""
        last = self._plan.steps[-1].geometry if self._plan is not None else None
        g = (
            replace(last, theta_r=min(last.theta_r + 5.0, 89.9))
            if last is not None
            else Geometry(45.0, 0.0, 0.0, 180.0)
        )
        self._loading = True
        try:
            self._append_row(GeometryStep(g))
        finally:
            self._loading = False
        self._revalidate()

    @Slot()
    def _on_remove_button_clicked(self) -> None:
        rows = sorted({i.row() for i in self.table.selectedIndexes()}, reverse=True)
        for r in rows or [self.table.rowCount() - 1]:
            self.table.removeRow(r)
        self._revalidate()

    @Slot()
    def _on_load_button_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self, "Load gonio plan", "", "Gonio plan (*.json)"
        )
        if path:
            try:
                self.load(path)
            except TuneSpecError as exc:
                self.error_label.setText(str(exc))

    @Slot()
    def _on_save_button_clicked(self) -> None:
        path, _ = QFileDialog.getSaveFileName(
            self,
            "Save gonio plan",
            str(self.path or "plan.json"),
            "Gonio plan (*.json)",
        )
        if path:
            try:
                self.save(path)
            except (TuneSpecError, OSError) as exc:
                self.error_label.setText(str(exc))


def _number(text: str) -> Any:
    """The cell's number, or the text itself (the validator then names it)."""
    try:
        return float(text.strip())
    except ValueError:
        return text.strip()
