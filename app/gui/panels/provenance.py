"""File > Measurement record…: the operator's fields of the open measurement.

One line edit per field of :data:`~tunespec.app.pipeline.record.RECORD_FIELDS`
(operator, sample ID, chart serial, the instruments' serials and calibration
dates...), stored in the measurement folder's ``record.json``, the same record that
``tunespec run``'s ``[provenance]`` and ``--operator``... fill, and that the report's
first page and ``summary.json`` show. The dialog holds no rules of its own: OK hands
the fields to :func:`~tunespec.app.pipeline.record.record_from_mapping`, the check
the CLI uses, and a bad field's one-line message is shown under the form.
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Slot
from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QVBoxLayout,
    QWidget,
)

from tunespec.app.pipeline.record import (
    RECORD_FIELDS,
    RECORD_FILE,
    read_record,
    record_from_mapping,
    write_record,
)
from tunespec.core.errors import InputError


class MeasurementRecordDialog(QDialog):
    """Edit ``record.json`` of ``folder`` (``None``: no measurement open, read-only).

    Attributes
    ----------
    edits
        Field key -> its line edit.
    error_label
        The one-line message of a refused field.
    """

    def __init__(self, folder: Path | None, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("measurement_record_dialog")
        self.setWindowTitle("Measurement record")
        self.folder = folder
        layout = QVBoxLayout(self)
        where = (
            f"Kept in {folder / RECORD_FILE}; shown on the report's first page and in "
            "summary.json."
            if folder is not None
            else "No measurement is open: start one (File > New…) or open one first."
        )
        intro = QLabel(where)
        intro.setWordWrap(True)
        layout.addWidget(intro)
        form = QFormLayout()
        layout.addLayout(form)
        try:
            record = read_record(folder) if folder is not None else None
            problem = ""
        except InputError as exc:  # a damaged record.json: shown, fields empty
            record, problem = None, str(exc)
        values = record.as_dict() if record is not None else {}
        self.edits: dict[str, QLineEdit] = {}
        for key, (label, what) in RECORD_FIELDS.items():
            edit = QLineEdit(values.get(key, ""))
            edit.setObjectName(f"record_{key}")
            edit.setPlaceholderText(what)
            edit.setEnabled(folder is not None)
            form.addRow(label, edit)
            self.edits[key] = edit
        self.error_label = QLabel(problem)
        self.error_label.setObjectName("record_error")
        self.error_label.setWordWrap(True)
        self.error_label.setStyleSheet("color: #c00000")
        layout.addWidget(self.error_label)
        buttons = QDialogButtonBox(
            QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel
        )
        buttons.button(QDialogButtonBox.StandardButton.Ok).setEnabled(
            folder is not None
        )
        buttons.accepted.connect(self._on_buttons_accepted)
        buttons.rejected.connect(self.reject)
        layout.addWidget(buttons)
        self.resize(560, self.sizeHint().height())

    @Slot()
    def _on_buttons_accepted(self) -> None:
        """Check the fields as the CLI does; write ``record.json`` and close, or say
        what is wrong in one line and stay open."""
        if self.folder is None:
            return
        values = {key: edit.text() for key, edit in self.edits.items()}
        try:
            record = record_from_mapping(values, section="record")
            write_record(self.folder, record)
        except InputError as exc:
            self.error_label.setText(str(exc))
            return
        except OSError as exc:
            self.error_label.setText(f"could not write {RECORD_FILE}: {exc}")
            return
        self.accept()
