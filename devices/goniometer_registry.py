"""Open a goniometer from its spec string (``sim``, ``zaber://...``).

Kept apart from :mod:`tunespec.devices.goniometer` so that the Protocol imports no
driver (the simulated goniometer uses the Protocol, the drivers stay independent).
"""

from __future__ import annotations

from tunespec.core.errors import InputError
from tunespec.devices.goniometer import Goniometer

__all__ = ["open_goniometer"]


def open_goniometer(spec: str) -> Goniometer:
    """A goniometer from its spec: ``sim`` or a Zaber spec (``zaber://...``).

    Raises
    ------
    InputError
        An unknown spec.
    DeviceError
        The device cannot be opened.
    """
    if spec.strip() in ("sim", "sim://"):
        from tunespec.devices.sim.gonio import SimGoniometer

        return SimGoniometer()
    if spec.strip().startswith("zaber"):
        from tunespec.devices.zaber.driver import open_zaber

        return open_zaber(spec)
    raise InputError(
        f"unknown goniometer {spec!r}: use sim, zaber:///dev/ttyUSB0 or "
        "zaber+socket://HOST:PORT"
    )
