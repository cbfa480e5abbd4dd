"""One measurement folder layout, the same for ``tunespec run``/``demo`` and the GUI.

::

    OUT/
      chart/          the chart's capture session (``core.io.session``: manifest + frames)
      sample/         the sample target's session
      truth/          a simulated bench's truth (sensitivities, corners, scene)
      summary.json    the headline numbers and Tables 1-2 (:meth:`write_summary`)
      *.csv *.json *.ti3 report.html report.pdf   the exports (``core.io.export``)

Every path of a measurement is named here once; readers and writers take a
:class:`MeasurementFolder`, not a path they compose themselves.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

from tunespec.core.io.session import MANIFEST_NAME, atomic_write_text
from tunespec.core.limits import dumps_json, read_json

__all__ = ["MeasurementFolder"]


@dataclass(frozen=True)
class MeasurementFolder:
    """The paths of one measurement below ``root``."""

    root: Path

    @classmethod
    def at(cls, root: str | PathLike[str]) -> MeasurementFolder:
        """The folder at ``root`` (nothing is created)."""
        return cls(Path(root))

    def session_dir(self, which: str) -> Path:
        """The capture session of ``which`` (``"chart"`` or ``"sample"``)."""
        if which not in ("chart", "sample"):
            raise ValueError(f"unknown session {which!r}")
        return self.root / which

    @property
    def chart_dir(self) -> Path:
        return self.session_dir("chart")

    @property
    def sample_dir(self) -> Path:
        return self.session_dir("sample")

    @property
    def truth_dir(self) -> Path:
        return self.root / "truth"

    @property
    def summary_path(self) -> Path:
        return self.root / "summary.json"

    def has_session(self, which: str) -> bool:
        """Whether a capture of ``which`` was started here."""
        return (self.session_dir(which) / MANIFEST_NAME).is_file()

    def write_summary(self, summary: dict[str, Any]) -> Path:
        """Write ``summary.json`` atomically (standard JSON, never NaN)."""
        self.root.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.summary_path, dumps_json(summary))
        return self.summary_path

    def read_summary(self) -> dict[str, Any]:
        """``summary.json`` as written by :meth:`write_summary`."""
        data = read_json(self.summary_path)
        if not isinstance(data, dict):
            from tunespec.core.errors import InputError

            raise InputError("expected an object", path=self.summary_path)
        return data
