"""Render screenshots of the workstation's main views and of the report's pages.

Runs the measurement wizard on the simulated bench in virtual time (offscreen, no
display needed), then grabs each view into ``docs/screenshots/*.png``: every
wizard step (``wizard_<n>_<step>.png``, and the dark frame while it meters,
``wizard_dark_running.png``), the layout editor, the plots, the tables, the
spectral-image tab (``image_view.png``), the device panel, and every page of the report the export step wrote (``report_page_<n>.png``,
rendered with poppler's ``pdftoppm`` when it is installed)::

    python tools/screenshots.py [--out docs/screenshots] [--resolution 1536x1024]

Nothing here is imported by the application.
"""

from __future__ import annotations

import argparse
import os
import shutil
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


def run_wizard(
    window: object, app: object, folder: Path, running_shot: Path | None = None
) -> list[str]:
    """Drive the wizard to the end (as far as it goes); returns the step outcomes.

    ``running_shot``: where to save the window while the dark frame step meters.
    """
    wizard = window.wizard_panel
    wizard.new_measurement(folder)
    outcomes = []
    shot = [running_shot]
    armed = [False]

    def on_stage(text: str) -> None:
        armed[0] = armed[0] or text.startswith("metering LED495")

    def on_value(_value: int) -> None:
        # the bar is redrawn at most every 100 ms: the first redraw after the
        # metering of LED495 started, while it still meters
        page = wizard.dark_page
        if shot[0] is not None and armed[0] and page.stage.startswith("metering"):
            for _ in range(3):
                app.processEvents()
            window.grab().save(str(shot[0]))
            shot[0] = None

    wizard.dark_page.stage_changed.connect(on_stage)
    wizard.dark_page.progress_bar.valueChanged.connect(on_value)
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

    from tunespec.app.gui.main_window import (
        TAB_IMAGE,
        TAB_LAYOUT,
        TAB_MEASUREMENT,
        TAB_SPECTRA,
        TAB_TABLES,
        MainWindow,
    )
    from tunespec.app.gui.settings import AppSettings
    from tunespec.devices.registry import parse_resolution

    app = QApplication.instance() or QApplication(sys.argv[:1])
    tmp = Path(tempfile.mkdtemp(prefix="tunespec-shots-"))
    try:
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
        args.out.mkdir(parents=True, exist_ok=True)
        running = args.out / "wizard_dark_running.png"
        for line in run_wizard(window, app, tmp / "measurement", running):
            print(line)
        print(f"wrote {running}")
        wizard = window.wizard_panel
        window.tabs.setCurrentIndex(TAB_MEASUREMENT)
        for i, page in enumerate(wizard.pages, 1):
            wizard.go_to(i - 1)
            for _ in range(10):
                app.processEvents()
            path = args.out / f"wizard_{i}_{page.key or 'connect'}.png"
            window.grab().save(str(path))
            print(f"wrote {path}")
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
        _image_shot(window, app, args.out / "image_view.png", TAB_IMAGE)
        device = args.out / "device_panel.png"
        window.device_panel.grab().save(str(device))
        print(f"wrote {device}")
        export = window.measurement.export
        window.close()
        if export is not None and "report_pdf" in export.paths:
            _report_pages(export.paths["report_pdf"], args.out)
    finally:
        # the measurement the wizard wrote (about 0.5 GB) is not kept
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


def _image_shot(window: object, app: object, path: Path, tab: int) -> None:
    """The spectral-image tab on the chart's per-pixel images (estimated here by
    the window's action), a pixel's spectrum shown."""
    view = window.image_view
    if window.estimate_image() is None:
        print(f"no spectral image: {window.statusBar().currentMessage()}")
        return
    _wait(app, lambda: view.worker is None)
    if view.image is None:
        print(f"no spectral image: {view.status.text()}")
        return
    rows, cols = view.image.shape
    view.show_pixel(rows // 2, cols // 2)
    window.tabs.setCurrentIndex(tab)
    for _ in range(20):
        app.processEvents()
    window.grab().save(str(path))
    print(f"wrote {path}")


def _report_pages(pdf: Path, out: Path) -> None:
    """Every page of the report as ``report_page_<n>.png`` (poppler's pdftoppm)."""
    import subprocess

    if shutil.which("pdftoppm") is None:
        print("pdftoppm not found: the report's pages are not rendered")
        return
    for old in out.glob("report_page_*.png"):
        old.unlink()
    subprocess.run(
        ["pdftoppm", "-r", "72", "-png", str(pdf), str(out / "report_page")],
        check=True,
    )
    for path in sorted(out.glob("report_page*.png")):
        # pdftoppm numbers with as many digits as the page count needs
        number = int(path.stem.rsplit("-", 1)[1])
        final = out / f"report_page_{number}.png"
        path.rename(final)
        print(f"wrote {final}")


if __name__ == "__main__":
    sys.exit(main())
