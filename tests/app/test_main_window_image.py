"""Issue 14 item 5 in the main window: the spectral-image tab, File > Spectral image…,
the "estimate the spectral image" action on the measurement, and the Dask scheduler
setting the view uses."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
import pytest
from PySide6.QtCore import QSettings
from PySide6.QtWidgets import QFileDialog

from tests.app.test_image_view import COLS, ROWS, _write_folder
from tests.app.test_wizard import STEP_TIMEOUT_MS, capture_chart, run_step
from tests.app.test_wizard import window as window  # the fixture
from tunespec.app.gui.main_window import IMAGES_DIR, TAB_IMAGE, MainWindow
from tunespec.app.gui.settings import AppSettings


def test_file_menu_opens_an_image_folder_in_the_image_tab(
    window, qtbot, tmp_path, monkeypatch
):
    data = _write_folder(tmp_path / "img")
    asked = []

    def choose(parent, caption, start):
        asked.append(caption)
        return str(tmp_path / "img")

    monkeypatch.setattr(QFileDialog, "getExistingDirectory", choose)
    window.open_image_action.trigger()
    assert asked == ["Open a spectral image folder"]
    assert window.tabs.currentIndex() == TAB_IMAGE
    view = window.image_view
    assert view.image.shape == (ROWS, COLS)
    view.layer_combo.setCurrentText("L*")
    np.testing.assert_array_equal(view.image_item.image, data["lab"][:, :, 0])
    # the pixel's spectrum is drawn in a colour the plot's background is not
    background = view.spectrum_plot.backgroundBrush().color()
    assert pg.mkPen(view.curve.opts["pen"]).color() != background

    # a folder that holds no image: one line in the status bar, the image kept
    window.tabs.setCurrentIndex(0)
    assert not window.open_image(tmp_path)
    message = window.statusBar().currentMessage()
    assert message.startswith("Not a spectral image folder: ") and "\n" not in message
    assert "Traceback" not in message
    assert window.tabs.currentIndex() == 0 and view.image.shape == (ROWS, COLS)


def test_estimate_needs_a_calibrated_measurement(window, tmp_path):
    assert window.estimate_image() is None
    assert "capture the chart" in window.statusBar().currentMessage()
    assert window.wizard_panel.new_measurement(tmp_path / "m")
    assert window.estimate_image() is None
    assert window.image_view.worker is None


def test_scheduler_setting_round_trips_and_is_used(qtbot, tmp_path, monkeypatch):
    import tunespec.app.pipeline.image as pipeline

    ini = str(tmp_path / "settings.ini")
    settings = AppSettings(QSettings(ini, QSettings.Format.IniFormat))
    assert settings.get("image/scheduler") == ""
    w = MainWindow(settings, sim_options={"realtime": False})
    qtbot.addWidget(w)
    assert w.image_view.scheduler_edit.text() == ""
    w.image_view.scheduler_edit.setText(" tcp://cluster:8786 ")
    w.image_view.scheduler_edit.editingFinished.emit()
    assert settings.get("image/scheduler") == "tcp://cluster:8786"
    w.close()

    again = AppSettings(QSettings(ini, QSettings.Format.IniFormat))
    assert again.get("image/scheduler") == "tcp://cluster:8786"
    w2 = MainWindow(again, sim_options={"realtime": False})
    qtbot.addWidget(w2)
    view = w2.image_view
    assert view.scheduler_edit.text() == "tcp://cluster:8786"
    used = []

    def fake(session, sens, out, *, scheduler=None, **_):
        used.append(scheduler)
        _write_folder(out)
        return {}

    monkeypatch.setattr(pipeline, "estimate_images", fake)
    with qtbot.waitSignal(view.estimate_finished, timeout=10_000):
        view.estimate("S", "cal.csv", tmp_path / "out")
    qtbot.waitUntil(lambda: view.worker is None)
    assert used == ["tcp://cluster:8786"]
    # cleared: local again, and remembered so
    view.scheduler_edit.setText("")
    w2.close()
    assert (
        AppSettings(QSettings(ini, QSettings.Format.IniFormat)).get("image/scheduler")
        == ""
    )


@pytest.mark.slow
def test_estimate_image_of_the_bench_measurement(window, qtbot, tmp_path):
    """The chart captured and calibrated by the wizard on the simulated bench; the
    action estimates its per-pixel images into images/chart and shows them; the
    pixels at the SG's patch centres match the chart's reference reflectances
    (median RMS 0.0037 measured)."""
    wizard, m = window.wizard_panel, window.measurement
    assert wizard.new_measurement(tmp_path / "m")
    capture_chart(qtbot, wizard)
    run_step(qtbot, wizard, wizard.calibrate_page)
    view = window.image_view
    with qtbot.waitSignal(view.estimate_finished, timeout=STEP_TIMEOUT_MS) as done:
        assert window.estimate_image() is not None
    qtbot.waitUntil(lambda: view.worker is None, timeout=STEP_TIMEOUT_MS)
    out = tmp_path / "m" / IMAGES_DIR / "chart"
    assert done.args == [str(out)]
    assert window.tabs.currentIndex() == TAB_IMAGE
    image = view.image
    assert image is not None and image.folder == out
    # superpixels: half the simulated mosaic in each direction
    width_px, height_px = window.measurement.sim_options["resolution"]
    assert image.shape == (height_px // 2, width_px // 2)
    # every patch's pixels (3 x 3 superpixels at its centre) against the chart's
    # reference reflectance: the calibration is good to a few percent
    from tunespec.devices.registry import layout_reflectances

    layout = m.calibration.layout
    ref = layout_reflectances(layout)
    centres = (layout.roi_quads_px().mean(axis=1) - 0.5) / 2  # superpixel x, y
    cube = np.asarray(image.cube)
    rms = []
    for (x, y), name in zip(centres, layout.patch_names, strict=True):
        c, r = round(x), round(y)
        pixel = cube[r - 1 : r + 2, c - 1 : c + 2].reshape(-1, cube.shape[2])
        values = ref.values[ref.names.index(name)]
        truth = np.interp(image.wavelength_nm, ref.wavelength_nm, values)
        rms.append(np.sqrt(np.mean((pixel.mean(axis=0) - truth) ** 2)))
    assert len(rms) == layout.n_patches
    print(f"\nper-pixel vs reference: median RMS {np.median(rms):.4f}")
    assert np.median(rms) < 0.01
