"""The wizard's "Frames per LED": the session takes that many frames per LED."""

from __future__ import annotations

import pytest
from PySide6.QtCore import QSettings

from tests.app.test_wizard import run_step
from tunespec.app.gui.main_window import MainWindow
from tunespec.app.gui.settings import AppSettings
from tunespec.app.gui.wizard.measurement import CaptureOptions

SIM = {"realtime": False, "resolution": (256, 192), "seed": 2}


@pytest.mark.slow
def test_frames_per_led_reach_the_session_and_the_settings(qtbot, tmp_path) -> None:
    settings = AppSettings(
        QSettings(str(tmp_path / "a.ini"), QSettings.Format.IniFormat)
    )
    w = MainWindow(settings, sim_options=SIM)
    qtbot.addWidget(w)
    wizard, m = w.wizard_panel, w.measurement
    assert wizard.new_measurement(tmp_path / "m")
    page = wizard.dark_page
    page.exposure_combo.setCurrentIndex(1)
    page.exposure_spin.setValue(0.05)
    page.darks_spin.setValue(2)
    page.repeats_spin.setValue(2)
    assert page.capture_options() == CaptureOptions(0.05, 100, 2, 2)
    run_step(qtbot, wizard, wizard.connect_page)
    run_step(qtbot, wizard, wizard.dark_page)
    session = m.session("chart")
    assert session.settings.bracket_factors == (1.0, 1.0)
    assert sum(f.kind == "dark" for f in session.frames) == 2
    assert m.capture_options.repeats == 2
    run_step(qtbot, wizard, wizard.white_page)
    run_step(qtbot, wizard, wizard.chart_page)
    session = m.session("chart")
    assert sum(f.kind == "white" for f in session.frames) == 2 * 22
    assert sum(f.kind == "target" for f in session.frames) == 2 * 22
    assert m.phase_complete("chart", None)
    assert CaptureOptions.from_dict(m.capture_options.to_dict()).repeats == 2
    w.close()
