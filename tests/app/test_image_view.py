"""The image view: layers, a pixel's spectrum with its band, regions, the worker."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tunespec.app.gui.plots.image_view import LAYERS, ImageView
from tunespec.core.colorimetry import delta_e_2000
from tunespec.core.io.image_formats import ImageOutputs
from tunespec.core.progress import Cancelled, check_stop

ROWS, COLS = 24, 32
WL = np.arange(400.0, 701.0, 10.0)
#: The sRGB preview's colours of the two halves.
PREVIEW_LEFT, PREVIEW_RIGHT = (200, 90, 70), (70, 110, 210)


def _write_folder(folder, u_reflectance=None) -> dict[str, np.ndarray]:
    """A finished image folder: left half one colour, right half another
    (``u_reflectance``: the RMS u(reflectance) image, else 0.01 everywhere)."""
    rng = np.random.default_rng(0)
    cube = np.empty((ROWS, COLS, WL.size), np.float32)
    cube[:, : COLS // 2] = 0.2 + 0.5 * (WL > 550)  # reddish
    cube[:, COLS // 2 :] = 0.6 - 0.3 * (WL > 550)  # bluish
    cube += rng.normal(0, 0.01, cube.shape).astype(np.float32)
    lab = np.empty((ROWS, COLS, 3), np.float32)
    lab[:, : COLS // 2] = (60.0, 30.0, 20.0)
    lab[:, COLS // 2 :] = (55.0, -5.0, -25.0)
    lab += rng.normal(0, 0.2, lab.shape).astype(np.float32)
    unc = np.full((ROWS, COLS, 2), (0.2, 0.01), np.float32)
    if u_reflectance is not None:
        unc[:, :, 1] = u_reflectance
    xyz = np.full((ROWS, COLS, 3), 30.0, np.float32)
    out = ImageOutputs.create(folder, (ROWS, COLS), WL, block_rows=8,
                              provenance={"session": "test"})  # fmt: skip
    for r0 in range(0, ROWS, 8):
        sl = slice(r0, r0 + 8)
        out.write_rows(r0, cube[sl], xyz[sl], lab[sl], unc[sl])
    preview = np.empty((ROWS, COLS, 3), np.uint8)  # not black: a screenshot shows it
    preview[:, : COLS // 2] = PREVIEW_LEFT
    preview[:, COLS // 2 :] = PREVIEW_RIGHT
    out.write_preview(preview)
    out.write_provenance({"session": "test"})
    return {"cube": cube, "lab": lab, "unc": unc}


def test_layers_pixel_spectrum_and_regions(qtbot, tmp_path) -> None:
    data = _write_folder(tmp_path / "img")
    view = ImageView()
    qtbot.addWidget(view)
    view.open_folder(tmp_path / "img")
    for name in LAYERS:
        view.layer_combo.setCurrentText(name)
        shown = view.image_item.image
        assert shown.shape[:2] == (ROWS, COLS)
    view.band_spin.setValue(600)
    np.testing.assert_array_equal(view.image_item.image, data["cube"][:, :, 20])
    view.layer_combo.setCurrentText("L*")
    np.testing.assert_array_equal(view.image_item.image, data["lab"][:, :, 0])

    view.show_pixel(5, 7)
    x, y = view.curve.getData()
    np.testing.assert_allclose(x, WL)
    np.testing.assert_allclose(y, data["cube"][5, 7])
    _, upper = view.upper.getData()
    np.testing.assert_allclose(upper - y, 1.96 * 0.01, atol=1e-6)
    assert "u(L*) 0.200" in view.status.text()

    view.roi_a.setPos((2, 2))
    view.roi_a.setSize((10, 10))
    view.roi_b.setPos((20, 10))
    view.roi_b.setSize((8, 8))
    view._on_roi_changed()
    a = data["lab"][2:12, 2:12].reshape(-1, 3).astype(float).mean(0)
    b = data["lab"][10:18, 20:28].reshape(-1, 3).astype(float).mean(0)
    expected = float(delta_e_2000(a, b))
    text = view.region_label.text()
    assert f"dE00(A, B) = {expected:.2f}" in text
    assert "A: 100 px" in text and "B: 64 px" in text

    # another folder: the last image's pixel spectrum goes with it
    _write_folder(tmp_path / "next")
    view.open_folder(tmp_path / "next")
    assert view.pixel is None
    for item in (view.curve, view.upper, view.lower):
        x, _ = item.getData()
        assert x is None or len(x) == 0


def test_estimate_runs_in_a_worker_with_progress(qtbot, tmp_path, monkeypatch) -> None:
    import tunespec.app.pipeline.image as pipeline

    calls = []

    def fake(session, sens, out, *, scheduler=None, progress=None, warn=None, **_):
        calls.append(scheduler)
        warn("the calibration cal.csv warned: Table 1 is poor")
        for k in range(5):
            progress((k + 1) / 5)
        _write_folder(out)
        return {"session": session}

    monkeypatch.setattr(pipeline, "estimate_images", fake)
    view = ImageView()
    qtbot.addWidget(view)
    view.scheduler_edit.setText(" tcp://cluster:8786 ")
    seen: list[float] = []
    with qtbot.waitSignal(view.estimate_finished, timeout=10_000):
        worker = view.estimate("S", "cal.csv", tmp_path / "out")
        worker.signals.progressed.connect(seen.append)
    assert view.image is not None and view.image.shape == (ROWS, COLS)
    qtbot.waitUntil(lambda: view.worker is None)
    assert seen and seen[-1] == pytest.approx(1.0)
    assert view.progress.isHidden()
    assert calls == ["tcp://cluster:8786"]
    # what the calibration said of itself stays in view beside the images
    assert view.warnings_label.isVisibleTo(view)
    assert view.warnings_label.text() == (
        "warning: the calibration cal.csv warned: Table 1 is poor"
    )
    _write_folder(tmp_path / "other")
    view.open_folder(tmp_path / "other")
    assert view.warnings_label.isHidden()


def _grab_rgb(widget, rect) -> np.ndarray:
    """The (rows, cols, 3) RGB pixels of ``rect`` of ``widget`` as drawn."""
    from PySide6.QtGui import QImage

    img = widget.grab(rect).toImage().convertToFormat(QImage.Format.Format_RGB888)
    rows = np.frombuffer(img.constBits(), np.uint8).reshape(
        img.height(), img.bytesPerLine()
    )
    return rows[:, : 3 * img.width()].reshape(img.height(), img.width(), 3)


def test_an_estimate_is_shown_at_once_over_its_wavelengths(
    qtbot, tmp_path, monkeypatch
) -> None:
    """Before a pixel is chosen, the regions' spectra alone set the wavelength
    axis (the empty band around the pixel's spectrum once put 0 nm in its range),
    and the preview is drawn as soon as the estimate is done."""
    import tunespec.app.pipeline.image as pipeline

    def fake(session, sens, out, **_):
        _write_folder(out)
        return {"session": session}

    monkeypatch.setattr(pipeline, "estimate_images", fake)
    view = ImageView()
    qtbot.addWidget(view)
    view.resize(900, 700)
    view.show()
    qtbot.waitExposed(view)
    with qtbot.waitSignal(view.estimate_finished, timeout=10_000):
        view.estimate("S", "cal.csv", tmp_path / "out")
    qtbot.waitUntil(lambda: view.worker is None)
    assert view.pixel is None
    box = view.spectrum_plot.getViewBox()
    qtbot.waitUntil(lambda: box.viewRange()[0][1] >= WL[-1])
    x0, x1 = box.viewRange()[0]
    assert 380.0 <= x0 <= WL[0] and WL[-1] <= x1 <= 730.0
    # a region off the image (its band empty) leaves the axis as it is
    view.roi_b.setPos((10 * COLS, 10 * ROWS))
    view._on_roi_changed()
    assert "B: off the image" in view.region_label.text()
    box.updateAutoRange()
    x0, x1 = box.viewRange()[0]
    assert 380.0 <= x0 <= WL[0] and WL[-1] <= x1 <= 730.0

    # the sRGB preview as drawn: each half its colour, not black
    gv = view.graphics
    for roi in (view.roi_a, view.roi_b):
        roi.hide()
    shown = gv.mapFromScene(view.image_item.sceneBoundingRect()).boundingRect()
    assert shown.width() > COLS and shown.height() > ROWS
    drawn = _grab_rgb(gv.viewport(), shown.adjusted(3, 3, -3, -3)).astype(float)
    half = drawn.shape[1] // 2
    np.testing.assert_allclose(
        drawn[:, : half - 3].mean(axis=(0, 1)), PREVIEW_LEFT, atol=3
    )
    np.testing.assert_allclose(
        drawn[:, half + 3 :].mean(axis=(0, 1)), PREVIEW_RIGHT, atol=3
    )
    # a scalar layer's levels are finite and within its values
    view.layer_combo.setCurrentText("wavelength")
    lo, hi = view.image_item.levels
    band = np.asarray(view.image_item.image)
    assert np.isfinite([lo, hi]).all() and band.min() <= lo < hi <= band.max()


def test_estimate_can_be_cancelled(qtbot, tmp_path, monkeypatch) -> None:
    import tunespec.app.pipeline.image as pipeline

    def slow(session, sens, out, *, should_stop=None, **_):
        while True:
            check_stop(should_stop)
            time.sleep(0.01)

    monkeypatch.setattr(pipeline, "estimate_images", slow)
    view = ImageView()
    qtbot.addWidget(view)
    worker = view.estimate("S", "cal.csv", tmp_path / "out")
    with qtbot.waitSignal(worker.signals.finished, timeout=10_000):
        view.cancel_button.click()
    assert view.status.text() == "cancelled"
    assert view.image is None
    assert Cancelled is not None


def test_scalar_layers_have_a_colour_bar_with_units_and_the_band_a_label(
    qtbot, tmp_path
) -> None:
    from tunespec.app.gui.plots.image_view import BAND_LABEL

    data = _write_folder(tmp_path / "img")
    view = ImageView()
    qtbot.addWidget(view)
    view.open_folder(tmp_path / "img")
    view.layer_combo.setCurrentText("sRGB")
    assert not view.colour_bar.isVisible()
    view.layer_combo.setCurrentText("u(L*)")
    assert view.colour_bar.isVisible()
    assert "L* units" in view.colour_bar.axis.labelText
    lo, hi = view.colour_bar.levels()
    np.testing.assert_allclose((lo, hi), view.image_item.levels, rtol=1e-6)
    view.layer_combo.setCurrentText("wavelength")
    view.band_spin.setValue(600)
    assert view.colour_bar.axis.labelText == (
        "reflectance factor at 600 nm (1 = white)"
    )
    lo, hi = view.colour_bar.levels()
    band = data["cube"][:, :, 20]
    assert lo == pytest.approx(np.percentile(band, 1), rel=1e-5)
    assert hi == pytest.approx(np.percentile(band, 99), rel=1e-5)
    # the band around a pixel's spectrum is named in the legend
    assert "pixel reflectance" in view.legend_label.text()
    assert BAND_LABEL in view.legend_label.text()


def _drag(view, start_rc, end_rc, *, shift=False) -> None:
    """A left-button drag on the image from pixel (row, col) to (row, col)."""
    from PySide6.QtCore import QEvent, QPointF, Qt
    from PySide6.QtGui import QMouseEvent
    from PySide6.QtWidgets import QApplication

    gv = view.graphics
    mods = (
        Qt.KeyboardModifier.ShiftModifier if shift else Qt.KeyboardModifier.NoModifier
    )

    def at(rc):
        scene = view.view_box.mapViewToScene(QPointF(rc[1], rc[0]))
        return QPointF(gv.mapFromScene(scene))

    a, b = at(start_rc), at(end_rc)
    vp = gv.viewport()
    left, none = Qt.MouseButton.LeftButton, Qt.MouseButton.NoButton

    def send(kind, pos, button, buttons):
        ev = QMouseEvent(kind, pos, vp.mapToGlobal(pos), button, buttons, mods)
        QApplication.sendEvent(vp, ev)

    send(QEvent.Type.MouseButtonPress, a, left, left)
    for t in np.linspace(0.1, 1.0, 6):
        send(QEvent.Type.MouseMove, a + (b - a) * float(t), none, left)
    send(QEvent.Type.MouseButtonRelease, b, left, none)
    QApplication.processEvents()


def test_a_drawn_region_gives_numpys_mean_and_spread_of_its_pixels(
    qtbot, tmp_path
) -> None:
    u_image = np.full((ROWS, COLS), 0.01)
    u_image[3:9, 4:14] = np.linspace(0.005, 0.03, 60).reshape(6, 10)
    data = _write_folder(tmp_path / "img", u_image)
    view = ImageView()
    qtbot.addWidget(view)
    view.resize(900, 700)
    view.show()
    qtbot.waitExposed(view)
    view.open_folder(tmp_path / "img")
    view.view_box.setRange(xRange=(0, COLS), yRange=(0, ROWS), padding=0)
    range_before = view.view_box.viewRange()
    # without the mode a drag pans; with it the same drag draws a region
    _drag(view, (3, 4), (9, 14))
    assert len(view.regions) == 2
    assert view.view_box.viewRange() != range_before
    view.view_box.setRange(xRange=(0, COLS), yRange=(0, ROWS), padding=0)
    view.draw_button.setChecked(True)
    _drag(view, (3, 4), (9, 14))
    assert [r.name for r in view.regions] == ["A", "B", "R1"]
    region = view.regions[2]
    r0, r1, c0, c1 = region.rect()
    assert (r0, r1, c0, c1) == (3, 9, 4, 14)
    pixels = data["cube"][r0:r1, c0:c1].reshape(-1, WL.size).astype(np.float64)
    x, mean = region.curve.getData()
    np.testing.assert_allclose(x, WL)
    np.testing.assert_allclose(mean, pixels.mean(axis=0), rtol=1e-6)
    _, upper = region.upper.getData()
    np.testing.assert_allclose(upper - mean, pixels.std(axis=0), rtol=1e-5)
    stats = view.region_stats(region)
    assert stats["n_pixels"] == 60
    # this region's pixels' mean u(reflectance) (written at float32)
    u = data["unc"][3:9, 4:14, 1].astype(np.float64).mean()
    assert stats["u_reflectance_mean"] == pytest.approx(u, rel=1e-6)
    assert "R1: 60 px" in view.region_label.text()
    assert f"mean u(reflectance) {u:.4f}" in view.region_label.text()
    # Shift draws without the mode; clearing keeps A and B
    view.draw_button.setChecked(False)
    _drag(view, (12, 18), (20, 30), shift=True)
    assert [r.name for r in view.regions][-1] == "R2"
    assert view.regions[3].rect() == (12, 20, 18, 30)
    view.clear_regions_button.click()
    assert [r.name for r in view.regions] == ["A", "B"]
