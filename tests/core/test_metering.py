"""The spectroradiometer's noise floor taken out of reported spectra (core.metering)."""

from __future__ import annotations

import numpy as np
import pytest

from tunespec.core.datasets import load_camera_database, load_led_set
from tunespec.core.forward_model import render_rgb
from tunespec.core.metering import (
    READING_NOISE_META,
    reading_meta,
    reading_noise_fractions,
    reading_noise_rms,
    suppress_meter_floor,
)
from tunespec.core.selfcheck import METER_NOISE_LIMIT
from tunespec.core.spectra import Grid, Spectra

WL = np.arange(380.0, 781.0)
#: The simulated CAL1's metering noise floor: 0.1 % of the peak per reading.
FLOOR_SD = 0.001


def _led(peak_nm: float, fwhm_nm: float = 20.0) -> np.ndarray:
    return np.exp(-0.5 * ((WL - peak_nm) / (fwhm_nm / 2.3548)) ** 2)


def _reported(true: np.ndarray, rng, reads: int = 2) -> np.ndarray:
    """Mean of ``reads`` readings, each clipped at zero (as capture averages the
    readings before and after a frame)."""
    sd = FLOOR_SD * true.max()
    return np.mean(
        [
            np.maximum(true + sd * rng.standard_normal(true.size), 0.0)
            for _ in range(reads)
        ],
        axis=0,
    )


def test_noise_free_spectra_come_back_unchanged() -> None:
    white = 0.3 + _led(450.0) + 0.8 * np.exp(-0.5 * ((WL - 580.0) / 60.0) ** 2)
    leds = load_led_set(Grid(380.0, 780.0, 1.0))
    synthetic = Spectra(WL, np.vstack([_led(700.0), white]), ("LED700", "W"))
    assert all(reading_noise_rms(v, WL) == 0.0 for v in synthetic.values)
    # the shipped LED model: no floor shows noise
    assert max(reading_noise_rms(v, WL) / v.max() for v in leds.values) == 0.0
    for s in (synthetic, leds):
        assert suppress_meter_floor(s) is s


@pytest.mark.parametrize("reads", [1, 2])
def test_the_clipped_floor_goes_and_the_emission_stays(reads) -> None:
    rng = np.random.default_rng(3)
    true = _led(700.0)
    rep = _reported(true, rng, reads)
    sd = FLOOR_SD / np.sqrt(reads)
    assert reading_noise_rms(rep, WL) == pytest.approx(sd, rel=0.35)
    got = suppress_meter_floor(Spectra(WL, rep[None], ("LED700",))).values[0]
    far = np.abs(WL - 700.0) > 60.0
    # the floor: about 0.4 sd a sample before, under a tenth of that after
    assert rep[far].mean() > 0.3 * sd
    assert got[far].mean() < 0.05 * sd
    near = ~far
    np.testing.assert_allclose(got[near], rep[near], atol=4 * sd)
    # cleaned is a fixed point: the calibration and the estimate clean again
    cleaned = Spectra(WL, got[None], ("LED700",))
    assert suppress_meter_floor(cleaned) is cleaned


def test_unclipped_noise_is_zeroed_below_the_detection_limit() -> None:
    rng = np.random.default_rng(4)
    true = _led(520.0)
    rep = true + FLOOR_SD * rng.standard_normal(WL.size)
    assert np.any(rep < 0)
    got = suppress_meter_floor(Spectra(WL, rep[None], ("LED520",))).values[0]
    assert np.all(got >= 0)
    assert reading_noise_rms(rep, WL) == pytest.approx(FLOOR_SD, rel=0.25)
    # outside the emission band and its 10 nm margins only noise was reported
    assert np.all(got[np.abs(WL - 520.0) > 40.0] == 0.0)
    np.testing.assert_array_equal(got[np.abs(WL - 520.0) < 15.0],
                                  rep[np.abs(WL - 520.0) < 15.0])  # fmt: skip


def test_eq1_off_channel_response_is_predicted_again() -> None:
    # The blue channel under a deep-red LED: the clipped floor over 380-600 nm, weighted
    # by blue's sensitivity, is as large as the true response; without it Eq. 1
    # predicts the measured response again.
    grid = Grid(380.0, 780.0, 1.0)
    cam = next(iter(load_camera_database(grid).values())).values
    white = np.ones((1, WL.size))
    true = _led(700.0)
    c_true = render_rgb(white, true[None], cam, 1.0)[0, 0]
    rng = np.random.default_rng(5)
    rep = _reported(true, rng)
    c_rep = render_rgb(white, rep[None], cam, 1.0)[0, 0]
    clean = suppress_meter_floor(Spectra(WL, rep[None], ("LED700",))).values
    c_clean = render_rgb(white, clean, cam, 1.0)[0, 0]
    assert c_rep[2] / c_true[2] > 1.3
    assert c_clean[2] / c_true[2] == pytest.approx(1.0, abs=0.1)
    assert c_clean[0] / c_true[0] == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("step_nm", [5.0, 10.0])
def test_coarsely_reported_spectra_lose_their_floor_too(step_nm) -> None:
    # At 10 nm an LED is two or three samples wide: the blue response to a deep-red
    # LED is predicted again from the spectrum as the instrument reported it
    # (triangular slit as wide as the step), cleaned before it is resampled.
    fine = Grid(380.0, 780.0, 1.0)
    coarse = Grid(380.0, 780.0, step_nm)
    cam = next(iter(load_camera_database(fine).values())).values
    true = Spectra(WL, _led(700.0)[None], ("LED700",)).resample(coarse, average=True)
    rng = np.random.default_rng(6)
    sd = FLOOR_SD * true.values.max()
    rep = true.with_values(
        np.mean(
            [
                np.maximum(true.values + sd * rng.standard_normal(true.values.shape), 0)
                for _ in range(2)
            ],
            axis=0,
        )
    )
    white = np.ones((1, WL.size))

    def blue(s: Spectra) -> float:
        return float(render_rgb(white, s.resample(fine).values, cam, 1.0)[0, 0, 2])

    assert blue(rep) / blue(true) > 1.3
    assert blue(suppress_meter_floor(rep)) / blue(true) == pytest.approx(1.0, abs=0.15)


def test_a_single_reading_every_10_nm_loses_its_floor_too() -> None:
    """One clipped reading every 10 nm leaves half the floor at zero and few samples
    turning: taken for a cleaned or noise-free spectrum, such a spectrum kept its
    floor, and a deep-red LED's made a calibration 0.24 RMS from the truth
    (docs/validation.md)."""
    coarse = Grid(380.0, 780.0, 10.0)
    leds = load_led_set(Grid(380.0, 780.0, 1.0)).resample(coarse)
    narrow = [i for i, n in enumerate(leds.names) if n.startswith("LED")]
    rng = np.random.default_rng(7)
    kept, total = 0, 0
    for noise in (0.001, 0.003):
        sd = noise * leds.values.max(axis=1, keepdims=True)
        for _ in range(25):
            rep = np.maximum(
                leds.values
                + sd * rng.standard_normal(sd.shape[:1] + leds.values.shape[1:]),
                0,
            )
            got = suppress_meter_floor(leds.with_values(rep)).values
            for i in narrow:
                far = (
                    np.abs(
                        coarse.wavelength_nm
                        - leds.wavelength_nm[np.argmax(leds.values[i])]
                    )
                    > 80.0
                )
                total += 1
                kept += bool(np.any(got[i, far] > 0))
    # measured: 0 of 1000 (5 before)
    assert total == 1000
    assert kept <= 1, kept
    # and a noise-free or cleaned spectrum is still taken as it is
    assert suppress_meter_floor(leds) is leds
    cleaned = suppress_meter_floor(leds.with_values(rep))
    bare = Spectra(cleaned.wavelength_nm, cleaned.values, cleaned.names)
    np.testing.assert_array_equal(suppress_meter_floor(bare).values, cleaned.values)


@pytest.mark.parametrize("step_nm", [1.0, 5.0, 10.0])
def test_the_reading_noise_is_kept_as_reported_when_the_floor_is_cleaned(
    step_nm,
) -> None:
    """Cleaned, a spectrum reported every 5 nm keeps only its bands' tails below
    them, which measured as noise of 0.3-0.9 % of the peak; the noise measured
    before the cleaning is kept with the spectra and given instead."""
    coarse = Grid(380.0, 780.0, step_nm)
    rng = np.random.default_rng(4)
    peaks = np.arange(420.0, 700.0, 20.0)
    true = Spectra(
        WL, np.stack([_led(p) for p in peaks]), tuple(f"L{p:.0f}" for p in peaks)
    )
    true = true.resample(coarse, average=True)
    rep = true.with_values(np.stack([_reported(v, rng) for v in true.values]))
    clean = suppress_meter_floor(rep)
    kept = reading_noise_fractions(clean)
    # two readings of 0.1 % averaged, clipped: about 0.07 % (0.03-0.15 % per LED)
    assert list(kept) == list(true.names)
    assert 0.0002 < np.median(list(kept.values())) < 0.0012, kept
    assert max(kept.values()) < METER_NOISE_LIMIT, kept
    assert kept == reading_noise_fractions(rep)  # as reported
    assert reading_noise_fractions(clean.resample(Grid(400.0, 700.0, 2.0))) == kept
    assert READING_NOISE_META not in suppress_meter_floor(true).meta  # noise-free


def test_a_white_with_no_floor_to_measure_gets_the_others_noise() -> None:
    """A phosphor white emits at every sample, so none of them shows the noise
    alone: it is read by the same instrument as the LEDs that do, and gets their
    median; noise-free readings stay noise-free."""
    rng = np.random.default_rng(7)
    peaks = np.arange(420.0, 700.0, 40.0)
    white = 0.2 + _led(450.0, 25.0) + 0.8 * _led(570.0, 120.0)
    true = Spectra(
        WL,
        np.stack([*(_led(p) for p in peaks), white]),
        (*(f"L{p:.0f}" for p in peaks), "WHITE"),
    )
    rep = true.with_values(np.stack([_reported(v, rng) for v in true.values]))
    noise = reading_noise_fractions(rep)
    leds = [noise[n] for n in true.names[:-1]]
    assert min(leds) > 0.0002, noise
    assert noise["WHITE"] == pytest.approx(float(np.median(leds)), rel=1e-12)
    # read one at a time and combined, as capture keeps them: the same
    each = [suppress_meter_floor(rep.select([n])) for n in rep.names]
    meta = {**rep.meta, **reading_meta(each, rep.names)}
    kept = Spectra(rep.wavelength_nm, rep.values, rep.names, meta)
    assert reading_noise_fractions(kept) == pytest.approx(noise, rel=1e-12)
    assert set(reading_noise_fractions(true).values()) == {0.0}


@pytest.mark.parametrize("reads", [1, 2])
@pytest.mark.parametrize("step_nm", [1.0, 5.0, 10.0])
def test_the_reading_noise_is_the_noise_on_the_emission(step_nm, reads) -> None:
    """What the readings' replicates draw on the emission: the noise of one reading,
    over the square root of the readings averaged. The floor clipped at zero
    shows less: its positive samples alone read 0.56-0.66 of it at 1 nm, 0.63-0.86
    at 5 nm."""
    coarse = Grid(380.0, 780.0, step_nm)
    rng = np.random.default_rng(11)
    peaks = np.arange(420.0, 700.0, 10.0)
    true = Spectra(
        WL, np.stack([_led(p) for p in peaks]), tuple(f"L{p:.0f}" for p in peaks)
    ).resample(coarse)
    rep = true.with_values(
        np.stack([_reported(v, rng, reads=reads) for v in true.values])
    )
    ratio = np.array(list(reading_noise_fractions(rep).values())) / (
        FLOOR_SD / np.sqrt(reads)
    )
    assert 0.9 < np.median(ratio) < 1.1, ratio


def test_a_white_keeps_its_tails_when_cleaned() -> None:
    """A white's samples far below its peak are mostly its own emission: measured
    on them, its detection limit was 1.7-6.7 % of the peak at 1 nm, and the cleaning
    cut 0.8-2.1 % of its light (moving a broad-band camera's a* by 0.09 rms). It is
    cleaned at the instrument's noise, which the LEDs' floors show."""
    leds = load_led_set(Grid(380.0, 780.0, 1.0))
    whites = [i for i, n in enumerate(leds.names) if not n.startswith("LED")]
    assert len(whites) == 2
    rng = np.random.default_rng(5)
    rep = leds.with_values(np.stack([_reported(v, rng, reads=1) for v in leds.values]))
    got = suppress_meter_floor(rep).values
    # the light the cleaning took away from each white, of its whole
    lost = np.sum(leds.values * (got == 0.0), axis=1) / np.sum(leds.values, axis=1)
    assert np.all(lost[whites] < 0.002), lost[whites]
    assert np.max(lost) < 0.002, lost
