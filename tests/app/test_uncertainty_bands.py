"""The GUI draws the calibration's and the estimate's uncertainties as 95 % bands."""

from __future__ import annotations

import numpy as np

from tunespec.app.gui.plots.reflectance_plot import ReflectancePlot
from tunespec.app.gui.plots.sensitivity_plot import SensitivityPlot
from tunespec.core.spectra import Spectra

WL = np.arange(400.0, 701.0, 10.0)


def _band_edges(band) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = band.curves_
    return lo.getData()[1], hi.getData()[1]


def test_sensitivity_bands_are_plus_minus_1_96_u(qtbot) -> None:
    plot = SensitivityPlot()
    qtbot.addWidget(plot)
    s = Spectra(WL, np.stack([np.linspace(0, 2, WL.size)] * 3), ("R", "G", "B"))
    std = np.full((3, WL.size), 0.1)
    plot.show_sensitivity(s, std=std)
    assert sorted(plot.bands) == ["B 95 %", "G 95 %", "R 95 %"]
    lo, hi = _band_edges(plot.bands["G 95 %"])
    # curves are shown peak-normalised (peak 2), so is the band
    assert np.allclose(hi - lo, 2 * 1.96 * 0.1 / 2.0)
    plot.show_sensitivity(s)  # no uncertainty: no band left over
    assert plot.bands == {}


def test_reflectance_band_follows_the_selected_patch(qtbot) -> None:
    plot = ReflectancePlot()
    qtbot.addWidget(plot)
    est = Spectra(WL, [np.full(WL.size, 0.4), np.full(WL.size, 0.6)], ("A", "B"))
    std = np.array([np.full(WL.size, 0.01), np.full(WL.size, 0.03)])
    plot.set_data(est, std=std)
    plot.select_patch("B")
    lo, hi = _band_edges(plot.bands["95 %"])
    assert np.allclose(lo, 0.6 - 1.96 * 0.03) and np.allclose(hi, 0.6 + 1.96 * 0.03)
    assert "95 %" in plot.title_label.text()
    plot.set_data(est)
    assert "95 %" not in plot.bands


def test_a_band_of_the_same_name_is_updated_in_place(qtbot) -> None:
    from tunespec.app.gui.plots.spectra_plot import SpectraPlot

    plot = SpectraPlot("bands", "reflectance factor")
    qtbot.addWidget(plot)
    wl = np.arange(400.0, 701.0, 10.0)
    first = plot.set_band("R 95 %", wl, wl * 0, wl * 0 + 1)
    again = plot.set_band("R 95 %", wl, wl * 0 + 0.2, wl * 0 + 0.7, colour="r")
    assert again is first and list(plot.bands) == ["R 95 %"]
    lo, hi = again.curves_
    np.testing.assert_allclose(lo.getData()[1], 0.2)
    np.testing.assert_allclose(hi.getData()[1], 0.7)
    assert again.brush().color().red() == 255
