"""Issue 13 item 3 for the plain CLI: ``tunespec capture`` keeps the session's
capture warnings in ``capture_warnings.json`` as the pipeline does, so a session
captured by the CLI shows them in the GUI (the dark frame step's badge) and in the
calibrate step's warnings, which the report lists."""

from __future__ import annotations

import json

from tests.app.test_warnings_progress import WEAK_LED, _weak_warning
from tests.app.test_warnings_progress import weak_leds as weak_leds  # the fixture
from tests.app.test_wizard import window as window  # the fixture
from tunespec.app.cli import main
from tunespec.app.gui.wizard.step_page import StepState
from tunespec.app.pipeline.folder import (
    CAPTURE_WARNINGS_FILE,
    read_capture_warnings,
    step_warnings,
)
from tunespec.core.datasets import resource_path

SG_LAYOUT = resource_path("layouts", "colorchecker_sg.json")


def _capture(out, weak_leds, *extra):
    return main(
        [
            "capture",
            "--light",
            f"sim?leds={weak_leds}",
            "--camera",
            "sim",
            "--resolution",
            "384x256",
            "--channels",
            # the target is found under LED450 (processing looks at the middle
            # channel; under the weak LED it would be flagged as not found)
            f"{WEAK_LED},LED450",
            "--out",
            str(out),
            *extra,
        ]
    )


def test_cli_capture_keeps_its_warnings_beside_the_session(
    window, qtbot, tmp_path, weak_leds, capsys
):
    wizard = window.wizard_panel
    assert wizard.new_measurement(tmp_path / "m")
    chart = tmp_path / "m" / "chart"
    # a stale store of an earlier session in the folder is not carried over
    chart.mkdir()
    (chart / CAPTURE_WARNINGS_FILE).write_text('{"warnings": ["old session"]}')
    assert _capture(chart, weak_leds, "--layout", str(SG_LAYOUT)) == 0
    printed = capsys.readouterr()
    text = _weak_warning(read_capture_warnings(chart))
    assert text in printed.out + printed.err
    stored = json.loads((chart / CAPTURE_WARNINGS_FILE).read_text())
    assert stored == {"warnings": [text]}
    # the calibrate step (and with it calibration.json and the report) lists it
    assert f"capture: {text}" in step_warnings(chart, None)
    # resuming the complete session adds nothing twice
    assert _capture(chart, weak_leds, "--resume") == 0
    assert read_capture_warnings(chart) == (text,)
    # the GUI, reopening the measurement, shows it on the dark frame step
    assert wizard.open_measurement(tmp_path / "m")
    assert wizard.dark_page.state == StepState.DONE
    assert wizard.dark_page.warnings == [text]
    assert not wizard.dark_page.warning_label.isHidden()  # the badge
