"""Shared fixtures of the device tests.

Light sources (this section): a virtual clock, one simulated LED unit, the simulated
light source, the CAL1 emulator serving that unit, and the CAL1 driver connected to
it. Everything runs on a ``VirtualClock``: nothing waits in real time except socket
timeouts that a test asks for on purpose.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator

import pytest

from tunespec.devices.cal1.driver import Cal1LightSource, open_cal1
from tunespec.devices.cal1.emulator import Cal1Emulator
from tunespec.devices.clock import VirtualClock
from tunespec.devices.sim.led_physics import LedPhysics
from tunespec.devices.sim.light import SimLightSource

# --- light sources ----------------------------------------------------------------------

#: Seed of the simulated unit used by the light source fixtures.
LIGHT_SEED = 7
#: Reply timeout of the driver in tests that do not provoke timeouts: generous, since
#: it is never reached when things work (the emulator answers in milliseconds).
CAL1_TIMEOUT_S = 5.0


@pytest.fixture(autouse=True)
def _no_emulator_threads_left() -> Iterator[None]:
    """Fail a test that leaves CAL1 emulator threads running (napari-style check)."""
    yield
    left = [t.name for t in threading.enumerate() if t.name.startswith("cal1-emulator")]
    assert not left, f"CAL1 emulator threads still running: {left}"


@pytest.fixture
def virtual_clock() -> VirtualClock:
    """A fresh virtual clock at t = 0 s."""
    return VirtualClock()


@pytest.fixture
def led_physics(virtual_clock: VirtualClock) -> LedPhysics:
    """A simulated CAL1-like unit (default parameters), switched on at t = 0 s."""
    return LedPhysics(clock=virtual_clock, seed=LIGHT_SEED)


@pytest.fixture
def sim_light(led_physics: LedPhysics) -> Iterator[SimLightSource]:
    """The simulated light source on :func:`led_physics`."""
    with SimLightSource(led_physics) as light:
        yield light


@pytest.fixture
def cal1_emulator(led_physics: LedPhysics) -> Iterator[Cal1Emulator]:
    """A CAL1 emulator serving :func:`led_physics`; fails if its threads crashed."""
    with Cal1Emulator(physics=led_physics) as emu:
        yield emu
    assert emu.errors == [], f"emulator threads raised: {emu.errors!r}"


@pytest.fixture
def cal1_light(cal1_emulator: Cal1Emulator) -> Iterator[Cal1LightSource]:
    """The CAL1 driver connected to :func:`cal1_emulator` (closed afterwards)."""
    with open_cal1(cal1_emulator.spec, timeout_s=CAL1_TIMEOUT_S) as light:
        yield light
