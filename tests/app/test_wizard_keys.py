"""Keyboard shortcuts of the wizard: Next, Back, start (Take frames...), Abort."""

from __future__ import annotations

from PySide6.QtCore import QSettings, Qt

from tests.app.test_wizard import STEP_TIMEOUT_MS
from tests.app.test_wizard_resume import EXPOSURE_S, SIM_REALTIME
from tunespec.app.gui.main_window import TAB_LAYOUT, MainWindow
from tunespec.app.gui.settings import AppSettings
from tunespec.app.gui.wizard.measurement import CaptureOptions
from tunespec.app.gui.wizard.step_page import StepState

ALT, CTRL = Qt.KeyboardModifier.AltModifier, Qt.KeyboardModifier.ControlModifier


def test_shortcuts_drive_the_wizard(qtbot, tmp_path):
    settings = AppSettings(
        QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat)
    )
    w = MainWindow(settings, sim_options=SIM_REALTIME)
    qtbot.addWidget(w)
    w.show()
    with qtbot.waitActive(w):  # shortcuts reach the active window only
        w.activateWindow()
    wizard = w.wizard_panel
    assert wizard.new_measurement(tmp_path / "m")
    w.measurement.capture_options = CaptureOptions(EXPOSURE_S, 100, 1)
    wizard.dark_page.exposure_combo.setCurrentIndex(1)
    wizard.dark_page.exposure_spin.setValue(EXPOSURE_S)
    wizard.step_list.setFocus()

    def key(k, mod=Qt.KeyboardModifier.NoModifier):
        qtbot.keyClick(w.focusWidget() or w, k, mod)

    # Ctrl+Enter starts the step shown (Connect)
    key(Qt.Key.Key_Return, CTRL)
    qtbot.waitUntil(
        lambda: wizard.connect_page.state == StepState.DONE, timeout=STEP_TIMEOUT_MS
    )
    # Alt+Right: Next; Alt+Left: Back
    key(Qt.Key.Key_Right, ALT)
    assert wizard.current_page is wizard.dark_page
    key(Qt.Key.Key_Left, ALT)
    assert wizard.current_page is wizard.connect_page
    key(Qt.Key.Key_Right, ALT)
    # Next does nothing while the step is not done
    key(Qt.Key.Key_Right, ALT)
    assert wizard.current_page is wizard.dark_page

    # Ctrl+Enter takes the frames
    key(Qt.Key.Key_Return, CTRL)
    assert wizard.dark_page.running
    qtbot.waitUntil(lambda: not wizard.dark_page.running, timeout=STEP_TIMEOUT_MS)
    assert wizard.dark_page.state == StepState.DONE
    key(Qt.Key.Key_Right, ALT)
    page = wizard.white_page  # 22 frames in real time: long enough to abort
    assert wizard.current_page is page
    key(Qt.Key.Key_Return, CTRL)
    assert page.running
    # Esc aborts, from another tab too
    w.tabs.setCurrentIndex(TAB_LAYOUT)
    w.layout_editor.frame_plot.graphics.setFocus()
    key(Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    assert page.state == StepState.ABORTED
    w.close()
