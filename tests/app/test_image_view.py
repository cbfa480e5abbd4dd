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


def _write_folder(folder) -> dict[str, np.ndarray]:
    """A finished image folder: left half one colour, right half another."""
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
    xyz = np.full((ROWS, COLS, 3), 30.0, np.float32)
    out = ImageOutputs.create(folder, (ROWS, COLS), WL, block_rows=8,
                              provenance={"session": "test"})  # fmt: skip
    for r0 in range(0, ROWS, 8):
        sl = slice(r0, r0 + 8)
        out.write_rows(r0, cube[sl], xyz[sl], lab[sl], unc[sl])
    out.write_preview(np.zeros((ROWS, COLS, 3), np.uint8))
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


def test_estimate_runs_in_a_worker_with_progress(qtbot, tmp_path, monkeypatch) -> None:
    import tunespec.app.pipeline.image as pipeline

    calls = []

    def fake(session, sens, out, *, scheduler=None, progress=None, should_stop=None):
        calls.append(scheduler)
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


def test_estimate_can_be_cancelled(qtbot, tmp_path, monkeypatch) -> None:
    import tunespec.app.pipeline.image as pipeline

    def slow(session, sens, out, *, scheduler=None, progress=None, should_stop=None):
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
