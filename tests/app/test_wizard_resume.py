"""Abort a capture step (LEDs off), reopen the interrupted measurement, resume it."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QSettings

from tests.app.test_wizard import STEP_TIMEOUT_MS, run_step
from tunespec.app.gui.main_window import MainWindow
from tunespec.app.gui.settings import AppSettings
from tunespec.app.gui.wizard.measurement import CaptureOptions
from tunespec.app.gui.wizard.step_page import StepState

#: Real time with short fixed exposures, so that a step can be caught half-way.
SIM_REALTIME = {"realtime": True, "resolution": (256, 192), "seed": 5}
EXPOSURE_S = 0.05


def _window(qtbot, tmp_path, name):
    settings = AppSettings(
        QSettings(str(tmp_path / f"{name}.ini"), QSettings.Format.IniFormat)
    )
    w = MainWindow(settings, sim_options=SIM_REALTIME)
    qtbot.addWidget(w)
    w.show()
    return w


def test_abort_then_reopen_and_resume(qtbot, tmp_path):
    folder = tmp_path / "m"
    w = _window(qtbot, tmp_path, "first")
    wizard, m = w.wizard_panel, w.measurement
    assert wizard.new_measurement(folder)
    m.capture_options = CaptureOptions(EXPOSURE_S, 100, 1)
    wizard.dark_page.exposure_combo.setCurrentIndex(1)
    wizard.dark_page.exposure_spin.setValue(EXPOSURE_S)
    run_step(qtbot, wizard, wizard.connect_page)
    run_step(qtbot, wizard, wizard.dark_page)
    run_step(qtbot, wizard, wizard.white_page)

    page = wizard.chart_page
    wizard.go_to(wizard.pages.index(page))
    page.start_button.click()
    qtbot.waitUntil(lambda: page.progress_bar.value() >= 150, timeout=STEP_TIMEOUT_MS)
    page.abort_button.click()
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    assert page.state == StepState.ABORTED
    assert "Aborted" in page.result_label.text()
    # the light is off after an abort
    qtbot.waitUntil(
        lambda: w.device_panel.levels.size and not np.any(w.device_panel.levels)
    )
    taken = sum(f.kind == "target" for f in m.session("chart").frames)
    assert 0 < taken < 22
    assert not wizard.next_button.isEnabled()
    w.close()

    # a new window (a new day): reopen the measurement and carry on where it stopped
    w2 = _window(qtbot, tmp_path, "second")
    wizard2 = w2.wizard_panel
    assert wizard2.open_measurement(folder)
    states = [p.state for p in wizard2.pages]
    assert states[1:3] == [StepState.DONE, StepState.DONE]  # dark, white restored
    assert states[3] == StepState.PENDING
    run_step(qtbot, wizard2, wizard2.connect_page)
    assert wizard2.first_unfinished() == 3
    text = run_step(qtbot, wizard2, wizard2.chart_page)
    assert f"{22 - taken} frame(s) taken" in text
    assert w2.measurement.phase_complete("chart", None)
    w2.close()


@pytest.mark.slow
def test_a_finished_measurement_reopens_with_its_results(qtbot, tmp_path):
    from tests.app.test_wizard import SIM

    folder = tmp_path / "m"
    settings = AppSettings(
        QSettings(str(tmp_path / "a.ini"), QSettings.Format.IniFormat)
    )
    w = MainWindow(settings, sim_options=SIM)
    qtbot.addWidget(w)
    wizard = w.wizard_panel
    assert wizard.new_measurement(folder)
    for page in wizard.pages:
        run_step(qtbot, wizard, page)
    shown1 = w.table1_panel.values.copy()
    shown2 = w.table2_panel.values.copy()
    w.close()

    w2 = _window(qtbot, tmp_path, "b")
    wizard2 = w2.wizard_panel
    assert wizard2.open_measurement(folder)
    assert [p.state for p in wizard2.pages[1:]] == [StepState.DONE] * 7
    np.testing.assert_array_equal(w2.table1_panel.values, shown1)
    np.testing.assert_allclose(w2.table2_panel.values, shown2, rtol=1e-12)
    # exporting again works from the restored results (the sessions are reprocessed)
    (folder / "export" / "reflectances.csv").unlink()
    run_step(qtbot, wizard2, wizard2.export_page)
    assert (folder / "export" / "reflectances.csv").is_file()
    w2.close()
