"""The measurement wizard driven to the end on the simulated bench (small frames)."""

from __future__ import annotations

import json
import re
import time

import numpy as np
import pytest

from tests.app.helpers import main_window
from tunespec.app.gui.wizard.step_page import StepState
from tunespec.core.spectra import CALIBRATION_GRID

#: Small enough to be quick, large enough for 140 ROIs of a few dozen pixels.
SIM = {"realtime": False, "resolution": (768, 512), "seed": 3}
#: Generous: the whole wizard takes a few seconds on the simulated bench.
STEP_TIMEOUT_MS = 120_000


@pytest.fixture
def window(qtbot, tmp_path):
    with main_window(qtbot, tmp_path, SIM) as w:
        yield w


def run_step(qtbot, wizard, page, *, expect=StepState.DONE):
    """Go to ``page``, start it and wait for it to end; returns its result text."""
    wizard.go_to(wizard.pages.index(page))
    page.start_button.click()
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    assert page.state == expect, page.result_label.text()
    return page.result_label.text()


def capture_chart(qtbot, wizard):
    """Run the wizard's connect, dark, white and chart steps."""
    for page in (
        wizard.connect_page,
        wizard.dark_page,
        wizard.white_page,
        wizard.chart_page,
    ):
        run_step(qtbot, wizard, page)


def test_chart_capture_steps_fill_the_session(window, qtbot, tmp_path):
    wizard = window.wizard_panel
    assert wizard.new_measurement(tmp_path / "m")
    run_step(qtbot, wizard, wizard.connect_page)
    assert wizard.current_index == 0 and wizard.next_button.isEnabled()
    for page in (wizard.dark_page, wizard.white_page, wizard.chart_page):
        run_step(qtbot, wizard, page)
        assert window.measurement.phase_complete("chart", page.kind)
    session = window.measurement.session("chart")
    assert not session.missing()
    kinds = [f.kind for f in session.frames]
    assert kinds.count("white") == kinds.count("target") == 22


@pytest.mark.slow
def test_wizard_runs_to_the_end_on_the_simulated_bench(window, qtbot, tmp_path):
    """connect -> dark -> white -> chart -> calibrate -> sample -> estimate -> export.

    The tables the GUI shows must equal the core's: Table 1 as the core's pipeline
    computes it from the chart session, Table 2 as ``reflectance_stats`` of the
    exported reflectances and references.
    """
    from tunespec.app.pipeline.steps import calibrate, process
    from tunespec.core.colorimetry import reflectance_stats
    from tunespec.core.io.export import EXPORT_NAMES
    from tunespec.core.io.spectral import read_spectra_csv
    from tunespec.devices.registry import layout_reflectances

    folder = tmp_path / "m"
    wizard, m = window.wizard_panel, window.measurement
    assert wizard.new_measurement(folder)
    elapsed = {}
    for page in wizard.pages:
        t0 = time.perf_counter()
        run_step(qtbot, wizard, page)
        elapsed[page.key] = time.perf_counter() - t0
        assert wizard.next_button.isEnabled() or page is wizard.export_page
    print(
        "\nchart capture to Table 1: "
        f"{elapsed['target'] + elapsed['calibrate']:.2f} s "
        f"(chart {elapsed['target']:.2f} s, calibrate {elapsed['calibrate']:.2f} s)"
    )

    export = folder / "export"
    for kind in (
        "sensitivities_csv",
        "sensitivities_json",
        "reflectances_csv",
        "reflectances_ti3",
        "responses_csv",
        "table1_csv",
        "table2_csv",
    ):
        assert (export / EXPORT_NAMES[kind]).is_file(), kind
    assert (export / "report.html").is_file() and (export / "report.pdf").is_file()
    assert json.loads((export / "exports.json").read_text())

    # Table 1 as shown == Table 1 of the core's pipeline, run again here on the chart
    # session (the CLI's path: pipeline.steps.process + calibrate)
    cal = m.calibration
    chart = process(m.session("chart"), layout=cal.layout, corners="layout")
    core1 = calibrate(
        chart,
        layout_reflectances(m.chart_layout, grid=CALIBRATION_GRID),
        method=cal.method,
    ).table1
    expected1 = np.column_stack([core1.mean, core1.max, core1.p95])
    for panel in (window.table1_panel, wizard.calibrate_page.table_panel):
        np.testing.assert_allclose(panel.values, expected1, rtol=1e-9)
        assert panel.row_names == ["Red", "Green", "Blue", "RGB"]
    assert cal.table1.n_stimuli == core1.n_stimuli
    assert core1.n_stimuli == (140 - len(cal.excluded_patches)) * 22
    assert window.table1_panel.passed == (core1.mean[3] <= cal.threshold)
    np.testing.assert_allclose(
        read_spectra_csv(export / "sensitivities.csv", allow_negative=True).values,
        cal.sensitivity.values,
    )

    # Table 2 as shown == the core's reflectance statistics of the exported data
    estimated = read_spectra_csv(export / EXPORT_NAMES["reflectances_csv"])
    reference = read_spectra_csv(export / EXPORT_NAMES["reference_csv"])
    core2 = reflectance_stats(estimated, reference)
    expected2 = np.vstack(
        [
            np.column_stack([core2.delta_e00, core2.spectral_rms]),
            [core2.mean_delta_e00, core2.mean_spectral_rms],
            [core2.max_delta_e00, core2.max_spectral_rms],
        ]
    )
    for panel in (window.table2_panel, wizard.estimate_page.table_panel):
        np.testing.assert_allclose(panel.values, expected2, rtol=1e-9)
        assert panel.row_names == [*core2.names, "average", "max"]
    assert len(core2.names) == 8
    # with the sample's scale against the chart's (the white board by Eq. 1)
    note = wizard.estimate_page.table_panel.note_label.text()
    assert re.search(r"white background over the chart's: 1\.0\d\dx", note), note

    # the plots show the results: sensitivities and a patch with its reference
    assert {"R estimated", "G estimated", "B estimated"} <= set(
        window.sensitivity_plot.curves
    )
    assert set(window.reflectance_plot.curves) == {"estimated", "reference"}
