"""LightSource conformance: one suite for every light source implementation.

Parametrised over ``sim`` (:class:`SimLightSource`) and ``cal1-emulator`` (the real
:class:`Cal1LightSource` driver talking to :class:`Cal1Emulator` over TCP). Both drive
the same simulated unit, whose truth (:meth:`LedPhysics.emitted_over`) the measured
spectra are checked against. A hardware kind would be added to ``KINDS`` behind
``--device-address``.

The second part tests the LED physics model both implementations share.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest

from tests.tolerances import ATOL_EXACT
from tunespec.core.datasets import load_led_set
from tunespec.core.errors import InputError
from tunespec.core.spectra import Spectra
from tunespec.devices.cal1.driver import open_cal1
from tunespec.devices.clock import VirtualClock
from tunespec.devices.protocols import (
    Channel,
    DeviceError,
    DeviceIdentity,
    LightSource,
    LightStatus,
)
from tunespec.devices.sim.led_physics import (
    LED_GRID,
    PEAK_RADIANCE_W_SR_M2_NM,
    RADIANCE_UNIT,
    LedPhysics,
    LedPhysicsParams,
)
from tunespec.devices.sim.light import SimLightSource, open_sim_light

# --- named tolerances (this suite) ------------------------------------------------------

#: Levels cross the CAL1 wire with 4 decimals.
ATOL_LEVEL_WIRE = 0.5e-4
#: In-band (truth > 1 % of its peak) integral of measured vs emitted radiance: 0.7 %
#: noise per sample averages down to ~0.1 %, and the meter's band-pass and wavelength
#: offset conserve the integral (measured worst case over 40 units: 0.4 %).
RTOL_SPD_INTEGRAL = 0.01
#: Pointwise measured vs emitted, as a fraction of the peak: the narrowest LED (410 nm,
#: FWHM 12 nm) has slopes up to 12 % of its peak per nm and the meter's calibration
#: offset is up to 1 nm, plus 0.7 % noise (measured worst case over 40 units: 11.3 %).
FRAC_SPD_POINTWISE = 0.15
#: Metering residuals against the noise-free meter model, in noise standard
#: deviations, on samples far from the clip at zero: |z| < 5 (p ~ 2e-4 for 400
#: samples) and the spread of z within 0.7..1.3 (>= 50 samples).
Z_MAX = 5.0
Z_STD_RANGE = (0.7, 1.3)
#: Peak wavelength of a measured narrowband LED vs the truth: meter offset <= 1 nm
#: plus the 1 nm sampling.
ATOL_PEAK_NM = 2.0
#: "Zero" spectrum with all LEDs off: dark noise is 1e-8 W sr^-1 m^-2 nm^-1 (1e-5 of
#: an LED peak); 1e-6 is 100 sigma and still 1e-3 of the peak.
DARK_MAX_W_SR_M2_NM = 1e-6

#: A real CAL1 joins the suite when its spec is given, e.g.
#: ``TUNESPEC_LIGHT=cal1:///dev/ttyUSB0 pytest -m hardware tests/devices``.
HARDWARE_SPEC = os.environ.get("TUNESPEC_LIGHT", "")
KINDS = [
    "sim",
    "cal1-emulator",
    pytest.param(
        "hardware",
        marks=[
            pytest.mark.hardware,
            pytest.mark.skipif(
                not HARDWARE_SPEC.startswith("cal1"),
                reason="no CAL1 given (TUNESPEC_LIGHT=cal1:///dev/ttyUSB0)",
            ),
        ],
    ),
]


@dataclass
class LightUnderTest:
    """A light source with the simulated unit behind it (None for hardware)."""

    device: LightSource
    physics: LedPhysics | None
    clock: VirtualClock | None


@pytest.fixture(params=KINDS)
def light(
    request: pytest.FixtureRequest, led_physics: LedPhysics, virtual_clock: VirtualClock
) -> Iterator[LightUnderTest]:
    if request.param == "hardware":
        with open_cal1(HARDWARE_SPEC) as device:
            yield LightUnderTest(device, None, None)
        return
    if request.param == "sim":
        sim: LightSource = request.getfixturevalue("sim_light")
    else:
        sim = request.getfixturevalue("cal1_light")
    yield LightUnderTest(sim, led_physics, virtual_clock)


def _model(light: LightUnderTest) -> tuple[LedPhysics, VirtualClock]:
    """The simulated unit and its clock; skips for hardware (no truth to compare)."""
    if light.physics is None or light.clock is None:
        pytest.skip("needs the simulated unit's truth")
    return light.physics, light.clock


def _single(name: str, level: float = 1.0) -> np.ndarray:
    names = load_led_set().names
    levels = np.zeros(len(names))
    levels[names.index(name)] = level
    return levels


# --- conformance ------------------------------------------------------------------------


def test_is_a_light_source(light: LightUnderTest) -> None:
    assert isinstance(light.device, LightSource)
    ident = light.device.identity
    assert isinstance(ident, DeviceIdentity)
    assert ident.vendor and ident.model and ident.serial and ident.spec


def test_channels_are_the_22_cal1_leds(light: LightUnderTest) -> None:
    channels = light.device.channels()
    assert all(isinstance(c, Channel) for c in channels)
    assert [c.index for c in channels] == list(range(22))
    narrow = [c for c in channels if c.kind == "narrowband"]
    white = [c for c in channels if c.kind == "white"]
    assert len(narrow) == 20 and len(white) == 2
    assert all(380.0 <= c.peak_nm <= 780.0 for c in channels)
    if light.physics is not None:  # the shipped model's names and nominal peaks
        assert tuple(c.name for c in channels) == load_led_set().names
        assert [c.name for c in white] == ["WHITE_COOL", "WHITE_WARM"]
        for c in narrow:
            assert c.peak_nm == float(re.sub(r"\D", "", c.name))


def test_levels_round_trip(light: LightUnderTest) -> None:
    levels = np.random.default_rng(0).uniform(0.0, 1.0, 22)
    levels[[0, 5]] = [0.0, 1.0]
    light.device.set_levels(levels)
    got = light.device.levels()
    assert got.shape == (22,) and got.dtype == np.float64
    np.testing.assert_allclose(got, levels, atol=ATOL_LEVEL_WIRE)
    if light.physics is not None:
        np.testing.assert_allclose(light.physics.levels(), levels, atol=ATOL_LEVEL_WIRE)


@pytest.mark.parametrize(
    "bad",
    [
        np.full(21, 0.5),
        np.full((2, 22), 0.5),
        _single("LED450", 1.5),
        -_single("LED450"),
        _single("LED450", np.nan),
    ],
    ids=["short", "2d", "above-1", "negative", "nan"],
)
def test_set_levels_rejects_bad_levels(light: LightUnderTest, bad: np.ndarray) -> None:
    light.device.set_levels(_single("LED525", 0.25))
    with pytest.raises(ValueError, match="level"):
        light.device.set_levels(bad)
    np.testing.assert_allclose(
        light.device.levels(), _single("LED525", 0.25), atol=ATOL_LEVEL_WIRE
    )


def test_measure_spd_shape_and_units(light: LightUnderTest) -> None:
    light.device.set_levels(_single("LED525"))
    spd = light.device.measure_spd()
    assert isinstance(spd, Spectra)
    assert spd.names == ("measured",)
    assert spd.meta["unit"] == RADIANCE_UNIT
    assert spd.values.shape == (1, spd.wavelength_nm.size)
    assert spd.wavelength_nm[0] <= 400.0 and spd.wavelength_nm[-1] >= 700.0
    assert spd.step_nm > 0  # equidistant
    assert np.all(np.isfinite(spd.values)) and np.all(spd.values >= 0.0)
    if light.physics is not None:
        np.testing.assert_allclose(
            spd.wavelength_nm, np.arange(380.0, 781.0), atol=1e-9
        )
    # absolute scale: the strongest LED peaks near PEAK_RADIANCE (unit gain +-5 %,
    # thermal droop, LED525 is 0.58 of the strongest in the nominal model)
    assert (
        0.3 * PEAK_RADIANCE_W_SR_M2_NM
        < spd.values.max()
        < 1.1 * PEAK_RADIANCE_W_SR_M2_NM
    )


@pytest.mark.parametrize(
    "setting",
    ["LED410", "LED585", "LED700", "WHITE_WARM", "mixture"],
)
def test_measure_spd_matches_the_emitted_truth(
    light: LightUnderTest, setting: str
) -> None:
    if setting == "mixture":
        levels = np.random.default_rng(1).uniform(0.0, 1.0, 22)
    else:
        levels = _single(setting)
    physics, clock = _model(light)
    light.device.set_levels(levels)
    clock.sleep(30.0)  # mid warm-up: the truth moves during the measurement
    t0_s = clock.now_s()
    spd = light.device.measure_spd()
    t1_s = clock.now_s()
    assert t1_s > t0_s  # the measurement integrates over (virtual) time
    truth = np.interp(
        spd.wavelength_nm, physics.wavelength_nm, physics.emitted_over(t0_s, t1_s)
    )
    measured = spd.values[0]
    band = truth > 0.01 * truth.max()
    np.testing.assert_allclose(
        measured[band].sum(), truth[band].sum(), rtol=RTOL_SPD_INTEGRAL
    )
    assert np.max(np.abs(measured - truth)) <= FRAC_SPD_POINTWISE * truth.max()
    if setting.startswith("LED"):
        wl = spd.wavelength_nm
        assert abs(wl[np.argmax(measured)] - wl[np.argmax(truth)]) <= ATOL_PEAK_NM
    # within metering noise of what the unit's meter model reports for that truth
    clean = physics.meter_response(physics.emitted_over(t0_s, t1_s))
    sd = physics.meter_noise_sd(clean)
    unclipped = clean > 5.0 * sd
    z = (measured - clean)[unclipped] / sd[unclipped]
    assert z.size >= 50
    assert np.max(np.abs(z)) < Z_MAX
    assert Z_STD_RANGE[0] < float(np.std(z)) < Z_STD_RANGE[1]


def test_all_off_gives_a_dark_spectrum(light: LightUnderTest) -> None:
    light.device.set_levels(np.full(22, 0.5))
    light.device.all_off()
    np.testing.assert_array_equal(light.device.levels(), np.zeros(22))
    spd = light.device.measure_spd()
    assert np.max(spd.values) < DARK_MAX_W_SR_M2_NM
    if light.physics is not None:
        assert not light.physics.lights_on
        np.testing.assert_array_equal(light.physics.emitted(), 0.0)


def test_status_fields(light: LightUnderTest) -> None:
    light.device.all_off()
    status = light.device.status()
    assert isinstance(status, LightStatus)
    assert isinstance(status.ready, bool)
    assert 15.0 <= status.temperature_c <= 60.0
    assert status.on_time_s == 0.0  # lights off
    assert isinstance(status.message, str)
    assert all(isinstance(v, str) for v in status.extra.values())


def test_status_follows_warm_up_and_on_time(light: LightUnderTest) -> None:
    physics, clock = _model(light)
    status = light.device.status()
    assert status.ready is False  # switched on at t = 0: warming up
    assert status.message
    assert float(status.extra["warmup_left_s"]) > 0.0
    assert "power_on_s" in status.extra

    light.device.set_levels(_single("LED630"))
    clock.sleep(30.0)
    lit = light.device.status()
    assert lit.on_time_s == pytest.approx(30.0, abs=0.1)

    clock.sleep(physics.params.warmup_s)
    warm = light.device.status()
    assert warm.ready is True
    assert float(warm.extra["warmup_left_s"]) == 0.0
    assert warm.temperature_c > status.temperature_c + 1.0


def test_close_switches_off(light: LightUnderTest) -> None:
    light.device.set_levels(np.full(22, 0.3))
    assert light.physics is None or light.physics.lights_on
    light.device.close()
    assert light.physics is None or not light.physics.lights_on
    light.device.close()  # idempotent
    with pytest.raises(DeviceError, match="closed"):
        light.device.set_levels(np.zeros(22))


# --- the shared LED physics -------------------------------------------------------------


def test_units_are_seeded_and_vary_within_limits() -> None:
    a, b = LedPhysics(seed=1), LedPhysics(seed=1)
    c = LedPhysics(seed=2)
    np.testing.assert_array_equal(a.unit.gain, b.unit.gain)
    assert not np.array_equal(a.unit.gain, c.unit.gain)
    for unit in (a.unit, c.unit):
        assert np.all(np.abs(unit.peak_shift_nm) <= 2.0)
        assert np.all(np.abs(unit.gain - 1.0) <= 0.05)
        assert abs(unit.meter_offset_nm) <= 1.0
    a.set_levels(np.full(22, 0.5))
    b.set_levels(np.full(22, 0.5))
    np.testing.assert_array_equal(a.measure_spd().values, b.measure_spd().values)


def test_ideal_unit_emits_the_scaled_nominal_spd_and_meters_it_exactly() -> None:
    physics = LedPhysics(params=LedPhysicsParams.ideal())
    nominal = load_led_set(LED_GRID)
    levels = np.random.default_rng(3).uniform(0.0, 1.0, 22)
    physics.set_levels(levels)
    expected = PEAK_RADIANCE_W_SR_M2_NM * levels @ nominal.values / nominal.values.max()
    np.testing.assert_allclose(physics.emitted(), expected, atol=ATOL_EXACT)
    spd = physics.measure_spd()
    on_meter_grid = np.interp(spd.wavelength_nm, nominal.wavelength_nm, expected)
    np.testing.assert_allclose(spd.values[0], on_meter_grid, atol=ATOL_EXACT)


def test_warm_up_droops_and_red_shifts_amber_more_than_blue() -> None:
    physics = LedPhysics(seed=0, params=LedPhysicsParams(drift_amplitude=0.0))
    names = [c.name for c in physics.channels]
    physics.set_levels(_single("LED585") + _single("LED450"))
    wl = physics.wavelength_nm
    amber = (wl > 560) & (wl < 610)
    blue = (wl > 420) & (wl < 480)
    start = physics.emitted()
    physics.clock.sleep(900.0)
    warm = physics.emitted()
    amber_drop = 1.0 - warm[amber].sum() / start[amber].sum()
    blue_drop = 1.0 - warm[blue].sum() / start[blue].sum()
    assert 0.03 < amber_drop < 0.25
    assert 0.0 < blue_drop < amber_drop / 3.0

    def centroid(spd: np.ndarray, band: np.ndarray) -> float:
        return float((wl[band] * spd[band]).sum() / spd[band].sum())

    assert centroid(warm, amber) - centroid(start, amber) > 0.5
    assert names.index("LED585") != names.index("LED450")


def test_emitted_over_averages_across_level_changes() -> None:
    physics = LedPhysics(params=LedPhysicsParams.ideal())
    clock = physics.clock
    t0_s = clock.now_s()
    physics.set_levels(_single("LED525", 1.0))
    clock.sleep(1.0)
    physics.set_levels(_single("LED525", 0.5))
    clock.sleep(3.0)
    full = physics.emitted(t0_s)
    mean = physics.emitted_over(t0_s, t0_s + 4.0)
    np.testing.assert_allclose(
        mean, full * (1.0 * 1.0 + 0.5 * 3.0) / 4.0, atol=ATOL_EXACT
    )
    spd = physics.emitted_spd_over(t0_s, t0_s + 4.0)
    assert spd.names == ("emitted",) and spd.meta["unit"] == RADIANCE_UNIT
    # the past stays evaluable after later changes
    np.testing.assert_allclose(physics.emitted(t0_s + 0.5), full, atol=ATOL_EXACT)


def test_metering_noise_has_the_modelled_size() -> None:
    physics = LedPhysics(seed=4)
    physics.set_levels(np.full(22, 0.6))
    t0_s = physics.clock.now_s()
    spd = physics.measure_spd()
    clean = physics.meter_response(physics.emitted_over(t0_s, physics.clock.now_s()))
    z = (spd.values[0] - clean) / physics.meter_noise_sd(clean)
    # 401 samples: the standard deviation of z is 1 within ~0.07 (2 sigma)
    assert 0.85 < float(np.std(z)) < 1.15
    assert abs(float(np.mean(z))) < 0.2
    rel = physics.meter_noise_sd(clean) / clean.max()
    assert 0.001 <= rel.max() <= 0.01  # 0.5-1 % noise at the peak


def test_sim_light_gives_the_truth_and_shares_its_clock() -> None:
    clock = VirtualClock()
    light = SimLightSource(clock=clock, seed=5)
    assert light.clock is clock and light.physics.clock is clock
    with pytest.raises(ValueError, match="clock"):
        SimLightSource(light.physics, clock=VirtualClock())
    light.set_levels(_single("LED660"))
    now = light.emitted_spd()
    assert now.names == ("emitted",) and now.values.max() > 0
    t0_s = clock.now_s()
    clock.sleep(6.0)
    exposure = light.emitted_spd_over(t0_s, t0_s + 6.0)
    np.testing.assert_allclose(exposure.values.sum(), now.values.sum(), rtol=0.05)
    light.close()
    np.testing.assert_array_equal(light.emitted_spd().values, 0.0)


def test_open_sim_light_spec() -> None:
    light = open_sim_light("sim?seed=3&warm=1")
    assert (
        light.identity.serial == "SIM-3" and light.identity.spec == "sim?seed=3&warm=1"
    )
    assert light.status().ready is True
    assert open_sim_light("sim", seed=4).identity.serial == "SIM-4"
    for bad in ("simx", "sim?colour=red", "sim?seed=x"):
        with pytest.raises(InputError):
            open_sim_light(bad)
