"""Time the GUI's measurement steps and its longest event-loop stall per step.

Drives the workstation (offscreen) on the simulated bench through connect, dark,
white, chart and calibrate (``--all``: to the end) while a 10 ms QTimer ticks, and
prints per step its wall time and the longest gap between ticks (and, first, the
same for the background imports the window starts with, which it waits for)::

    python tools/gui_timing.py                      # virtual time, 1536x1024
    python tools/gui_timing.py --all --repeat 3      # every step, 3 runs
    python tools/gui_timing.py --realtime --exposure 0.5
    python tools/gui_timing.py --why                 # what the GUI thread ran in stalls

With ``--repeat N`` every step's stall is given as the median and the largest of N
runs, each in a fresh process as the GUI starts (on a machine shared with other
work a single run is noisy).

``--why`` samples the GUI thread's stack (every 2 ms, from a thread of its own)
while the event loop has not ticked for 20 ms, and prints per step the places of
this project (and pyqtgraph) seen most in those stalls: where to look.

``--realtime`` waits the exposures as the real camera would (``--exposure`` fixes
them; the default metering picks up to 30 s per LED).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


def _timed_run(app: Any, args: argparse.Namespace, tmp: Path) -> tuple[list, Any]:
    """One run through the wizard: (rows of (step, state, wall s, stall ms), window)."""
    from PySide6.QtCore import QSettings, QTimer

    from tunespec.app.gui.main_window import MainWindow
    from tunespec.app.gui.settings import AppSettings
    from tunespec.app.gui.wizard.measurement import CaptureOptions
    from tunespec.devices.registry import parse_resolution

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
    seen: dict[str, dict[str, int]] = {}
    sampling = {"step": "", "on": False}
    if args.why:
        _start_sampler(last, seen, sampling)

    def measure(title: str, start: Any, running: Any) -> tuple[str, float, float]:
        last[0], longest[0] = time.perf_counter(), 0.0
        timer.start()
        sampling.update(step=title, on=True)
        t0 = time.perf_counter()
        start()
        while running():
            app.processEvents()
            time.sleep(0.002)
        sampling["on"] = False
        timer.stop()
        return title, time.perf_counter() - t0, 1000 * longest[0]

    # the window imports the pipeline in the background while the operator looks at
    # it: measured on its own, and over before the first step, as in real use
    title, wall, stall = measure(
        "(start-up imports)", lambda: None, lambda: not window.preloaded
    )
    rows = [(title, "done", wall, stall)]
    pages = (
        wizard.pages
        if args.all
        else wizard.pages[: wizard.pages.index(wizard.calibrate_page) + 1]
    )
    for page in pages:
        wizard.go_to(wizard.pages.index(page))
        for _ in range(5):
            app.processEvents()
        title, wall, stall = measure(
            page.title, page.start, lambda p=page: p.running or p.state == "pending"
        )
        rows.append((title, page.state, wall, stall))
        if page.state != "done":
            print(page.result_label.text())
            break
    for step, places in seen.items():
        top = sorted(places.items(), key=lambda kv: -kv[1])[:6]
        print(f"stalls in {step}: " + "; ".join(f"{n}x {w}" for w, n in top))
    return rows, window


def _start_sampler(last: list[float], seen: dict, sampling: dict) -> None:
    """A daemon thread: while the event loop has not ticked for 20 ms, note the
    GUI thread's innermost frames of this project and pyqtgraph (``--why``)."""
    import threading
    import traceback

    main = threading.main_thread().ident

    def sample() -> None:
        while True:
            time.sleep(0.002)
            if not sampling["on"] or time.perf_counter() - last[0] < 0.02:
                continue
            frame = sys._current_frames().get(main)
            if frame is None:
                continue
            stack = traceback.extract_stack(frame)
            ours = [
                f"{Path(f.filename).name}:{f.lineno} {f.name}"
                for f in stack
                if "tunespec" in f.filename
                or "/app/" in f.filename
                or "/core/" in f.filename
                or "pyqtgraph" in f.filename
            ]
            inner = stack[-1]
            where = " < ".join(reversed(ours[-3:]))
            if (
                not ours
                or ours[-1]
                != f"{Path(inner.filename).name}:{inner.lineno} {inner.name}"
            ):
                where = f"{Path(inner.filename).name}:{inner.lineno} {inner.name}" + (
                    f" < {where}" if where else ""
                )
            step = seen.setdefault(sampling["step"], {})
            step[where] = step.get(where, 0) + 1

    threading.Thread(target=sample, name="stall-sampler", daemon=True).start()


def _run_in_child(argv: list[str]) -> list[list[Any]]:
    """One run in a fresh interpreter, as the GUI starts: its rows (JSON)."""
    child = subprocess.run(
        [sys.executable, __file__, *argv, "--rows-json"],
        capture_output=True,
        text=True,
        check=True,
    )
    line = next(x for x in child.stdout.splitlines() if x.startswith("ROWS "))
    rows: list[list[Any]] = json.loads(line[5:])
    return rows


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
    parser.add_argument(
        "--repeat", type=int, default=1, help="runs, each in a fresh process (1)"
    )
    parser.add_argument(
        "--why", action="store_true", help="sample the GUI thread's stack in stalls"
    )
    parser.add_argument("--rows-json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.repeat > 1:
        one = list(argv if argv is not None else sys.argv[1:])
        k = one.index("--repeat")
        del one[k : k + 2]
        runs = []
        for n in range(args.repeat):
            runs.append(_run_in_child(one))
            rows = runs[-1]
            print(f"run {n + 1}: " + ", ".join(f"{r[0]} {r[3]:.0f} ms" for r in rows))
        _print_table(runs)
        return 0

    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication(sys.argv[:1])
    tmp = Path(tempfile.mkdtemp(prefix="tunespec-timing-"))
    rows, window = _timed_run(app, args, tmp)
    if args.rows_json:
        print("ROWS " + json.dumps(rows))
        window.close()
        return 0
    _print_table([rows])
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


def _print_table(runs: list[list[Any]]) -> None:
    """Per step: median wall time, median and largest longest stall of the runs."""
    print(
        f"\n{'step':<24}{'state':<8}{'wall s':>9}{'longest stall ms':>18}"
        f"{'max of runs':>13}"
    )
    worst = 0.0
    for i, (title, state, _, _) in enumerate(runs[0]):
        walls = [r[i][2] for r in runs if i < len(r)]
        stalls = [r[i][3] for r in runs if i < len(r)]
        if i > 0:
            worst = max(worst, statistics.median(stalls))
        print(
            f"{title:<24}{state:<8}{statistics.median(walls):9.2f}"
            f"{statistics.median(stalls):18.1f}{max(stalls):13.1f}"
        )
    print(f"longest stall of any step (median of runs): {worst:.1f} ms (goal <= 50 ms)")


if __name__ == "__main__":
    sys.exit(main())
