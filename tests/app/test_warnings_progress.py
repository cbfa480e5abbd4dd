"""Issue 13, items 2 and 3: progress through exposure metering, and pipeline warnings
shown in the GUI (the step's badge, the step list, the log) and in the results.

The weak LED is real: the simulated light gets an LED spectral file in which LED700
emits 1e-5 of the shipped model's power, so metering reaches only a few percent of
full scale (the dark level) at the longest exposure allowed and ``devices.capture``
warns.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.app.test_wizard import STEP_TIMEOUT_MS, run_step
from tests.app.test_wizard import window as window  # the fixture
from tunespec.app.gui.wizard.step_page import StepState
from tunespec.core.datasets import resource_path
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv

WEAK_LED = "LED700"
#: The weak LED's power relative to the shipped model.
WEAK_FACTOR = 1e-5


@pytest.fixture
def weak_leds(tmp_path):
    """The shipped 22-LED model with LED700 at 1e-5 of its power."""
    leds = read_spectra_csv(resource_path("leds", "cal1_model_22.csv"))
    values = leds.values.copy()
    values[leds.names.index(WEAK_LED)] *= WEAK_FACTOR
    path = tmp_path / "weak_leds.csv"
    write_spectra_csv(leds.with_values(values), path)
    return path


def _dark_page_ready(qtbot, window, folder):
    """A new measurement, the devices connected, the dark frame step shown."""
    wizard = window.wizard_panel
    assert wizard.new_measurement(folder)
    run_step(qtbot, wizard, wizard.connect_page)
    page = wizard.dark_page
    wizard.go_to(wizard.pages.index(page))
    return wizard, page


def _connect_weak(qtbot, window, weak_leds, folder):
    wizard = window.wizard_panel
    assert wizard.new_measurement(folder)
    window.device_panel.light_spec_combo.setEditText(f"sim?leds={weak_leds}")
    run_step(qtbot, wizard, wizard.connect_page)
    return wizard


def _weak_warning(warnings):
    hits = [w for w in warnings if WEAK_LED in w and "of full scale" in w]
    assert len(hits) == 1, warnings
    return hits[0]


def test_weak_led_warning_reaches_the_step_the_list_and_the_log(
    window, qtbot, tmp_path, weak_leds
):
    wizard = _connect_weak(qtbot, window, weak_leds, tmp_path / "m")
    page = wizard.dark_page
    run_step(qtbot, wizard, page)
    text = _weak_warning(page.warnings)
    assert text.startswith(f"{WEAK_LED}: only ")
    # the level metered is a fraction of a percent: the warning states it
    level = float(text.split("only ")[1].split("%")[0])
    assert 0.0 <= level < 5.0
    # the badge on the page, the mark in the step list and its tooltip
    assert page.warning_label.isVisible()
    assert "1 warning" in page.warning_label.text()
    item = wizard.step_list.item(wizard.pages.index(page))
    assert "⚠ 1" in item.text() and text in item.toolTip()
    assert text in window.log_panel.plain_text()
    # no other step carries it
    assert not wizard.white_page.warnings
    # kept beside the session: a reopened measurement shows it again
    stored = json.loads(
        (tmp_path / "m" / "chart" / "capture_warnings.json").read_text()
    )
    assert stored["warnings"] == [text]
    assert wizard.open_measurement(tmp_path / "m")
    assert wizard.dark_page.state == StepState.DONE
    assert wizard.dark_page.warnings == [text]


def test_progress_is_monotonic_through_metering_and_names_the_stage(
    window, qtbot, tmp_path
):
    _, page = _dark_page_ready(qtbot, window, tmp_path / "m")
    # every stage the job names, with the fraction done when it starts
    stages: list[tuple[str, float]] = []
    page.stage_changed.connect(lambda text: stages.append((text, page.clock.fraction)))
    # what the bar shows (redrawn at most every PROGRESS_PERIOD_MS)
    shown: list[tuple[str, int]] = []
    page.progress_bar.valueChanged.connect(
        lambda v: shown.append((page.progress_bar.format(), v))
    )
    page.start_button.click()
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    assert page.state == StepState.DONE
    names = [t for t, _ in stages]
    assert names[:22] == [
        f"metering {c}, {i} of 22"
        for i, c in enumerate(window.measurement.session("chart").settings.channels, 1)
    ]
    assert names[22].startswith("dark frame 1 of ")
    fractions = [f for _, f in stages]
    assert np.all(np.diff(fractions) >= 0)
    # 22 LEDs metered, then the dark frames: metering is not the whole step (the
    # bar showed 100 % from the first metered LED on)
    assert 0.0 < fractions[21] < 0.9
    values = [v for _, v in shown]
    assert np.all(np.diff(values) >= 0), values
    assert values[-1] == 1000
    # whatever the bar showed while metering (redraws are throttled) was below 90 %
    assert all(v < 900 for f, v in shown if f.startswith("metering LED")), shown
    # the stage is in the bar's text while running, gone when done
    assert page.progress_bar.format() == "%p %"


def test_progress_resets_on_abort_during_metering(window, qtbot, tmp_path):
    wizard, page = _dark_page_ready(qtbot, window, tmp_path / "m")
    reached: list[float] = []

    def on_stage(text: str) -> None:
        if text.startswith("metering LED495") and not reached:
            reached.append(page.clock.fraction)
            page.abort_button.click()

    page.stage_changed.connect(on_stage)
    page.start_button.click()
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    assert page.state == StepState.ABORTED
    assert reached and 0 < reached[0] < 1
    assert page.progress_bar.value() == 0
    assert page.progress_bar.format() == "%p %"
    assert "stopped after" in page.remaining_label.text()
    # retaken, it resumes the metering and ends at 100 %
    run_step(qtbot, wizard, page)
    assert page.progress_bar.value() == 1000


@pytest.mark.slow
def test_weak_led_warning_reaches_calibration_json_and_the_report(
    window, qtbot, tmp_path, weak_leds
):
    wizard = _connect_weak(qtbot, window, weak_leds, tmp_path / "m")
    run_step(qtbot, wizard, wizard.dark_page)
    # retaken, the exposures are not metered again, and the LED is as weak as it was
    run_step(qtbot, wizard, wizard.dark_page)
    assert "Retake" in wizard.dark_page.start_button.text()
    _weak_warning(wizard.dark_page.warnings)
    for page in (
        wizard.white_page,
        wizard.chart_page,
        wizard.calibrate_page,
        wizard.sample_page,
        wizard.estimate_page,
        wizard.export_page,
    ):
        run_step(qtbot, wizard, page)
    text = _weak_warning(wizard.dark_page.warnings)
    cal = json.loads((tmp_path / "m" / "calibration" / "calibration.json").read_text())
    assert f"capture: {text}" in cal["warnings"]
    assert f"capture: {text}" in wizard.calibrate_page.warnings
    # the sample was taken with the chart's exposures: nothing metered, no warning
    # of its own, but the calibration it rests on carries one
    export = window.measurement.export
    html = export.paths["report_html"].read_text()
    assert f"chart: capture: {text}" in html.replace("&#x27;", "'")
