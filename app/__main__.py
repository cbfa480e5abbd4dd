"""Start the TuneSpec workstation: ``python -m tunespec.app`` or ``tunespec-gui``."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
from collections.abc import Sequence

__all__ = ["main"]

#: What ``tunespec-gui`` says when the GUI's packages are not installed.
INSTALL_HINT = (
    "tunespec-gui: the GUI needs {missing}, which is not installed; "
    "install the GUI with: pip install 'tunespec[gui]'"
)
#: The distributions the ``gui`` extra installs, by the module they provide.
GUI_MODULES = {"PySide6": "PySide6", "shiboken6": "PySide6", "pyqtgraph": "pyqtgraph"}


def _gui_import_error() -> str | None:
    """One line saying why the GUI cannot start, or None if its packages load."""
    import importlib

    try:
        # Qt first: pyqtgraph without a Qt binding raises its own ImportError
        for name in ("PySide6.QtWidgets", "pyqtgraph"):
            importlib.import_module(name)
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if top in GUI_MODULES:
            return INSTALL_HINT.format(missing=GUI_MODULES[top])
        raise
    except ImportError as exc:
        # installed but not loadable, e.g. a system library Qt needs is missing
        return f"tunespec-gui: Qt cannot be loaded: {exc}"
    return None


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="tunespec-gui", description="The TuneSpec operator's workstation."
    )
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument(
        "--fast-sim",
        action="store_true",
        help="run the simulated bench in virtual time, no real exposure waits "
        "(the default unless 'Real-time exposures' was switched on)",
    )
    timing.add_argument(
        "--realtime-sim",
        action="store_true",
        help="the simulated camera waits out every exposure, as a real one does",
    )
    parser.add_argument(
        "--sim-resolution",
        metavar="WxH",
        help="resolution of the simulated camera, e.g. 768x512",
    )
    parser.add_argument(
        "--measurement", metavar="FOLDER", help="open (resume) this measurement"
    )
    parser.add_argument(
        "-v", "--verbose", action="store_true", help="log debug messages"
    )
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the GUI until its window closes; returns the exit code."""
    args = _parse(sys.argv[1:] if argv is None else argv)
    problem = _gui_import_error()
    if problem is not None:
        sys.stderr.write(problem + "\n")
        return 1
    from PySide6.QtCore import QTimer
    from PySide6.QtWidgets import QApplication

    from tunespec.app.gui.main_window import MainWindow
    from tunespec.app.gui.settings import APPLICATION, ORGANIZATION

    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setOrganizationName(ORGANIZATION)
    app.setApplicationName(APPLICATION)
    sim: dict[str, object] = {}
    if args.fast_sim or args.realtime_sim:
        sim["realtime"] = bool(args.realtime_sim)
    if args.sim_resolution:
        from tunespec.devices.registry import parse_resolution

        sim["resolution"] = parse_resolution(args.sim_resolution)
    window = MainWindow(sim_options=sim)
    if args.measurement:
        window.wizard_panel.open_measurement(args.measurement)
    window.show()
    # Ctrl-C / SIGTERM close the window like the operator would (LEDs off, devices
    # closed); the timer lets Python run its signal handlers inside Qt's loop
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: window.close())
    tick = QTimer()
    tick.timeout.connect(lambda: None)
    tick.start(200)
    return int(app.exec())


if __name__ == "__main__":
    sys.exit(main())
