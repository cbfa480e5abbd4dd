"""The per-pixel images of a session: layers, a pixel's spectrum, regions compared.

:class:`ImageView` shows a finished image folder
(:func:`tunespec.core.io.image_formats.open_image_outputs`, memory-mapped, so a full
5D Mark III cube is not loaded): the sRGB preview or one layer (L*, a*, b*, u(L*),
u(reflectance), the reflectance at one wavelength). Hovering or clicking a pixel
plots its spectrum with its 95 % band (+-1.96 u); two rectangles (A and B) give
their mean L*a*b* and spread and the CIEDE2000 between their means. "Draw region"
(or Shift) makes a drag on the image draw a new rectangle instead of panning; every
region's mean spectrum is plotted with its spread over the region's pixels (mean +-
1 sd) and the mean of its pixels' standard uncertainty is given. It can also run
``estimate-image`` for a session on the worker pool (:class:`~tunespec.app.gui.workers.
Worker`) with a progress bar and Cancel, and shows the result when it is done.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QRectF, Qt, Signal, Slot
from PySide6.QtWidgets import (
    QComboBox,
    QGraphicsRectItem,
    QHBoxLayout,
    QLabel,
    QLineEdit,
    QProgressBar,
    QPushButton,
    QSpinBox,
    QVBoxLayout,
    QWidget,
)

from tunespec.core.intervals import COVERAGE_FACTOR_95

__all__ = ["LAYERS", "ImageView", "Region"]

#: The layers the view shows, in the combo box's order.
LAYERS = ("sRGB", "L*", "a*", "b*", "u(L*)", "u(reflectance)", "wavelength")
#: The colour bar's label of each scalar layer (quantity and unit; "wavelength"
#: names its band).
LAYER_LABELS = {
    "L*": "L* (CIELAB, D50; 0-100)",
    "a*": "a* (CIELAB, D50)",
    "b*": "b* (CIELAB, D50)",
    "u(L*)": "u(L*): standard uncertainty of L* (L* units)",
    "u(reflectance)": "u(reflectance): RMS standard uncertainty (reflectance factor)",
}
#: The legend of the band around a pixel's spectrum.
BAND_LABEL = "95 % band (±1.96 u)"
#: The legend of the band around a region's mean spectrum.
REGION_BAND_LABEL = "region mean ± 1 sd over its pixels"
#: Pens of the regions, in the order they are made (A, B, then drawn ones).
REGION_COLOURS = ("c", "m", (230, 120, 0), (0, 150, 0), (200, 0, 0), (120, 60, 200))


@dataclass(eq=False)
class Region:
    """A rectangle on the image and the items that plot its mean spectrum."""

    name: str
    roi: Any
    curve: Any
    band: Any
    upper: Any
    lower: Any

    def rect(self) -> tuple[int, int, int, int]:
        """(row0, row1, col0, col1) in image pixels."""
        return _rect(self.roi)


class DrawingViewBox(pg.ViewBox):
    """A view box whose left-button drag draws a rectangle (``region_drawn``, in
    image coordinates) instead of panning while :attr:`drawing` is on or Shift is
    held; otherwise it pans and zooms as any view box."""

    region_drawn = Signal(object)

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.drawing = False
        self.rubber = QGraphicsRectItem()
        self.rubber.setPen(pg.mkPen("y", width=1, style=Qt.PenStyle.DashLine))
        self.rubber.hide()
        self.addItem(self.rubber, ignoreBounds=True)

    def mouseDragEvent(self, ev: Any, axis: Any = None) -> None:
        shift = bool(ev.modifiers() & Qt.KeyboardModifier.ShiftModifier)
        if ev.button() != Qt.MouseButton.LeftButton or not (self.drawing or shift):
            super().mouseDragEvent(ev, axis)
            return
        ev.accept()
        start = self.mapSceneToView(ev.buttonDownScenePos())
        now = self.mapSceneToView(ev.scenePos())
        rect = QRectF(start, now).normalized()
        if ev.isFinish():
            self.rubber.hide()
            self.region_drawn.emit(rect)
        else:
            self.rubber.setRect(rect)
            self.rubber.show()


class ImageView(QWidget):
    """Images of a session, a pixel's spectrum and two regions compared.

    ``pixel_selected(row, col)`` is emitted when a pixel is clicked;
    ``estimate_finished(folder)`` when an estimate started here is shown.
    """

    pixel_selected = Signal(int, int)
    estimate_finished = Signal(str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        from tunespec.app.gui.workers import collect_on_gui_thread

        # zarr reads through a thread of its own (zarr_io) that must not collect
        # this view's Qt objects
        collect_on_gui_thread()
        self.image: Any = None
        self.worker: Any = None
        self.layer_combo = QComboBox()
        self.layer_combo.addItems(LAYERS)
        self.band_spin = QSpinBox()
        self.band_spin.setSuffix(" nm")
        self.band_spin.setToolTip("the band the 'wavelength' layer shows")
        self.band_spin.setEnabled(False)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1000)
        self.progress.hide()
        self.cancel_button = QPushButton("Cancel")
        self.cancel_button.hide()
        self.scheduler_edit = QLineEdit()
        self.scheduler_edit.setPlaceholderText("local threads")
        self.scheduler_edit.setToolTip(
            "a dask.distributed scheduler (tcp://host:8786) to estimate on; "
            "empty: Dask's local threads"
        )
        self.status = QLabel("Estimate images or open an image folder.")
        # what the calibration said of itself when the images were estimated
        self.warnings_label = QLabel("")
        self.warnings_label.setObjectName("image_warnings")
        self.warnings_label.setWordWrap(True)
        self.warnings_label.setTextFormat(Qt.TextFormat.PlainText)  # paths, "<"
        self.warnings_label.hide()
        self.region_label = QLabel("")
        self.region_label.setWordWrap(True)
        self.draw_button = QPushButton("Draw region")
        self.draw_button.setCheckable(True)
        self.draw_button.setToolTip(
            "on: a drag on the image draws a new region (Shift+drag does too); "
            "off: a drag pans"
        )
        self.clear_regions_button = QPushButton("Clear drawn regions")
        top = QHBoxLayout()
        top.addWidget(QLabel("Layer"))
        top.addWidget(self.layer_combo)
        self.band_label = QLabel("Band")
        top.addWidget(self.band_label)
        top.addWidget(self.band_spin)
        top.addWidget(self.draw_button)
        top.addWidget(self.clear_regions_button)
        top.addStretch(1)
        top.addWidget(QLabel("Scheduler"))
        top.addWidget(self.scheduler_edit)
        top.addWidget(self.progress)
        top.addWidget(self.cancel_button)

        self.graphics = pg.GraphicsLayoutWidget()
        self.view_box = DrawingViewBox(lockAspect=True, invertY=True)
        self.graphics.addItem(self.view_box, row=0, col=0)
        self.image_item = pg.ImageItem(axisOrder="row-major")
        self.view_box.addItem(self.image_item)
        # a scalar layer's colours in its units (hidden for sRGB)
        self.colour_map = pg.colormap.get("viridis")
        self.colour_bar = pg.ColorBarItem(
            values=(0.0, 1.0), colorMap=self.colour_map, interactive=False, width=15
        )
        self.graphics.addItem(self.colour_bar, row=0, col=1)
        self.colour_bar.hide()
        self.regions: list[Region] = []
        # white like the other spectra plots (the black curve was invisible on
        # pyqtgraph's default black)
        self.spectrum_plot = pg.PlotWidget(background="w")
        self.spectrum_plot.showGrid(x=True, y=True, alpha=0.25)
        self.spectrum_plot.getAxis("bottom").enableAutoSIPrefix(False)
        self.spectrum_plot.setLabel("bottom", "wavelength", units="nm")
        self.spectrum_plot.setLabel("left", "reflectance factor")
        self.spectrum_plot.setYRange(0.0, 1.0, padding=0.02)
        self.curve = self.spectrum_plot.plot(pen=pg.mkPen("k", width=2))
        self.upper = self.spectrum_plot.plot(pen=pg.mkPen(None))
        self.lower = self.spectrum_plot.plot(pen=pg.mkPen(None))
        self.band = pg.FillBetweenItem(
            self.lower, self.upper, brush=(100, 100, 255, 70)
        )
        # a band's extent is its edges' (which count); an empty band's own bounds
        # are the point (0, 0), which auto-ranged the wavelength axis from 0 nm
        self.spectrum_plot.addItem(self.band, ignoreBounds=True)
        self.roi_a = self.add_region(0, 10, 0, 10, name="A").roi
        self.roi_b = self.add_region(0, 10, 20, 30, name="B").roi
        for roi in (self.roi_a, self.roi_b):
            roi.hide()
        # beside the plot, not a legend item drawn over the curve (as the other
        # spectra plots do)
        self.legend_label = QLabel(
            "<span style='color:#000000'>&#9473;&#9473;</span> pixel reflectance"
            "&nbsp;&nbsp;&nbsp;<span style='color:#6464ff'>&#9608;</span> "
            f"{BAND_LABEL}&nbsp;&nbsp;&nbsp;coloured: {REGION_BAND_LABEL}"
        )
        self.legend_label.setObjectName("band_legend")
        self.pixel: tuple[int, int] | None = None
        self._out: str | None = None  # the folder being (or last) estimated into

        layout = QVBoxLayout(self)
        layout.addLayout(top)
        layout.addWidget(self.graphics, 3)
        layout.addWidget(self.spectrum_plot, 2)
        layout.addWidget(self.legend_label)
        layout.addWidget(self.region_label)
        layout.addWidget(self.warnings_label)
        layout.addWidget(self.status)

        self.layer_combo.currentTextChanged.connect(self._on_layer_combo_changed)
        self.band_spin.valueChanged.connect(self._on_band_spin_changed)
        self.cancel_button.clicked.connect(self._on_cancel_button_clicked)
        self._hover = pg.SignalProxy(
            self.graphics.scene().sigMouseMoved, rateLimit=20, slot=self._on_mouse_moved
        )
        self.graphics.scene().sigMouseClicked.connect(self._on_mouse_clicked)
        self.view_box.region_drawn.connect(self._on_view_box_region_drawn)
        self.draw_button.toggled.connect(self._on_draw_button_toggled)
        self.clear_regions_button.clicked.connect(self._on_clear_regions_clicked)

    # -- regions -------------------------------------------------------------------
    def add_region(
        self, row0: int, row1: int, col0: int, col1: int, *, name: str | None = None
    ) -> Region:
        """A new rectangle region (rows row0..row1-1, columns col0..col1-1) with
        its mean spectrum and spread plotted; named R1, R2, ... unless ``name``."""
        colour = REGION_COLOURS[len(self.regions) % len(REGION_COLOURS)]
        if name is None:
            name = f"R{sum(r.name.startswith('R') for r in self.regions) + 1}"
        roi = pg.RectROI(
            (col0, row0), (max(1, col1 - col0), max(1, row1 - row0)),
            pen=pg.mkPen(colour, width=2), snapSize=1.0, scaleSnap=True,
            translateSnap=True,
        )  # fmt: skip
        self.view_box.addItem(roi)
        pen = pg.mkPen(colour, width=2)
        curve = self.spectrum_plot.plot(pen=pen, name=name)
        upper = self.spectrum_plot.plot(pen=pg.mkPen(None))
        lower = self.spectrum_plot.plot(pen=pg.mkPen(None))
        fill = pg.mkColor(colour)
        fill.setAlpha(45)
        band = pg.FillBetweenItem(lower, upper, brush=fill)
        self.spectrum_plot.addItem(band, ignoreBounds=True)  # as the pixel's band
        region = Region(name, roi, curve, band, upper, lower)
        self.regions.append(region)
        roi.sigRegionChangeFinished.connect(self._on_roi_changed)
        if self.image is not None:
            self._on_roi_changed()
        return region

    def remove_drawn_regions(self) -> None:
        """Remove the drawn regions (A and B stay)."""
        for region in self.regions[2:]:
            self.view_box.removeItem(region.roi)
            for item in (region.curve, region.band, region.upper, region.lower):
                self.spectrum_plot.removeItem(item)
        del self.regions[2:]
        if self.image is not None:
            self._on_roi_changed()

    def region_stats(self, region: Region) -> dict[str, Any]:
        """The region's statistics (:meth:`SpectralImage.region
        <tunespec.core.io.image_formats.SpectralImage.region>`): mean L*a*b*,
        mean spectrum and its sd over the pixels, the pixels' mean u(reflectance)."""
        return dict(self.image.region(*region.rect()))

    def _show_region_spectra(self) -> list[dict[str, Any]]:
        wl = self.image.wavelength_nm
        stats = []
        for region in self.regions:
            try:
                s = self.region_stats(region)
            except Exception:  # a region moved off the image: nothing to plot
                s = None
            if s is None:
                for item in (region.curve, region.upper, region.lower):
                    item.setData([], [])
            else:
                m, sd = s["reflectance_mean"], s["reflectance_std"]
                region.curve.setData(wl, m)
                region.upper.setData(wl, m + sd)
                region.lower.setData(wl, m - sd)
            stats.append(s)
        return stats

    # -- data ----------------------------------------------------------------------
    def open_folder(self, folder: str | Path) -> None:
        """Show a finished image folder (see ``tunespec estimate-image``); the
        warnings of an estimate stay shown with its own folder only."""
        from tunespec.core.io.image_formats import open_image_outputs

        self.set_image(open_image_outputs(folder))
        if str(folder) != self._out:
            self.warnings_label.clear()
            self.warnings_label.hide()

    def set_image(self, image: Any) -> None:
        """Show a :class:`~tunespec.core.io.image_formats.SpectralImage`."""
        self.image = image
        wl = image.wavelength_nm
        self.band_spin.blockSignals(True)
        self.band_spin.setRange(int(wl[0]), int(wl[-1]))
        self.band_spin.setSingleStep(round(wl[1] - wl[0]) if wl.size > 1 else 1)
        self.band_spin.setValue(int(wl[wl.size // 2]))
        self.band_spin.blockSignals(False)
        rows, cols = image.shape
        self.pixel = None  # the last image's pixel spectrum is not this image's
        for item in (self.curve, self.upper, self.lower):
            item.setData([], [])
        self.remove_drawn_regions()
        self.roi_a.setPos((round(cols * 0.1), round(rows * 0.1)))
        self.roi_a.setSize((max(2, cols // 8), max(2, rows // 8)))
        self.roi_b.setPos((round(cols * 0.6), round(rows * 0.6)))
        self.roi_b.setSize((max(2, cols // 8), max(2, rows // 8)))
        self.roi_a.show()
        self.roi_b.show()
        self.show_layer(self.layer_combo.currentText())
        self.view_box.autoRange()
        self.status.setText(
            f"{cols} x {rows} px, {wl.size} bands "
            f"({wl[0]:g}-{wl[-1]:g} nm): {image.folder}"
        )
        self._on_roi_changed()

    def layer_data(self, name: str) -> np.ndarray:
        """The array the view shows for layer ``name``."""
        img = self.image
        if name == "sRGB":
            return img.srgb()
        if name in ("L*", "a*", "b*"):
            return np.asarray(img.lab[:, :, ("L*", "a*", "b*").index(name)])
        if name == "u(L*)":
            return np.asarray(img.uncertainty[:, :, 0])
        if name == "u(reflectance)":
            return np.asarray(img.uncertainty[:, :, 1])
        if name == "wavelength":
            k = int(np.argmin(np.abs(img.wavelength_nm - self.band_spin.value())))
            return np.asarray(img.cube[:, :, k])
        raise ValueError(f"unknown layer {name!r}")

    def show_layer(self, name: str) -> None:
        """Switch the image to layer ``name`` (one of :data:`LAYERS`)."""
        if self.image is None:
            return
        data = self.layer_data(name)
        self.band_spin.setEnabled(name == "wavelength")
        if data.ndim == 3:
            self.image_item.setLookupTable(None)
            self.image_item.setImage(data, autoLevels=False, levels=None)
            self.colour_bar.hide()
        else:
            finite = data[np.isfinite(data)]
            lo, hi = np.percentile(finite, [1, 99]) if finite.size else (0.0, 1.0)
            levels = (float(lo), float(max(hi, lo + 1e-6)))
            self.image_item.setImage(data, autoLevels=False, levels=levels)
            self.image_item.setColorMap(self.colour_map)
            self.colour_bar.setLevels(levels)
            self.colour_bar.axis.setLabel(self.layer_label(name))
            self.colour_bar.show()

    def layer_label(self, name: str) -> str:
        """What a scalar layer's colour bar says: the quantity and its unit."""
        if name == "wavelength":
            return f"reflectance factor at {self.band_spin.value()} nm (1 = white)"
        return LAYER_LABELS[name]

    def show_pixel(self, row: int, col: int) -> None:
        """Plot the spectrum of pixel (row, col) with its 95 % band."""
        img = self.image
        if img is None or not (0 <= row < img.shape[0] and 0 <= col < img.shape[1]):
            return
        r = np.asarray(img.cube[row, col], dtype=np.float64)
        u = float(img.uncertainty[row, col, 1])
        wl = img.wavelength_nm
        self.pixel = (row, col)
        self.curve.setData(wl, r)
        self.upper.setData(wl, r + COVERAGE_FACTOR_95 * u)
        self.lower.setData(wl, r - COVERAGE_FACTOR_95 * u)
        L, a, b = (float(v) for v in img.lab[row, col])
        self.status.setText(
            f"pixel ({col}, {row}): L*a*b* {L:.2f} {a:.2f} {b:.2f}, "
            f"u(L*) {float(img.uncertainty[row, col, 0]):.3f}, "
            f"RMS u(reflectance) {u:.4f}"
        )

    def region_text(self, stats: list[dict[str, Any] | None] | None = None) -> str:
        """Mean +- spread of every region, their pixels' mean u(reflectance), and
        the CIEDE2000 between the means of A and B."""
        from tunespec.core.colorimetry import delta_e_2000

        if stats is None:
            stats = [self.region_stats(r) for r in self.regions]
        parts = []
        for region, s in zip(self.regions, stats, strict=True):
            if s is None:
                parts.append(f"{region.name}: off the image")
                continue
            m, sd = s["lab_mean"], s["lab_std"]
            parts.append(
                f"{region.name}: {s['n_pixels']} px, L*a*b* {m[0]:.2f} {m[1]:.2f} "
                f"{m[2]:.2f} (sd {sd[0]:.2f} {sd[1]:.2f} {sd[2]:.2f}), "
                f"mean u(reflectance) {s['u_reflectance_mean']:.4f}"
            )
        if stats[0] is not None and stats[1] is not None:
            de = float(delta_e_2000(stats[0]["lab_mean"], stats[1]["lab_mean"]))
            parts.append(f"dE00(A, B) = {de:.2f}")
        return "; ".join(parts)

    # -- estimating ------------------------------------------------------------------
    def estimate(
        self, session: str | Path, sensitivities: str | Path, out: str | Path
    ) -> Any:
        """Run ``estimate-image`` on the worker pool (on the Dask scheduler named in
        :attr:`scheduler_edit`, else locally); the result is shown when done, and
        what the calibration said of itself (its warnings, a missing side file)
        above the status line."""
        from tunespec.app.gui.workers import Worker
        from tunespec.app.pipeline import image as pipeline

        scheduler = self.scheduler_edit.text().strip() or None
        self.worker = Worker(
            pipeline.estimate_images, str(session), str(sensitivities), str(out),
            scheduler=scheduler, warns=True,
        )  # fmt: skip
        self.warnings_label.clear()
        self.warnings_label.hide()
        self.worker.signals.warned.connect(self._on_worker_warned)
        self.worker.signals.progressed.connect(self._on_worker_progressed)
        self.worker.signals.returned.connect(self._on_worker_returned)
        self.worker.signals.errored.connect(self._on_worker_errored)
        self.worker.signals.finished.connect(self._on_worker_finished)
        self._out = str(out)
        self.progress.setValue(0)
        self.progress.show()
        self.cancel_button.show()
        self.status.setText(f"estimating images of {session} ...")
        return self.worker.start()

    # -- slots -------------------------------------------------------------------------
    @Slot(str)
    def _on_layer_combo_changed(self, name: str) -> None:
        self.show_layer(name)

    @Slot(int)
    def _on_band_spin_changed(self, _value: int) -> None:
        if self.layer_combo.currentText() == "wavelength":
            self.show_layer("wavelength")

    def _on_mouse_moved(self, event: Any) -> None:
        pos = event[0]
        if self.image is None or not self.view_box.sceneBoundingRect().contains(pos):
            return
        p = self.view_box.mapSceneToView(pos)
        self.show_pixel(int(p.y()), int(p.x()))

    def _on_mouse_clicked(self, event: Any) -> None:
        if self.image is None:
            return
        p = self.view_box.mapSceneToView(event.scenePos())
        row, col = int(p.y()), int(p.x())
        self.show_pixel(row, col)
        self.pixel_selected.emit(row, col)

    def _on_roi_changed(self, *_args: Any) -> None:
        if self.image is not None:
            self.region_label.setText(self.region_text(self._show_region_spectra()))

    def _on_view_box_region_drawn(self, rect: QRectF) -> None:
        if self.image is None:
            return
        rows, cols = self.image.shape
        r0, r1 = max(0, round(rect.top())), min(rows, round(rect.bottom()))
        c0, c1 = max(0, round(rect.left())), min(cols, round(rect.right()))
        if r1 - r0 < 1 or c1 - c0 < 1:
            self.status.setText("a region needs at least one pixel: drag further")
            return
        region = self.add_region(r0, r1, c0, c1)
        self.status.setText(f"region {region.name}: rows {r0}-{r1 - 1}, "
                            f"columns {c0}-{c1 - 1}")  # fmt: skip

    @Slot(bool)
    def _on_draw_button_toggled(self, on: bool) -> None:
        self.view_box.drawing = on

    @Slot()
    def _on_clear_regions_clicked(self) -> None:
        self.remove_drawn_regions()

    @Slot()
    def _on_cancel_button_clicked(self) -> None:
        if self.worker is not None:
            self.worker.abort()
            self.status.setText("cancelling ...")

    @Slot(float)
    def _on_worker_progressed(self, fraction: float) -> None:
        self.progress.setValue(round(1000 * fraction))

    @Slot(object)
    def _on_worker_returned(self, _provenance: object) -> None:
        self.open_folder(self._out)
        self.estimate_finished.emit(self._out)

    @Slot(str)
    def _on_worker_warned(self, line: str) -> None:
        shown = self.warnings_label.text()
        self.warnings_label.setText(
            f"{shown}\nwarning: {line}" if shown else f"warning: {line}"
        )
        self.warnings_label.show()

    @Slot(object)
    def _on_worker_errored(self, exc: object) -> None:
        from tunespec.core.progress import Cancelled

        self.status.setText(
            "cancelled" if isinstance(exc, Cancelled) else f"estimate failed: {exc}"
        )

    @Slot()
    def _on_worker_finished(self) -> None:
        self.progress.hide()
        self.cancel_button.hide()
        self.worker = None


def _rect(roi: Any) -> tuple[int, int, int, int]:
    """(row0, row1, col0, col1) of a rectangle ROI in image pixels."""
    x, y = roi.pos()
    w, h = roi.size()
    return round(y), round(y + h), round(x), round(x + w)
