"""Nothing stale on screen or in the model: retakes, another measurement, closing."""

from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QSettings

from tests.app.helpers import caught, main_window
from tunespec.app.gui import workers
from tunespec.app.gui.editors.target_layout_editor import TargetLayoutEditor
from tunespec.app.gui.main_window import MainWindow
from tunespec.app.gui.plots.frame_plot import build_preview
from tunespec.app.gui.settings import AppSettings
from tunespec.app.gui.wizard.measurement import (
    CalibrationResult,
    CaptureOptions,
    EstimateResult,
    Measurement,
)
from tunespec.app.gui.wizard.step_page import StepState
from tunespec.core.datasets import resource_path
from tunespec.core.layout import TargetLayout
from tunespec.core.spectra import DEFAULT_GRID, Spectra
from tunespec.core.stats import prediction_stats
from tunespec.devices.protocols import LightStatus

SIM = {"realtime": False, "resolution": (256, 192), "seed": 1}


@pytest.fixture
def window(qtbot, tmp_path):
    with main_window(qtbot, tmp_path, SIM, show=False) as w:
        yield w


def _calibration(m: Measurement) -> CalibrationResult:
    rng = np.random.default_rng(0)
    measured = rng.uniform(0.1, 0.9, (30, 3))
    wl = DEFAULT_GRID.wavelength_nm
    sensitivity = Spectra(wl, rng.uniform(0, 1, (3, wl.size)), ("R", "G", "B"))
    return CalibrationResult(
        sensitivity=sensitivity,
        table1=prediction_stats(measured, measured + 0.001),
        threshold=0.005,
        method="smooth",
        layout=m.chart_layout,
    )


def _estimate() -> EstimateResult:
    wl = DEFAULT_GRID.wavelength_nm
    return EstimateResult(
        reflectance=Spectra(wl, np.full((2, wl.size), 0.5), ("P1", "P2"))
    )


def test_retaking_the_chart_drops_the_calibration_and_what_follows(window, tmp_path):
    wizard, m = window.wizard_panel, window.measurement
    assert wizard.new_measurement(tmp_path / "m")
    m.calibration = _calibration(m)
    m.calibrated.emit(m.calibration)
    wizard.calibrate_page.mark_done("done")
    m.estimate = _estimate()
    m.estimated.emit(m.estimate)
    wizard.estimate_page.mark_done("done")
    assert window.table1_panel.values.shape == (4, 3)
    assert window.reflectance_plot.estimated is not None

    # the chart frames are retaken: calibration and estimate no longer hold
    wizard.chart_page._set_state(StepState.RUNNING)
    assert wizard.calibrate_page.state == StepState.PENDING
    assert wizard.estimate_page.state == StepState.PENDING
    assert m.calibration is None and m.estimate is None
    assert wizard.estimate_page.can_start() == "Calibrate first (step 5)."
    assert window.table1_panel.values.size == 0
    assert wizard.calibrate_page.table_panel.values.size == 0
    assert window.sensitivity_plot.sensitivity is None
    assert window.reflectance_plot.estimated is None
    assert window.reflectance_plot.patch_combo.count() == 0
    wizard.chart_page._set_state(StepState.ABORTED)


def test_a_reset_step_loses_its_red_message(window):
    page = window.wizard_panel.calibrate_page
    page.start()  # refused: nothing captured
    assert "c00000" in page.result_label.styleSheet()
    page.reset()
    assert page.result_label.styleSheet() == ""


def test_opening_a_measurement_shows_its_own_options(window, qtbot, tmp_path):
    wizard, m = window.wizard_panel, window.measurement
    ref = tmp_path / "ref.csv"
    other = Measurement(m.controller, m.settings)
    other.new(tmp_path / "old")
    other.capture_options = CaptureOptions(2.5, 400, 3)
    other.method = "pca"
    other.threshold = 0.0031
    other.reference_path = ref
    other.save()
    assert wizard.new_measurement(tmp_path / "new")
    assert wizard.open_measurement(tmp_path / "old")

    dark = wizard.dark_page
    assert dark.capture_options() == CaptureOptions(2.5, 400, 3)
    assert dark.exposure_spin.isEnabled()
    cal = wizard.calibrate_page
    assert cal.method_combo.currentData() == "pca"
    assert cal.threshold_spin.value() == pytest.approx(0.0031)
    assert wizard.estimate_page.reference_edit.text() == str(ref)


def test_automatic_exposure_greys_out_the_seconds(window):
    dark = window.wizard_panel.dark_page
    dark.exposure_combo.setCurrentIndex(dark.exposure_combo.findData("auto"))
    assert not dark.exposure_spin.isEnabled()
    dark.exposure_combo.setCurrentIndex(dark.exposure_combo.findData("fixed"))
    assert dark.exposure_spin.isEnabled()


def test_no_new_measurement_while_a_step_runs(window, tmp_path):
    wizard, m = window.wizard_panel, window.measurement
    assert wizard.new_measurement(tmp_path / "a")
    wizard.dark_page._set_state(StepState.RUNNING)
    try:
        assert not wizard.new_measurement(tmp_path / "b")
        assert not wizard.open_measurement(tmp_path / "a")
    finally:
        wizard.dark_page._set_state(StepState.ABORTED)
    assert m.folder == tmp_path / "a"
    assert not (tmp_path / "b").exists()
    text = wizard.folder_label.text()
    assert "a step is running" in text and str(tmp_path / "a") in text


def test_closing_stops_the_devices_even_if_saving_fails(qtbot, tmp_path, monkeypatch):
    settings = AppSettings(
        QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    )
    w = MainWindow(settings, sim_options=SIM)
    qtbot.addWidget(w)

    def fail() -> None:
        raise OSError("disk gone")

    monkeypatch.setattr(w.measurement, "save", fail)
    w.close()
    assert not w.controller.thread_running
    assert w.controller._thread not in workers.running_threads()


def test_a_corrupt_export_index_is_not_restored(window, tmp_path):
    m = window.measurement
    m.new(tmp_path / "m")
    (tmp_path / "m" / "export").mkdir()
    (tmp_path / "m" / "export" / "exports.json").write_text("{not json")
    assert m.restore_export() is None


def test_corners_found_for_the_other_target_are_not_used(qtbot):
    chart = TargetLayout.load(resource_path("layouts", "colorchecker_sg.json"))
    sample = TargetLayout.load(resource_path("layouts", "neugebauer_cmy.json"))
    found = np.array([[10.0, 10.0], [200.0, 10.0], [200.0, 150.0], [10.0, 150.0]])
    editor = TargetLayoutEditor(chart, corner_finder=lambda *a, **k: found)
    qtbot.addWidget(editor)

    class Frame:
        planes = np.full((3, 96, 128), 0.5, np.float32)
        saturated = None

    editor.show_preview(build_preview(Frame()))
    worker = editor.find_corners()
    assert worker is not None
    # the wizard shows the sample before the finder's answer arrives
    editor.set_target_layout(sample.with_corners(found + 5.0))
    qtbot.waitUntil(lambda: editor._finder_worker is None, timeout=5000)
    np.testing.assert_allclose(editor.target_layout.corners_px, found + 5.0)
    assert "not used" in editor.status_label.text()


def test_live_view_goes_on_after_a_capture(panel, qtbot):
    c = panel.controller
    with caught(qtbot, c.devices_opened, timeout=20_000):
        panel.connect_devices()
    with caught(qtbot, c.frame_acquired, timeout=20_000):
        panel.live_check.setChecked(True)
    qtbot.waitUntil(lambda: not panel._live_pending)
    c.busy_changed.emit(True)
    panel.live_timer.stop()  # its tick while busy took no frame
    c.busy_changed.emit(False)
    assert panel.live_timer.isActive()
    with caught(qtbot, c.devices_closed, timeout=10_000):
        panel.controller.close_devices()
    assert not panel.live_check.isChecked()
    assert not panel.live_timer.isActive()


def test_status_says_ready_once(panel):
    status = LightStatus(ready=True, temperature_c=28.2, on_time_s=3.0, message="ready")
    panel._on_controller_status_changed(status)
    assert panel.status_label.text().count("ready") == 1


def test_spd_peak_is_written_with_the_axis_prefix(qtbot):
    from tunespec.app.gui.plots.spd_plot import SpdPlot

    plot = SpdPlot()
    qtbot.addWidget(plot)
    wl = DEFAULT_GRID.wavelength_nm
    values = np.zeros((1, wl.size))
    values[0, 10] = 7.6e-4
    plot.show_spd(Spectra(wl, values, ("measured",)))
    assert plot.message_label.text() == f"peak 760 µW sr⁻¹ m⁻² nm⁻¹ at {wl[10]:g} nm"
