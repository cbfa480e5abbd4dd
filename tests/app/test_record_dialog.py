"""File > Measurement record…: the operator's fields into the folder's record.json,
checked as the command line checks them (issue 27 item 5)."""

from __future__ import annotations

import json

import pytest
from PySide6.QtWidgets import QDialogButtonBox

from tunespec.app.gui.panels.provenance import MeasurementRecordDialog
from tunespec.app.pipeline.record import RECORD_FILE, MeasurementRecord, write_record


def _ok(dialog: MeasurementRecordDialog) -> None:
    box = dialog.findChild(QDialogButtonBox)
    box.button(QDialogButtonBox.StandardButton.Ok).click()


def test_the_dialog_edits_the_folders_record(qtbot, tmp_path) -> None:
    write_record(tmp_path, MeasurementRecord(operator="Kim", chart_serial="SG-1"))
    dialog = MeasurementRecordDialog(tmp_path)
    qtbot.addWidget(dialog)
    assert dialog.edits["operator"].text() == "Kim"
    assert dialog.edits["chart_serial"].text() == "SG-1"
    dialog.edits["sample_id"].setText("CMY-9")
    dialog.edits["light_source_calibration"].setText("next week")
    _ok(dialog)
    # refused with the CLI's one-line message; nothing written, still open
    assert "light_source_calibration: expected a date YYYY-MM-DD" in (
        dialog.error_label.text()
    )
    assert json.loads((tmp_path / RECORD_FILE).read_text())["sample_id"] == ""
    assert dialog.result() == 0
    dialog.edits["light_source_calibration"].setText("2026-10-01")
    _ok(dialog)
    doc = json.loads((tmp_path / RECORD_FILE).read_text())
    assert (doc["operator"], doc["sample_id"], doc["light_source_calibration"]) == (
        "Kim",
        "CMY-9",
        "2026-10-01",
    )
    assert dialog.result() == MeasurementRecordDialog.DialogCode.Accepted


def test_without_a_measurement_the_dialog_says_so(qtbot) -> None:
    dialog = MeasurementRecordDialog(None)
    qtbot.addWidget(dialog)
    assert not any(e.isEnabled() for e in dialog.edits.values())
    box = dialog.findChild(QDialogButtonBox)
    assert not box.button(QDialogButtonBox.StandardButton.Ok).isEnabled()


def test_a_damaged_record_is_named_not_raised(qtbot, tmp_path) -> None:
    (tmp_path / RECORD_FILE).write_text('{"operator": 5}')
    dialog = MeasurementRecordDialog(tmp_path)
    qtbot.addWidget(dialog)
    assert "record.operator: expected text" in dialog.error_label.text()


@pytest.mark.slow
def test_the_main_window_file_menu_opens_it(qtbot, tmp_path, monkeypatch) -> None:
    from PySide6.QtCore import QSettings

    from tunespec.app.gui.main_window import MainWindow
    from tunespec.app.gui.settings import AppSettings

    shown = []
    monkeypatch.setattr(
        MeasurementRecordDialog, "exec", lambda self: shown.append(self.folder) or 0
    )
    ini = QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat)
    win = MainWindow(AppSettings(ini))
    qtbot.addWidget(win)
    file_menu = win.menuBar().actions()[0].menu()
    assert win.record_action in file_menu.actions()
    win.measurement.new(tmp_path / "m")
    win.record_action.trigger()
    assert shown == [tmp_path / "m"]
    win.close()
