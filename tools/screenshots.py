"""Render screenshots of the workstation's main views for the README.

Runs the measurement wizard on the simulated bench in virtual time (offscreen, no
display needed), then grabs each view into ``docs/screenshots/*.png``::

    python tools/screenshots.py [--out docs/screenshots] [--resolution 1536x1024]

Nothing here is imported by the application.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

ROOT = Path(__file__).resolve().parents[1]
#: Longest a wizard step may take here (the simulated bench runs in virtual time).
STEP_LIMIT_S = 600.0


def _wait(app: object, done: object, limit_s: float = STEP_LIMIT_S) -> None:
    t0 = time.monotonic()
    while not done():
        app.processEvents()
        time.sleep(0.005)
        if time.monotonic() - t0 > limit_s:
            raise TimeoutError("step did not finish in time")


def run_wizard(window: object, app: object, folder: Path) -> list[str]:
    """Drive the wizard to the end (as far as it goes); returns the step outcomes."""
    wizard = window.wizard_panel
    wizard.new_measurement(folder)
    outcomes = []
    for page in wizard.pages:
        wizard.go_to(wizard.pages.index(page))
        page.start()
        _wait(app, lambda p=page: not p.running)
        outcomes.append(f"{page.title}: {page.state} - {page.result_label.text()}")
        if page.state != "done":
            break
    return outcomes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "screenshots")
    parser.add_argument(
        "--resolution", default="1536x1024", help="simulated camera WxH"
    )
    parser.add_argument("--size", default="1500x950", help="window size WxH")
    args = parser.parse_args(argv)

    from PySide6.QtCore import QSettings
    from PySide6.QtWidgets import QApplication

    from tunespec.app.main_window import (
        TAB_LAYOUT,
        TAB_MEASUREMENT,
        TAB_SPECTRA,
        TAB_TABLES,
        MainWindow,
    )
    from tunespec.app.settings import AppSettings
    from tunespec.devices.registry import parse_resolution

    app = QApplication.instance() or QApplication(sys.argv[:1])
    tmp = Path(tempfile.mkdtemp(prefix="tunespec-shots-"))
    settings = AppSettings(
        QSettings(str(tmp / "settings.ini"), QSettings.Format.IniFormat)
    )
    sim = {
        "realtime": False,
        "resolution": parse_resolution(args.resolution),
        "seed": 0,
    }
    window = MainWindow(settings, sim_options=sim)
    w, h = (int(v) for v in args.size.split("x"))
    window.resize(w, h)
    window.show()
    app.processEvents()
    for line in run_wizard(window, app, tmp / "measurement"):
        print(line)
    args.out.mkdir(parents=True, exist_ok=True)
    wizard = window.wizard_panel
    shots = {
        "wizard_calibrate": (TAB_MEASUREMENT, wizard.calibrate_page),
        "wizard_estimate": (TAB_MEASUREMENT, wizard.estimate_page),
        "layout_editor": (TAB_LAYOUT, None),
        "spectra": (TAB_SPECTRA, None),
        "tables": (TAB_TABLES, None),
    }
    for name, (tab, page) in shots.items():
        window.tabs.setCurrentIndex(tab)
        if page is not None:
            wizard.go_to(wizard.pages.index(page))
        if name == "layout_editor":
            window.measurement.edit_target("chart")
            if window.measurement.calibration is not None:
                window.layout_editor.set_target_layout(
                    window.measurement.calibration.layout
                )
        for _ in range(20):
            app.processEvents()
        path = args.out / f"{name}.png"
        window.grab().save(str(path))
        print(f"wrote {path}")
    device = args.out / "device_panel.png"
    window.device_panel.grab().save(str(device))
    print(f"wrote {device}")
    window.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
