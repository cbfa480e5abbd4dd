"""Test helpers for the camera tests: a stub light and DNG frames for the fake camera.

The fake python-gphoto2 module is ``tunespec.devices.testing.make_fake_gphoto2``.

Kept out of ``conftest.py`` (owned by another part of the project); the camera test
modules import from here.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from tunespec.core.datasets import load_led_set
from tunespec.core.spectra import Spectra
from tunespec.devices.clock import Clock
from tunespec.devices.sim.camera import NOMINAL_PEAK_RADIANCE_W_SR_M2_NM


class StubLight:
    """A light source that only knows its true SPD (stands in for SimLightSource).

    Parameters
    ----------
    channel
        LED of the nominal set, or ``None`` for darkness.
    level
        The LED's level: its SPD is the nominal relative SPD times ``level`` times
        the nominal peak radiance (1e-3 W sr^-1 m^-2 nm^-1, as ``SimLightSource``).
    drift_per_s
        Relative change of the output per second of ``clock`` time (0: stable).
    """

    def __init__(
        self,
        channel: str | None = "WHITE_WARM",
        level: float = 1.0,
        *,
        clock: Clock | None = None,
        drift_per_s: float = 0.0,
    ) -> None:
        leds = load_led_set()
        self._wl = leds.wavelength_nm
        self._base = (
            np.zeros_like(self._wl)
            if channel is None
            else leds[channel] * level * NOMINAL_PEAK_RADIANCE_W_SR_M2_NM
        )
        self._clock = clock
        self._drift = drift_per_s

    def factor(self) -> float:
        t = 0.0 if self._clock is None else self._clock.now_s()
        return 1.0 + self._drift * t

    def emitted_spd(self) -> Spectra:
        return Spectra(self._wl, self._base[None] * self.factor(), ("emitted",))


def dng_raw_maker(tmp_dir: Path) -> Callable[[dict[str, str]], bytes]:
    """``make_raw`` that returns a small CFA DNG tagged with the camera's settings."""
    from tunespec.devices.canon.gphoto2_camera import parse_shutter_speed
    from tunespec.devices.dng import write_dng

    rng = np.random.default_rng(0)

    def make(settings: dict[str, str]) -> bytes:
        mosaic = rng.integers(2048, 15000, (64, 96)).astype(np.uint16)
        path = write_dng(
            tmp_dir / "fake_frame.dng",
            mosaic,
            exposure_s=parse_shutter_speed(settings["shutterspeed"]),
            iso=int(settings["iso"]) if settings["iso"].isdigit() else None,
            make="Canon",
            model="Canon EOS 5D Mark III",
        )
        return path.read_bytes()

    return make
