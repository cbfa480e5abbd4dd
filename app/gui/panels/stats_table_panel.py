"""A read-only table of statistics (paper Tables 1 and 2) with a verdict line."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from PySide6.QtCore import Qt, Signal, Slot
from PySide6.QtGui import QBrush, QColor
from PySide6.QtWidgets import (
    QAbstractItemView,
    QHeaderView,
    QLabel,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

__all__ = [
    "StatsTablePanel",
    "show_table1",
    "show_table2",
    "table1_panel",
    "table2_panel",
]

_PASS = QColor(0, 128, 0)
_FAIL = QColor(192, 0, 0)


class StatsTablePanel(QWidget):
    """Rows x columns of numbers, a caption and a pass/fail verdict.

    The numbers are shown exactly as the core computed them (formatted with
    ``fmt``); :attr:`values` keeps the raw array so tests can compare it with the
    core's statistics.

    Parameters
    ----------
    title
        Caption above the table, e.g. "Table 1: prediction error".
    fmt
        Format of each cell, or one format per column.
    """

    #: A row was clicked: its name.
    row_selected = Signal(str)

    def __init__(
        self,
        title: str,
        fmt: str | Sequence[str] = "{:.4f}",
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.fmt = fmt
        self.title_label = QLabel(title)
        self.title_label.setStyleSheet("font-weight: bold")
        self.table = QTableWidget()
        self.table.setEditTriggers(QAbstractItemView.EditTrigger.NoEditTriggers)
        self.table.setSelectionBehavior(QAbstractItemView.SelectionBehavior.SelectRows)
        self.table.setSelectionMode(QAbstractItemView.SelectionMode.SingleSelection)
        self.table.horizontalHeader().setSectionResizeMode(
            QHeaderView.ResizeMode.Stretch
        )
        self.verdict_label = QLabel("")
        self.verdict_label.setWordWrap(True)
        self.note_label = QLabel("")
        self.note_label.setWordWrap(True)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addWidget(self.title_label)
        layout.addWidget(self.table, 1)
        layout.addWidget(self.verdict_label)
        layout.addWidget(self.note_label)
        self.row_names: list[str] = []
        self.column_names: list[str] = []
        self.values = np.zeros((0, 0))
        self.passed: bool | None = None
        self.table.cellClicked.connect(self._on_table_cell_clicked)

    def set_table(
        self,
        row_names: Sequence[str],
        column_names: Sequence[str],
        values: ArrayLike,
        *,
        failing: ArrayLike | None = None,
    ) -> None:
        """Fill the table.

        Parameters
        ----------
        row_names, column_names
            Headers.
        values : (n_rows, n_cols)
            The numbers.
        failing : (n_rows, n_cols) bool or None
            Cells to mark in red (over a threshold).
        """
        vals = np.asarray(values, dtype=float).reshape(
            len(row_names), len(column_names)
        )
        bad = (
            np.zeros(vals.shape, bool)
            if failing is None
            else np.asarray(failing, dtype=bool).reshape(vals.shape)
        )
        self.row_names, self.column_names, self.values = (
            list(row_names),
            list(column_names),
            vals,
        )
        self.table.clear()
        self.table.setRowCount(len(row_names))
        self.table.setColumnCount(len(column_names))
        self.table.setHorizontalHeaderLabels(self.column_names)
        self.table.setVerticalHeaderLabels(self.row_names)
        for i in range(vals.shape[0]):
            for j in range(vals.shape[1]):
                v = vals[i, j]
                fmt = self.fmt if isinstance(self.fmt, str) else self.fmt[j]
                item = QTableWidgetItem("—" if not np.isfinite(v) else fmt.format(v))
                item.setTextAlignment(
                    Qt.AlignmentFlag.AlignRight | Qt.AlignmentFlag.AlignVCenter
                )
                item.setData(Qt.ItemDataRole.UserRole, float(v))
                if bad[i, j]:
                    item.setForeground(QBrush(_FAIL))
                self.table.setItem(i, j, item)

    def set_verdict(
        self, passed: bool | None, text: str, *, outcome: str | None = None
    ) -> None:
        """Show a PASS/FAIL line (``passed=None``: neutral text); ``outcome`` names
        it (``"PASS with warnings"``) where plain PASS/FAIL would say too little."""
        self.passed = passed
        if passed is None:
            self.verdict_label.setStyleSheet("")
            self.verdict_label.setText(text)
            return
        colour = _PASS if passed else _FAIL
        self.verdict_label.setStyleSheet(f"color: {colour.name()}; font-weight: bold")
        if outcome is None:
            outcome = "PASS" if passed else "FAIL"
        self.verdict_label.setText(f"{outcome}: {text}")

    def set_note(self, text: str) -> None:
        """A line of context under the verdict (counts, thresholds, exclusions)."""
        self.note_label.setText(text)

    def clear_table(self, message: str = "") -> None:
        """Empty the table and show ``message``."""
        self.set_table([], [], np.zeros((0, 0)))
        self.set_verdict(None, message)
        self.set_note("")

    def cell_value(self, row: str, column: str) -> float:
        """The number in ``row``/``column`` as shown."""
        return float(
            self.values[self.row_names.index(row), self.column_names.index(column)]
        )

    @Slot(int, int)
    def _on_table_cell_clicked(self, row: int, _column: int) -> None:
        self.row_selected.emit(self.row_names[row])


def table1_panel() -> StatsTablePanel:
    """An empty panel for Table 1 (prediction error, full-scale units)."""
    panel = StatsTablePanel("Table 1 — response prediction error (full scale)")
    panel.clear_table("Not calibrated yet.")
    return panel


def table2_panel() -> StatsTablePanel:
    """An empty panel for Table 2 (CIEDE2000 to 2 decimals, RMS to 4, as the paper)."""
    panel = StatsTablePanel(
        "Table 2 — estimated vs reference reflectance", fmt=("{:.2f}", "{:.4f}")
    )
    panel.clear_table("Not estimated yet.")
    return panel


def show_table1(panel: StatsTablePanel, calibration: Any) -> None:
    """Fill ``panel`` with Table 1 of a ``CalibrationResult`` and its verdict."""
    from tunespec.core.stats import STAT_ROWS

    t = calibration.table1
    values = np.column_stack([t.mean, t.max, t.p95])
    failing = np.zeros(values.shape, bool)
    failing[3, 0] = not calibration.passed
    panel.set_table(
        STAT_ROWS, ["Mean", "Maximum", "95th percentile"], values, failing=failing
    )
    outcome, why = calibration.verdict_reason
    panel.set_verdict(outcome != "FAIL", why, outcome=outcome)
    note = f"{t.n_stimuli} stimuli; method {calibration.method}; paper: RGB mean 0.0024"
    if calibration.excluded_patches:
        note += f"; {len(calibration.excluded_patches)} saturated patch(es) left out"
    checked = getattr(calibration, "self_check", None)
    if checked is not None:
        found = len(checked.get("warnings", ()))
        note += (
            f"; self-check: {found} finding(s), see the warnings"
            if found
            else "; self-check passed"
        )
    panel.set_note(note)


def show_table2(panel: StatsTablePanel, estimate: Any) -> None:
    """Fill ``panel`` with Table 2 of an ``EstimateResult`` (or say why there is none)."""
    t = estimate.table2
    if t is None:
        panel.clear_table("No references given: Table 2 needs reference reflectances.")
        return
    rows = [*t.names, "average", "max"]
    values = np.vstack(
        [
            np.column_stack([t.delta_e00, t.spectral_rms]),
            [t.mean_delta_e00, t.mean_spectral_rms],
            [t.max_delta_e00, t.max_spectral_rms],
        ]
    )
    panel.set_table(rows, ["CIEDE2000 [D50]", "Spectral RMS"], values)
    panel.set_verdict(
        None,
        f"average CIEDE2000 {t.mean_delta_e00:.2f}, spectral RMS {t.mean_spectral_rms:.4f} "
        "(paper: 0.67 / 0.0286)",
    )
    note = f"{len(t.names)} patches compared with their references"
    # the sample's scale against the chart session's (pipeline.lighting)
    scale = getattr(estimate.estimation, "white_scale_text", "")
    if scale:
        note += f"; the sample's white background over the chart's: {scale}"
    panel.set_note(note)
