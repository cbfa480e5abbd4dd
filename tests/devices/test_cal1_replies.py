"""Issue 24: impossible CAL1 replies are device errors naming the reply.

A spectroradiometer reply that parses but cannot be a measurement (every value
-0.001, 1e300, a spectrum cut short, wavelengths in µm) used to pass: 1e300 halved
an LED's exposure and left 132 saturated patches. Scripted exchanges as in
``test_cal1_protocol.py``; the emulator case goes through the socket.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.devices.conftest import CAL1_TIMEOUT_S
from tests.devices.test_cal1_protocol import IDN, OFF, make_driver
from tunespec.devices.cal1 import commands as cmds
from tunespec.devices.cal1.driver import open_cal1
from tunespec.devices.cal1.emulator import Cal1Emulator
from tunespec.devices.protocols import DeviceProtocolError
from tunespec.devices.testing import FakeTransport


def _reply(start_nm: float, step_nm: float, values: np.ndarray) -> bytes:
    body = ",".join(f"{v:.6e}" for v in values)
    return f"{start_nm:g},{step_nm:g},{values.size},{body}\n".encode()


def _led(peak: float = 1e-3) -> np.ndarray:
    wl = np.arange(380.0, 781.0)
    return peak * np.exp(-0.5 * ((wl - 450.0) / 10.0) ** 2)


def test_a_plausible_spectrum_with_meter_noise_passes() -> None:
    rng = np.random.default_rng(0)
    values = _led() + 1e-6 * rng.standard_normal(401)  # negatives in the tails
    assert values.min() < 0
    with FakeTransport([IDN, (b"MEAS:SPD?\n", _reply(380, 1, values))]) as fake:
        spd = make_driver(fake).measure_spd()
    assert spd.values.shape == (1, 401)
    assert spd.values.max() == pytest.approx(1e-3, rel=0.01)


IMPOSSIBLE = {
    "all -0.001": (380, 1, np.full(401, -0.001), "no value above zero"),
    "all 1e300": (380, 1, np.full(401, 1e300), "no light source is that bright"),
    "one 1e300": (380, 1, np.where(np.arange(401) == 70, 1e300, _led()), "1e+300"),
    "negative": (380, 1, _led() - 2e-4, "negative beyond the meter's noise"),
    "cut short": (380, 1, _led()[:240], "cut short"),
    "micrometres": (0.38, 0.001, _led(), "not a visible spectroradiometer's grid"),
}


@pytest.mark.parametrize("case", IMPOSSIBLE, ids=list(IMPOSSIBLE))
def test_an_impossible_spectrum_is_a_device_error_naming_the_reply(case) -> None:
    start, step, values, why = IMPOSSIBLE[case]
    script = [IDN, (b"MEAS:SPD?\n", _reply(start, step, values)), OFF]
    with FakeTransport(script) as fake, pytest.raises(DeviceProtocolError) as info:
        make_driver(fake).measure_spd()
    message = str(info.value)
    assert "impossible reply" in message and "to MEAS:SPD?" in message
    assert f"{start:g},{step:g},{values.size}," in message  # the reply, shortened
    assert why in message and "switched off" in message
    assert len(message.splitlines()) == 1


def test_spectrum_problem_names_nothing_for_the_emulator(cal1_emulator) -> None:
    with open_cal1(cal1_emulator.spec, timeout_s=CAL1_TIMEOUT_S) as light:
        light.set_levels(np.eye(len(light.channels()))[0])
        spd = light.measure_spd()
    v = spd.values[0]
    step = float(spd.wavelength_nm[1] - spd.wavelength_nm[0])
    s = cmds.MeasuredSpectrum(float(spd.wavelength_nm[0]), step, v)
    assert cmds.spectrum_problem(s) == ""


def test_an_absurd_reply_from_the_emulator_stops_the_measurement(
    cal1_emulator: Cal1Emulator,
) -> None:
    bad = _reply(380, 1, np.full(401, 1e300))
    with open_cal1(cal1_emulator.spec, timeout_s=CAL1_TIMEOUT_S) as light:
        light.set_levels(np.eye(len(light.channels()))[0])
        cal1_emulator.inject_fault("garbage", command="MEAS:SPD?", payload=bad)
        with pytest.raises(DeviceProtocolError, match="no light source is that"):
            light.measure_spd()
    assert not cal1_emulator.lights_on
