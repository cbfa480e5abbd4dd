"""The base of every spectral plot: a pyqtgraph plot with wavelength on x.

Subclasses (:class:`~tunespec.app.gui.plots.spd_plot.SpdPlot`,
:class:`~tunespec.app.gui.plots.sensitivity_plot.SensitivityPlot`,
:class:`~tunespec.app.gui.plots.reflectance_plot.ReflectancePlot`) only decide what
curves to show; drawing and clearing are shared here.
"""

from __future__ import annotations

from collections.abc import Sequence
from html import escape

import numpy as np
import pyqtgraph as pg
from numpy.typing import ArrayLike
from PySide6.QtCore import Qt
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget

__all__ = ["CHANNEL_COLOURS", "SpectraPlot"]

#: Pens for R, G, B curves.
CHANNEL_COLOURS = {"R": (214, 39, 40), "G": (44, 160, 44), "B": (31, 119, 180)}


class SpectraPlot(QWidget):
    """A titled plot of spectra against wavelength in nm.

    Parameters
    ----------
    title
        Shown above the plot.
    y_label, y_units
        Left axis label and unit.
    """

    def __init__(
        self,
        title: str,
        y_label: str,
        y_units: str | None = None,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.plot_widget = pg.PlotWidget(background="w")
        self.plot_item = self.plot_widget.getPlotItem()
        self.plot_item.setLabel("bottom", "wavelength", units="nm")
        self.plot_item.setLabel("left", y_label, units=y_units)
        self.plot_item.showGrid(x=True, y=True, alpha=0.25)
        # SI prefixes on "nm" would print "knm"-style nonsense when zoomed out
        self.plot_item.getAxis("bottom").enableAutoSIPrefix(False)
        # the legend is a line of text under the plot: never over the curves, and
        # it wraps instead of being cut off when the plot is narrow
        self.legend = QLabel()
        self.legend.setWordWrap(True)
        self.legend.setTextFormat(Qt.TextFormat.RichText)
        self._legend_entries: dict[str, tuple[str, bool]] = {}
        self.title_label = QLabel(title)
        self.title_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.title_label.setStyleSheet("font-weight: bold")
        self.message_label = QLabel("")
        self.message_label.setWordWrap(True)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addWidget(self.title_label)
        layout.addWidget(self.plot_widget, 1)
        layout.addWidget(self.legend)
        layout.addWidget(self.message_label)
        self.curves: dict[str, pg.PlotDataItem] = {}
        self.bands: dict[str, pg.FillBetweenItem] = {}
        self._update_empty()

    @property
    def empty(self) -> bool:
        """Whether no curve is shown."""
        return not self.curves

    def _update_empty(self) -> None:
        """An empty plot shows no axes: pyqtgraph's default 0-1 range would read as
        data (ticks 0.1 ... 0.9 of nothing); the message under it says why."""
        shown = bool(self.curves)
        for side in ("left", "bottom"):
            self.plot_item.showAxis(side, shown)
        self.plot_item.showGrid(x=shown, y=shown, alpha=0.25)
        self.legend.setVisible(shown)
        self._update_legend()

    def _update_legend(self) -> None:
        entries = []
        for name, (colour, dashed) in self._legend_entries.items():
            sample = "╍╍╍" if dashed else "━━━"
            entries.append(
                f"<span style='color:{colour}'>{sample}</span>&nbsp;"
                + escape(name).replace(" ", "&nbsp;")  # wrap between entries only
            )
        self.legend.setText(" &nbsp;&nbsp; ".join(entries))

    def clear(self) -> None:
        """Remove every curve and band."""
        self.plot_item.clear()
        self._legend_entries.clear()
        self.curves.clear()
        self.bands.clear()
        self._update_empty()

    def set_band(
        self,
        name: str,
        wavelength_nm: ArrayLike,
        lower: ArrayLike,
        upper: ArrayLike,
        *,
        colour: Sequence[int] | str = "k",
        alpha: int = 60,
    ) -> pg.FillBetweenItem:
        """Shade between ``lower`` and ``upper`` (an uncertainty interval).

        A band of the same name is updated in place; bands are not in the legend
        (the title says what they are).
        """
        x = np.asarray(wavelength_nm, dtype=float)
        brush = pg.mkColor(colour)
        brush.setAlpha(alpha)
        band = self.bands.get(name)
        if band is not None:  # in place: new items cost the GUI thread far more
            lo, hi = band.curves_
            lo.setData(x, np.asarray(lower, dtype=float))
            hi.setData(x, np.asarray(upper, dtype=float))
            band.setBrush(brush)
            return band
        lo = pg.PlotDataItem(x, np.asarray(lower, dtype=float))
        hi = pg.PlotDataItem(x, np.asarray(upper, dtype=float))
        band = pg.FillBetweenItem(lo, hi, brush=brush)
        band.setZValue(-10)
        band.curves_ = (lo, hi)  # keep the edges alive with the band
        self.plot_item.addItem(band)
        self.bands[name] = band
        return band

    def remove_band(self, name: str) -> None:
        """Remove the band called ``name`` (if shown)."""
        band = self.bands.pop(name, None)
        if band is not None:
            self.plot_item.removeItem(band)

    def add_curve(
        self,
        name: str,
        wavelength_nm: ArrayLike,
        values: ArrayLike,
        *,
        colour: Sequence[int] | str = "k",
        dashed: bool = False,
        width: float = 2.0,
    ) -> pg.PlotDataItem:
        """Draw one curve; a curve of the same name is updated in place (cheap)."""
        style = Qt.PenStyle.DashLine if dashed else Qt.PenStyle.SolidLine
        pen = pg.mkPen(colour, width=width, style=style)
        x = np.asarray(wavelength_nm, dtype=float)
        y = np.asarray(values, dtype=float)
        item = self.curves.get(name)
        if item is None:
            item = self.plot_item.plot(x, y, pen=pen)
            self.curves[name] = item
        else:
            item.setData(x, y)
            item.setPen(pen)
        entry = (pen.color().name(), dashed)
        if self._legend_entries.get(name) != entry:
            self._legend_entries[name] = entry
            self._update_empty()
        return item

    def remove_curve(self, name: str) -> None:
        """Remove the curve called ``name`` (if shown)."""
        item = self.curves.pop(name, None)
        if item is not None:
            self.plot_item.removeItem(item)
            self._legend_entries.pop(name, None)
            self._update_empty()

    def set_title(self, text: str) -> None:
        """Change the title above the plot."""
        self.title_label.setText(text)

    def set_message(self, text: str) -> None:
        """A line under the plot (what is shown, or why nothing is)."""
        self.message_label.setText(text)
