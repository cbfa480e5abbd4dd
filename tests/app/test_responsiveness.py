"""The window never freezes: the event loop keeps turning during a capture.

A 10 ms QTimer ticks while the simulated bench captures a whole chart session
through the GUI (device thread, live view, SPD plot, progress). The longest gap
between ticks is the UI's longest stall; it is printed and recorded
(``record_property``) so a run shows the number.
"""

from __future__ import annotations

import time

import numpy as np
from PySide6.QtCore import QSettings, QTimer

from tests.app.helpers import caught
from tests.app.test_wizard import SIM, STEP_TIMEOUT_MS
from tunespec.app.gui.main_window import MainWindow
from tunespec.app.gui.settings import AppSettings

#: A frozen window would stall for the whole capture (seconds): the capture on the GUI
#: thread is what this guards against. Measured on a shared 2-core machine: p99 gap
#: 25-90 ms, longest 50-470 ms (the longest when other jobs load the CPUs and the GIL
#: holder gets descheduled), so the bound leaves room for a loaded CI machine.
MAX_STALL_S = 1.0


class TickRecorder:
    """Records the longest gap between the timeouts of a 10 ms timer."""

    def __init__(self, period_ms: int = 10) -> None:
        self.timer = QTimer()
        self.timer.setInterval(period_ms)
        self.timer.timeout.connect(self._on_timer_timeout)
        self.ticks = 0
        self.longest_gap_s = 0.0
        self.gaps_s: list[float] = []
        self._last = 0.0

    def start(self) -> None:
        self._last = time.perf_counter()
        self.timer.start()

    def stop(self) -> None:
        self.timer.stop()

    def _on_timer_timeout(self) -> None:
        now = time.perf_counter()
        self.longest_gap_s = max(self.longest_gap_s, now - self._last)
        self.gaps_s.append(now - self._last)
        self._last = now
        self.ticks += 1


def test_event_loop_keeps_turning_during_a_capture(qtbot, tmp_path, record_property):
    settings = AppSettings(
        QSettings(str(tmp_path / "s.ini"), QSettings.Format.IniFormat)
    )
    window = MainWindow(settings, sim_options=SIM)
    qtbot.addWidget(window)
    window.show()
    wizard = window.wizard_panel
    # as an operator would: the window has finished starting up (pipeline imported)
    qtbot.waitUntil(lambda: window.preloaded, timeout=STEP_TIMEOUT_MS)
    assert wizard.new_measurement(tmp_path / "m")
    with caught(qtbot, window.controller.devices_opened, timeout=STEP_TIMEOUT_MS):
        wizard.connect_page.start_button.click()
    recorder = TickRecorder()
    page = wizard.sample_page  # a whole session: metering, dark, white, target
    wizard.go_to(wizard.pages.index(page))
    started = time.perf_counter()
    recorder.start()
    page.start_button.click()
    qtbot.waitUntil(lambda: not page.running, timeout=STEP_TIMEOUT_MS)
    recorder.stop()
    elapsed = time.perf_counter() - started
    assert page.result_label.text() and page.state == "done", page.result_label.text()
    record_property("capture_s", round(elapsed, 3))
    record_property("longest_stall_ms", round(1000 * recorder.longest_gap_s, 1))
    p99_ms = 1000 * float(np.percentile(recorder.gaps_s, 99))
    print(
        f"\ncapture of a whole session took {elapsed:.2f} s; "
        f"{recorder.ticks} ticks; event-loop gap p99 {p99_ms:.1f} ms, longest "
        f"{1000 * recorder.longest_gap_s:.1f} ms"
    )
    assert recorder.ticks > elapsed / 0.05  # turned at least every 50 ms on average
    assert recorder.longest_gap_s < MAX_STALL_S
    window.close()
