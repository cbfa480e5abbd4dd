"""GonioPlanEditor: edit the geometry list, save, reload; invalid entries inline."""

from __future__ import annotations

import pytest
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QDialogButtonBox

from tunespec.app.gui.editors.gonio_plan_editor import COLUMNS, GonioPlanEditor
from tunespec.app.pipeline.gonio import GonioPlan, default_plan
from tunespec.core.errors import InputError


@pytest.fixture
def editor(qtbot):
    ed = GonioPlanEditor(default_plan(6))
    qtbot.addWidget(ed)
    ed.show()
    qtbot.waitExposed(ed)
    return ed


def _set(ed, row, key, text):
    ed.table.item(row, COLUMNS.index(key)).setText(text)


def _check(ed, row, key, on):
    state = Qt.CheckState.Checked if on else Qt.CheckState.Unchecked
    ed.table.item(row, COLUMNS.index(key)).setCheckState(state)


def test_edit_save_reload_gives_the_same_plan(editor, tmp_path):
    assert editor.table.rowCount() == 6 and editor.plan() == default_plan(6)
    _set(editor, 1, "theta_r", "15")
    _set(editor, 2, "phi_r", "90")
    _check(editor, 1, "spectral", True)
    _check(editor, 0, "hdr", True)
    editor.mix_combo.setCurrentText("camera")
    editor.add_button.click()  # the last geometry, 5 deg further in theta_r
    plan = editor.plan()
    assert plan is not None and len(plan.steps) == 7 and plan.mix == "camera"
    s1, s2, new = plan.steps[1], plan.steps[2], plan.steps[6]
    assert s1.geometry.theta_r == 15 and s1.spectral
    assert s2.geometry.phi_r == 90 and plan.steps[0].hdr
    assert new.geometry.theta_r == plan.steps[5].geometry.theta_r + 5
    path = tmp_path / "plan.json"
    editor.save(path)
    # what the CLI reads is what the editor showed
    assert GonioPlan.load(path) == plan
    other = GonioPlanEditor()
    try:
        other.load(path)
        assert other.plan() == plan and other.table.rowCount() == 7
        assert other.table.item(1, COLUMNS.index("theta_r")).text() == "15"
        assert other.mix_combo.currentText() == "camera"
    finally:
        other.deleteLater()
    editor.table.selectRow(6)
    editor.remove_button.click()
    assert len(editor.plan().steps) == 6


def test_invalid_angle_is_rejected_inline_with_one_clear_message(editor, tmp_path):
    ok = editor.buttons.button(QDialogButtonBox.StandardButton.Ok)
    assert ok.isEnabled() and editor.error_label.text() == ""
    _set(editor, 3, "theta_r", "95")
    assert editor.plan() is None
    msg = editor.error_label.text()
    assert msg == "Row 4: theta_r = 95 deg outside 0..89.9"
    assert "\n" not in msg and editor.summary_label.text() == ""
    bad = editor.table.item(3, COLUMNS.index("theta_r"))
    assert bad.background().color().red() == 255  # the entry is marked
    assert editor.table.item(3, COLUMNS.index("theta_i")).background().style() == (
        Qt.BrushStyle.NoBrush
    )
    assert not ok.isEnabled() and not editor.save_button.isEnabled()
    with pytest.raises(InputError, match="not valid"):
        editor.save(tmp_path / "bad.json")
    assert not (tmp_path / "bad.json").exists()
    _set(editor, 3, "theta_r", "abc")
    assert editor.error_label.text().startswith("Row 4: expected a number")
    _set(editor, 3, "theta_r", "30")
    assert editor.plan() is not None and editor.error_label.text() == ""
    assert ok.isEnabled()
    assert bad.background().style() == Qt.BrushStyle.NoBrush
    # a geometry twice: the same validator as the CLI says so
    _set(editor, 3, "theta_r", "20")
    assert "twice" in editor.error_label.text() and editor.plan() is None


@pytest.mark.slow
def test_main_window_menu_opens_the_editor(qtbot, tmp_path):
    from PySide6.QtCore import QSettings

    from tunespec.app.gui.main_window import MainWindow
    from tunespec.app.gui.settings import AppSettings

    ini = QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat)
    win = MainWindow(AppSettings(ini))
    qtbot.addWidget(win)
    win.gonio_plan_action.trigger()
    assert isinstance(win.gonio_plan_editor, GonioPlanEditor)
    assert win.gonio_plan_editor.isVisible()
    assert win.gonio_plan_editor.plan() == default_plan()
    win.gonio_plan_editor.close()
    win.close()
