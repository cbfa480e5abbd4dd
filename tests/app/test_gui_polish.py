"""What the operator sees: legends beside the curves, empty plots without a fake
axis, status texts that match the state, buttons that stay put, Retake labels."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
import pytest
from PySide6.QtCore import QPoint

from tests.app.helpers import main_window
from tests.app.test_wizard import SIM, run_step
from tunespec.app.gui.plots.sensitivity_plot import SensitivityPlot
from tunespec.app.gui.plots.spd_plot import SpdPlot
from tunespec.core.spectra import Spectra


def _rgb(scale: float) -> Spectra:
    wl = np.arange(400.0, 701.0, 10.0)
    rows = [np.exp(-(((wl - c) / 40) ** 2)) * scale for c in (600, 540, 450)]
    return Spectra(wl, np.array(rows), ("R", "G", "B"))


@pytest.fixture
def window(qtbot, tmp_path):
    with main_window(qtbot, tmp_path, SIM, exposed=True) as w:
        yield w


def test_the_legend_does_not_cover_the_curves(qtbot):
    plot = SensitivityPlot()
    qtbot.addWidget(plot)
    plot.resize(330, 400)  # narrow: the legend wraps, nothing is cut off
    plot.show()
    qtbot.waitExposed(plot)
    plot.show_sensitivity(_rgb(2.0), _rgb(1.0), reference_label="database")
    qtbot.wait(20)
    assert plot.legend.isVisible()
    for name in plot.curves:
        assert name.replace(" ", "&nbsp;") in plot.legend.text()
    # the legend is beside the plot's scene, not an item drawn over the curves
    items = plot.plot_item.getViewBox().addedItems
    assert all(isinstance(i, pg.PlotDataItem) for i in items)
    assert plot.legend.geometry().top() >= plot.plot_widget.geometry().bottom()
    assert plot.legend.geometry().right() <= plot.width()
    assert plot.legend.heightForWidth(plot.legend.width()) <= plot.legend.height()


def test_an_empty_plot_shows_no_made_up_axis(qtbot):
    plot = SensitivityPlot()
    qtbot.addWidget(plot)
    left, bottom = (plot.plot_item.getAxis(s) for s in ("left", "bottom"))
    # (graphics items: isVisible() is their own flag, the widget need not be shown)
    assert plot.empty and not left.isVisible() and not bottom.isVisible()
    assert plot.legend.isHidden()
    assert "Calibrate" in plot.message_label.text()
    plot.show_sensitivity(_rgb(1.0))
    assert left.isVisible() and bottom.isVisible()
    plot.clear_data()
    assert plot.empty and not left.isVisible()


def test_spd_plot_says_connect_only_when_not_connected(qtbot):
    plot = SpdPlot()
    qtbot.addWidget(plot)
    assert plot.message_label.text().startswith("Connect the light source")
    plot.set_channel_names(["LED410", "LED420"])
    assert "Connect the light source" not in plot.message_label.text()
    plot.set_connected(False)
    assert plot.message_label.text().startswith("Connect the light source")


def test_connected_window_does_not_ask_to_connect(window, qtbot, tmp_path):
    wizard = window.wizard_panel
    assert wizard.new_measurement(tmp_path / "m")
    run_step(qtbot, wizard, wizard.connect_page)
    # the window follows the device thread's signal as the page does
    qtbot.waitUntil(
        lambda: "Connect the light source" not in window.spd_plot.message_label.text()
    )


def test_buttons_stay_put_and_retake_says_what(window, qtbot, tmp_path):
    wizard = window.wizard_panel
    assert wizard.new_measurement(tmp_path / "m")

    def where(button) -> QPoint:
        qtbot.wait(10)
        return button.mapTo(wizard, QPoint(0, 0))

    places = {}
    for i, page in enumerate(wizard.pages):
        wizard.go_to(i)
        places[page.title] = (where(page.start_button), where(wizard.next_button))
    assert len(set(places.values())) == 1, places

    page = wizard.dark_page
    wizard.go_to(wizard.pages.index(page))
    start, abort = where(page.start_button), where(page.abort_button)
    page.mark_done("A long message. " * 40)
    assert page.start_button.text() == "Retake dark frames"
    assert (where(page.start_button), where(page.abort_button)) == (start, abort)
    labels = {p.key: p.start_button for p in wizard.pages}
    for p in wizard.pages[1:]:
        p.mark_done("done")
    assert [labels[k].text() for k in ("white", "target", "calibrate")] == [
        "Retake white frames",
        "Retake chart frames",
        "Recalibrate",
    ]
