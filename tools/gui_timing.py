"""Time the GUI's measurement steps and its longest event-loop stall per step.

Drives the workstation (offscreen) on the simulated bench through connect, dark,
white, chart and calibrate (``--all``: to the end) while a 10 ms QTimer ticks, and
prints per step its wall time and the longest gap between ticks (and, first, the
same for the background imports the window starts with, which it waits for)::

    python tools/gui_timing.py                      # virtual time, 1536x1024
    python tools/gui_timing.py --realtime --exposure 0.5

``--realtime`` waits the exposures as the real camera would (``--exposure`` fixes
them; the default metering picks up to 30 s per LED).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", default="1536x1024")
    parser.add_argument("--realtime", action="store_true")
    parser.add_argument(
        "--exposure", type=float, help="fixed exposure in s (default: auto)"
    )
    parser.add_argument(
        "--all", action="store_true", help="run every step, not only to Table 1"
    )
    args = parser.parse_args(argv)

    from PySide6.QtCore import QSettings, QTimer
    from PySide6.QtWidgets import QApplication

    from tunespec.app.main_window import MainWindow
    from tunespec.app.settings import AppSettings
    from tunespec.app.wizard.measurement import CaptureOptions
    from tunespec.devices.registry import parse_resolution

    app = QApplication.instance() or QApplication(sys.argv[:1])
    tmp = Path(tempfile.mkdtemp(prefix="tunespec-timing-"))
    settings = AppSettings(QSettings(str(tmp / "s.ini"), QSettings.Format.IniFormat))
    sim = {"realtime": args.realtime, "resolution": parse_resolution(args.resolution)}
    window = MainWindow(settings, sim_options=sim)
    window.show()
    wizard = window.wizard_panel
    wizard.new_measurement(tmp / "m")
    if args.exposure:
        window.measurement.capture_options = CaptureOptions(args.exposure)
        wizard.dark_page.exposure_combo.setCurrentIndex(1)
        wizard.dark_page.exposure_spin.setValue(args.exposure)

    last = [time.perf_counter()]
    longest = [0.0]

    def on_tick() -> None:
        now = time.perf_counter()
        longest[0] = max(longest[0], now - last[0])
        last[0] = now

    timer = QTimer()
    timer.setInterval(10)
    timer.timeout.connect(on_tick)
    # the window imports the pipeline in the background while the operator looks at
    # it: measured on its own, and over before the first step, as in real use
    rows = []
    timer.start()
    t0 = time.perf_counter()
    while not window.preloaded:
        app.processEvents()
        time.sleep(0.002)
    timer.stop()
    rows.append(
        ("(start-up imports)", "done", time.perf_counter() - t0, 1000 * longest[0])
    )
    pages = (
        wizard.pages
        if args.all
        else wizard.pages[: wizard.pages.index(wizard.calibrate_page) + 1]
    )
    for page in pages:
        wizard.go_to(wizard.pages.index(page))
        for _ in range(5):
            app.processEvents()
        last[0], longest[0] = time.perf_counter(), 0.0
        timer.start()
        t0 = time.perf_counter()
        page.start()
        while page.running or page.state == "pending":
            app.processEvents()
            time.sleep(0.002)
        elapsed = time.perf_counter() - t0
        timer.stop()
        rows.append((page.title, page.state, elapsed, 1000 * longest[0]))
        if page.state != "done":
            print(page.result_label.text())
            break
    print(f"{'step':<24}{'state':<8}{'wall s':>9}{'longest stall ms':>18}")
    for title, state, elapsed, stall in rows:
        print(f"{title:<24}{state:<8}{elapsed:9.2f}{stall:18.1f}")
    worst = max(stall for title, _, _, stall in rows[1:])
    print(f"longest stall of any step: {worst:.1f} ms (goal <= 50 ms)")
    times = {t: e for t, _, e, _ in rows}
    if "Calibrate" in times:
        chart = times["Chart under all LEDs"]
        print(f"start of chart capture to Table 1: {chart + times['Calibrate']:.2f} s")
    session = window.measurement.session("chart")
    if session is not None:
        exposure = sum(f.exposure_s for f in session.frames if f.kind == "target")
        print(f"sum of the chart frames' exposures: {exposure:.1f} s")
    window.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
