"""A simulated CAL1-like light source (:class:`SimLightSource`) for tests and demos.

It implements :class:`~tunespec.devices.protocols.LightSource` directly on a
:class:`~tunespec.devices.sim.led_physics.LedPhysics` unit, with no protocol in
between; :class:`~tunespec.devices.cal1.emulator.Cal1Emulator` serves the same physics
over the CAL1 protocol instead. Besides the protocol it offers the truth, for the
simulated camera:

- :meth:`SimLightSource.emitted_spd` - the spectral radiance emitted *now*;
- :meth:`SimLightSource.emitted_spd_over` - the mean spectral radiance over an
  exposure ``[t0_s, t1_s]`` (clock times), which includes warm-up and drift during
  the exposure. A camera does ``t0 = clock.now_s(); clock.sleep(exposure_s);
  spd = light.emitted_spd_over(t0, t0 + exposure_s)``.

Both are in W sr^-1 m^-2 nm^-1 on the LED data's grid (360-780 nm, 1 nm for the
shipped model); the camera resamples to its working grid.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qs

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.spectra import Spectra
from tunespec.devices.clock import Clock, VirtualClock
from tunespec.devices.protocols import (
    Channel,
    ClosesOnExit,
    DeviceConnectionError,
    DeviceIdentity,
    LightStatus,
)
from tunespec.devices.sim.led_physics import LedPhysics, validate_levels

__all__ = ["SimLightSource", "open_sim_light"]

#: How long before "now" a ``warm`` simulated unit was switched on.
WARM_POWER_ON_AGO_S = 3600.0


class SimLightSource(ClosesOnExit):
    """A :class:`~tunespec.devices.protocols.LightSource` backed by LED physics.

    Parameters
    ----------
    physics
        The simulated unit; default ``LedPhysics(clock=clock, seed=seed)``.
    clock
        Time source when ``physics`` is not given (default a ``VirtualClock``); if
        both are given, it must be ``physics.clock``.
    seed
        Unit and noise seed when ``physics`` is not given.
    spec
        Spec string recorded in :attr:`identity`.
    """

    def __init__(
        self,
        physics: LedPhysics | None = None,
        *,
        clock: Clock | None = None,
        seed: int = 0,
        spec: str = "sim",
    ) -> None:
        if physics is None:
            physics = LedPhysics(clock=clock, seed=seed)
        elif clock is not None and clock is not physics.clock:
            raise ValueError("clock must be physics.clock (one clock per unit)")
        self._physics = physics
        self._closed = False
        self._identity = DeviceIdentity(
            vendor="TuneSpec",
            model="SimLightSource (CAL1 model)",
            serial=f"SIM-{physics.seed}",
            firmware="sim",
            spec=spec,
        )

    @property
    def physics(self) -> LedPhysics:
        """The simulated unit (shared with a simulated camera)."""
        return self._physics

    @property
    def clock(self) -> Clock:
        """The unit's clock (give the same one to the simulated camera)."""
        return self._physics.clock

    # --- LightSource ------------------------------------------------------------------

    @property
    def identity(self) -> DeviceIdentity:
        """Vendor ``TuneSpec``, serial ``SIM-<seed>``."""
        return self._identity

    def channels(self) -> list[Channel]:
        """The LED channels, in device order."""
        self._check_open()
        return list(self._physics.channels)

    def set_levels(self, levels: ArrayLike) -> None:
        """Set every channel's level in [0, 1], shape (n_channels,).

        Raises
        ------
        ValueError
            Wrong shape, non-finite or out-of-range levels (nothing changes).
        """
        self._check_open()
        self._physics.set_levels(validate_levels(levels, self._physics.n_channels))

    def levels(self) -> NDArray[np.float64]:
        """The levels now set, shape (n_channels,)."""
        self._check_open()
        return self._physics.levels()

    def all_off(self) -> None:
        """Switch every channel off."""
        self._check_open()
        self._physics.all_off()

    def measure_spd(self) -> Spectra:
        """The SPD emitted now, as the simulated spectroradiometer reports it.

        Advances the clock by the meter's integration time (0.5 s by default).
        """
        self._check_open()
        return self._physics.measure_spd()

    def status(self) -> LightStatus:
        """Readiness, case temperature, on-time (see :meth:`LedPhysics.status`)."""
        self._check_open()
        return self._physics.status()

    def close(self) -> None:
        """Switch everything off; further calls raise. Idempotent."""
        if not self._closed:
            self._physics.all_off()
            self._closed = True

    # --- truth for simulated cameras ------------------------------------------------

    def emitted_spd(self) -> Spectra:
        """The true emitted spectral radiance now, one spectrum named ``"emitted"``.

        W sr^-1 m^-2 nm^-1 on the LED data's wavelengths. Works after :meth:`close`
        (then it is zero).
        """
        return self._physics.emitted_spd()

    def emitted_spd_over(self, t0_s: float, t1_s: float) -> Spectra:
        """The true spectral radiance averaged over the clock interval ``[t0_s, t1_s]``.

        Named ``"emitted"``; multiply by ``t1_s - t0_s`` for radiant exposure.
        """
        return self._physics.emitted_spd_over(t0_s, t1_s)

    def __repr__(self) -> str:
        return f"SimLightSource(seed={self._physics.seed}, closed={self._closed})"

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceConnectionError(
                "simulated light source was closed; open it again to use it"
            )


def open_sim_light(
    spec: str = "sim",
    *,
    clock: Clock | None = None,
    seed: int | None = None,
    leds: str | Path | None = None,
    warm: bool | None = None,
) -> SimLightSource:
    """A :class:`SimLightSource` from a spec string.

    ``spec`` is ``sim`` optionally followed by options, e.g.
    ``sim?seed=3&warm=1&leds=/path/leds.csv``; keyword arguments override them.

    Parameters
    ----------
    clock
        Time source (``RealClock`` in the GUI; default a ``VirtualClock``).
    seed
        Unit and noise seed (default 0).
    leds
        An LED spectral CSV replacing the shipped 22-LED model.
    warm
        Start warmed up (switched on an hour ago) instead of just switched on.

    Raises
    ------
    InputError
        For a malformed spec or LED file.
    """
    head, _, query = spec.strip().partition("?")
    if head not in ("sim", "sim://"):
        raise InputError(f"bad simulated light spec {spec!r}: expected sim[?seed=N]")
    options = {k: v[-1] for k, v in parse_qs(query, strict_parsing=False).items()}
    unknown = set(options) - {"seed", "warm", "leds"}
    if unknown:
        raise InputError(
            f"bad simulated light spec {spec!r}: unknown option(s) "
            f"{', '.join(sorted(unknown))} (known: seed, warm, leds)"
        )
    try:
        seed_value = int(options.get("seed", "0")) if seed is None else int(seed)
    except ValueError:
        raise InputError(
            f"bad simulated light spec {spec!r}: seed must be an integer"
        ) from None
    warm_value = (
        (options.get("warm", "0") in ("1", "true", "yes")) if warm is None else warm
    )
    leds_path = leds if leds is not None else options.get("leds")
    led_spectra = read_spectra_csv(leds_path) if leds_path else None
    clock = clock if clock is not None else VirtualClock()
    power_on_s = clock.now_s() - WARM_POWER_ON_AGO_S if warm_value else None
    physics = LedPhysics(
        led_spectra, clock=clock, seed=seed_value, power_on_s=power_on_s
    )
    return SimLightSource(physics, spec=spec)
