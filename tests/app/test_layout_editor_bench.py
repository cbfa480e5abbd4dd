"""The layout editor on the simulated bench's own frames (issue 13, item 1).

"Find corners" must find the chart in the frames the wizard captured, with the
detector and the inputs processing uses, and after Calibrate the editor shows the
corners Calibrate used.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.app.helpers import main_window
from tests.app.test_wizard import SIM, capture_chart, run_step
from tunespec.app.gui.main_window import TAB_LAYOUT
from tunespec.core.processing import find_session_corners

#: Automatic corners against the simulation's truth, mosaic pixels (as the demo's).
MAX_CORNER_ERROR_PX = 1.0


@pytest.fixture
def window(qtbot, tmp_path):
    with main_window(qtbot, tmp_path, SIM) as w:
        yield w


@pytest.mark.slow
def test_find_corners_works_on_the_bench_frames(window, qtbot, tmp_path):
    wizard, editor = window.wizard_panel, window.layout_editor
    assert wizard.new_measurement(tmp_path / "m")
    capture_chart(qtbot, wizard)
    truth = np.asarray(window._truth["corners_px"])
    window.tabs.setCurrentIndex(TAB_LAYOUT)
    assert editor.session_root == tmp_path / "m" / "chart"

    editor.reset_button.click()
    assert np.max(np.abs(editor.target_layout.corners_px - truth)) > 10
    editor.find_button.click()
    qtbot.waitUntil(lambda: editor.find_button.isEnabled(), timeout=30_000)
    assert "processing" in editor.status_label.text(), editor.status_label.text()
    found = np.asarray(editor.target_layout.corners_px)
    assert np.max(np.abs(found - truth)) < MAX_CORNER_ERROR_PX
    np.testing.assert_allclose(editor.handle_positions(), found)
    # one detector, the same inputs: exactly what processing finds
    session = window.measurement.session("chart")
    np.testing.assert_array_equal(
        found, find_session_corners(session, editor.target_layout)[0].corners_px
    )
    # the editor's corners reached the measurement (Calibrate may use them)
    np.testing.assert_array_equal(window.measurement.chart_layout.corners_px, found)

    # move a corner away; Calibrate (corners found automatically) puts it back
    editor.set_corners(found + np.array([25.0, -15.0]))
    run_step(qtbot, wizard, wizard.calibrate_page)
    used = np.asarray(window.measurement.calibration.layout.corners_px)
    np.testing.assert_array_equal(used, found)
    np.testing.assert_array_equal(editor.target_layout.corners_px, used)
    np.testing.assert_allclose(editor.handle_positions(), used)
    assert "Calibrate used" in editor.status_label.text()
