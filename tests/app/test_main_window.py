"""Main window: settings persist, the log reaches the log panel, plots take data."""

from __future__ import annotations

import logging

import numpy as np
from PySide6.QtCore import QSettings

from tunespec.app.gui.main_window import TAB_LAYOUT, MainWindow
from tunespec.app.gui.plots.reflectance_plot import ReflectancePlot
from tunespec.app.gui.plots.spd_plot import SpdPlot
from tunespec.app.gui.settings import AppSettings
from tunespec.core.spectra import Spectra


def _settings(tmp_path):
    return AppSettings(QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat))


def test_settings_persist_between_sessions(qtbot, tmp_path):
    w = MainWindow(_settings(tmp_path))
    qtbot.addWidget(w)
    w.tabs.setCurrentIndex(TAB_LAYOUT)
    w.device_panel.light_spec_combo.setCurrentText("cal1+socket://127.0.0.1:5025")
    w.wizard_panel.calibrate_page.threshold_spin.setValue(0.0042)
    w.measurement.threshold = 0.0042
    w.close()
    w2 = MainWindow(_settings(tmp_path))
    qtbot.addWidget(w2)
    assert w2.tabs.currentIndex() == TAB_LAYOUT
    assert (
        w2.device_panel.light_spec_combo.currentText() == "cal1+socket://127.0.0.1:5025"
    )
    assert w2.measurement.threshold == 0.0042
    assert w2.wizard_panel.calibrate_page.threshold_spin.value() == 0.0042
    w2.close()


def test_default_settings_never_touch_the_users(temp_settings):
    # conftest redirected QSettings' default location into a temporary folder
    s = AppSettings()
    s.set("ui/tab", 2)
    s.sync()
    assert str(temp_settings) in s.qsettings.fileName()


def test_python_logging_reaches_the_log_panel(qtbot, tmp_path):
    w = MainWindow(_settings(tmp_path))
    qtbot.addWidget(w)
    logging.getLogger("tunespec.devices.test").warning("lamp is warming up")
    qtbot.waitUntil(lambda: "lamp is warming up" in w.log_panel.plain_text())
    w.log_panel.level_combo.setCurrentIndex(3)  # ERROR and up
    assert "lamp is warming up" not in w.log_panel.plain_text()
    w.close()


def test_spd_plot_names_the_channel_on(qtbot):
    plot = SpdPlot()
    qtbot.addWidget(plot)
    plot.set_channel_names(["LED410", "LED450"])
    wl = np.arange(380.0, 731.0, 5.0)
    spd = Spectra(wl, np.exp(-(((wl - 450) / 10) ** 2))[None], ("measured",))
    plot.show_spd(spd, np.array([0.0, 0.5]))
    assert "LED450 at 50%" in plot.title_label.text()
    assert "450 nm" in plot.message_label.text()
    _, y = plot.curves["measured"].getData()
    np.testing.assert_array_equal(y, spd.values[0])


def test_reflectance_plot_shows_estimate_and_reference(qtbot):
    plot = ReflectancePlot()
    qtbot.addWidget(plot)
    wl = np.arange(400.0, 701.0, 10.0)
    est = Spectra(wl, np.vstack([np.full(31, 0.2), np.full(31, 0.6)]), ("A", "B"))
    ref = Spectra(wl, np.full((1, 31), 0.25), ("A",))
    selected = []
    plot.patch_selected.connect(selected.append)
    plot.set_data(est, ref, {"A": "CIEDE2000 1.00"})
    assert set(plot.curves) == {"estimated", "reference"}
    plot.select_patch("B")
    assert selected[-1] == "B"
    assert set(plot.curves) == {"estimated"}  # no reference for B
    assert "no reference" in plot.message_label.text()
