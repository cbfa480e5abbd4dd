"""Issue 27, item 1: no crash, ever. Every wizard step while another process holds
a core, a window closed in the middle of each kind of job, and a job that raises
(one line for the operator, and the step can be taken again)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator

import pytest

from tests.app.helpers import new_main_window
from tests.app.test_wizard import SIM, STEP_TIMEOUT_MS, run_step
from tunespec.app.gui import workers
from tunespec.app.gui.wizard.step_page import StepState


@pytest.fixture
def busy_core() -> Iterator[subprocess.Popen]:
    """A second process spinning on one core for the whole test (issue 27: the
    crashes showed on a machine where another process kept a core busy)."""
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield spinner
    finally:
        spinner.kill()
        spinner.wait()


@pytest.fixture
def window(qtbot, tmp_path):
    w = new_main_window(qtbot, tmp_path, SIM)
    yield w
    w.close()


def _closed_cleanly(qtbot, window) -> None:
    """Close ``window`` as the operator would; its threads must stop."""
    window.close()
    assert not window.controller.thread_running
    qtbot.waitUntil(lambda: workers.Worker.active_count() == 0, timeout=30_000)


@pytest.mark.slow
def test_every_step_with_a_core_busy(window, qtbot, tmp_path, busy_core):
    wizard = window.wizard_panel
    assert wizard.new_measurement(tmp_path / "m")
    for page in wizard.pages:
        run_step(qtbot, wizard, page)
    assert window.measurement.export is not None
    # and again from a retaken capture: the later steps follow
    run_step(qtbot, wizard, wizard.dark_page)
    assert wizard.calibrate_page.state == StepState.PENDING
    _closed_cleanly(qtbot, window)


#: Steps to interrupt: a device job (metering, then frames), the chart frames and
#: a numerics job in its own process.
MID_JOB = ("dark", "target", "calibrate")


@pytest.mark.slow
@pytest.mark.parametrize("key", MID_JOB)
def test_closing_the_window_mid_job(qtbot, tmp_path, busy_core, key):
    window = new_main_window(qtbot, tmp_path, SIM)
    wizard = window.wizard_panel
    assert wizard.new_measurement(tmp_path / "m")
    pages = {p.key: p for p in wizard.pages}
    for page in wizard.pages:
        if page.key == key:
            break
        run_step(qtbot, wizard, page)
    page = pages[key]
    wizard.go_to(wizard.pages.index(page))
    page.start_button.click()
    assert page.running
    # well inside the job: it has reported progress (or what it is doing)
    qtbot.waitUntil(
        lambda: page.clock.fraction > 0 or bool(page.stage) or not page.running,
        timeout=STEP_TIMEOUT_MS,
    )
    assert page.running, page.result_label.text()
    _closed_cleanly(qtbot, window)
    # the light was switched off and the devices closed by the device thread
    assert not window.controller.is_open or not window.controller.thread_running


def test_a_job_that_raises_is_one_line_and_the_step_runs_again(
    window, qtbot, tmp_path, monkeypatch
):
    import tunespec.app.pipeline.jobs as steps  # the wizard runs the jobs

    real = steps.capture_target

    def broken(*args, **kwargs):
        raise RuntimeError("the camera's buffer is full\n(and a second line)")

    wizard = window.wizard_panel
    assert wizard.new_measurement(tmp_path / "m")
    run_step(qtbot, wizard, wizard.connect_page)
    monkeypatch.setattr(steps, "capture_target", broken)
    text = run_step(qtbot, wizard, wizard.dark_page, expect=StepState.FAILED)
    assert text.startswith("Failed: RuntimeError: the camera's buffer is full")
    assert "\n" not in text
    # the GUI stays usable: the same step runs once the fault is gone
    monkeypatch.setattr(steps, "capture_target", real)
    assert wizard.dark_page.start_button.isEnabled()
    run_step(qtbot, wizard, wizard.dark_page)
    assert window.measurement.phase_complete("chart", "dark")
