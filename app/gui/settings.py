"""Persistent GUI settings: one typed wrapper around :class:`QSettings`.

Every key the GUI stores is declared here with its default, so a missing or
malformed value falls back instead of breaking start-up. Tests pass a
:class:`QSettings` on a temporary INI file (or redirect the default location).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from PySide6.QtCore import QByteArray, QSettings

import tunespec.app.gui.qt_compat  # noqa: F401 (before any signal)

__all__ = ["DEFAULTS", "MAX_RECENT", "AppSettings"]

ORGANIZATION = "TuneSpec"
APPLICATION = "TuneSpec"

#: Recent measurements remembered.
MAX_RECENT = 8

#: key -> default; the default's type is the stored type.
DEFAULTS: dict[str, Any] = {
    "devices/light_spec": "sim",
    "devices/camera_spec": "sim",
    # virtual time: the simulated camera does not wait out its exposures (the whole
    # wizard in about 2 minutes, not 20); the device panel's switch turns it on
    "sim/realtime": False,
    "sim/width_px": 1536,
    "sim/height_px": 1024,
    "sim/seed": 0,
    "session/last_dir": "",  # the last measurement opened or started
    "session/root_dir": "",  # where new measurements go (asked once)
    "session/recent": "",  # recent measurements, one folder a line, newest first
    "layout/chart_path": "",
    "layout/sample_path": "",
    "capture/exposure": "auto",
    "capture/iso": 100,
    "capture/n_darks": 1,
    "capture/repeats": 1,
    "calibration/method": "",  # "": the library's default method
    "calibration/threshold_rgb_mean": 0.005,
    "estimate/reference_path": "",
    "image/scheduler": "",  # a dask.distributed address for the images; "": local
    "ui/tab": 0,
    "ui/geometry": QByteArray(),
    "ui/state": QByteArray(),
}


@dataclass
class AppSettings:
    """Typed access to the stored settings.

    Parameters
    ----------
    qsettings
        Where they live; ``None`` is the user's INI file of organisation and
        application ``TuneSpec`` (e.g. ``~/.config/TuneSpec/TuneSpec.ini``).
    """

    qsettings: QSettings | None = None

    def __post_init__(self) -> None:
        if self.qsettings is None:
            # INI everywhere (readable, and QSettings.setPath can redirect it in tests)
            self.qsettings = QSettings(
                QSettings.Format.IniFormat,
                QSettings.Scope.UserScope,
                ORGANIZATION,
                APPLICATION,
            )

    def get(self, key: str) -> Any:
        """The stored value of ``key`` converted to its default's type."""
        default = DEFAULTS[key]
        value = self.qsettings.value(key, default)
        if value is None:
            return default
        try:
            if isinstance(default, bool):
                return (
                    value
                    if isinstance(value, bool)
                    else str(value).lower() in ("1", "true", "yes")
                )
            if isinstance(default, int):
                return int(value)
            if isinstance(default, float):
                return float(value)
            if isinstance(default, str):
                return str(value)
        except (TypeError, ValueError):
            return default
        return value

    def set(self, key: str, value: Any) -> None:
        """Store ``value`` under ``key`` (which must be declared in :data:`DEFAULTS`)."""
        if key not in DEFAULTS:
            raise KeyError(f"undeclared setting {key!r}")
        self.qsettings.setValue(key, value)

    def sync(self) -> None:
        """Write to disk now."""
        self.qsettings.sync()

    def remember_measurement(self, folder: str | Path) -> None:
        """``folder`` is the measurement in use: the last one, first of the recent."""
        path = str(Path(folder).resolve())
        rest = [p for p in self.get("session/recent").splitlines() if p and p != path]
        self.set("session/recent", "\n".join([path, *rest][:MAX_RECENT]))
        self.set("session/last_dir", path)

    def recent_measurements(self) -> list[Path]:
        """The recent measurements that still exist, newest first."""
        from tunespec.app.pipeline.folder import MEASUREMENT_FILE

        paths = [Path(p) for p in self.get("session/recent").splitlines() if p]
        return [p for p in paths if (p / MEASUREMENT_FILE).is_file()]

    def last_measurement(self) -> Path | None:
        """The last measurement used, if it still exists."""
        from tunespec.app.pipeline.folder import MEASUREMENT_FILE

        last = self.get("session/last_dir")
        return (
            Path(last) if last and (Path(last) / MEASUREMENT_FILE).is_file() else None
        )

    def measurements_dir(self) -> str:
        """Where the folder dialogs start: the folder holding the last measurement,
        else where new measurements go, else the home folder."""
        last = self.get("session/last_dir")
        if last and Path(last).parent.is_dir():
            return str(Path(last).parent)
        root = self.get("session/root_dir")
        return root if root and Path(root).is_dir() else str(Path.home())

    def sim_options(self) -> dict[str, Any]:
        """Keyword options for opening the simulated bench."""
        return {
            "realtime": self.get("sim/realtime"),
            "resolution": (self.get("sim/width_px"), self.get("sim/height_px")),
            "seed": self.get("sim/seed"),
        }
