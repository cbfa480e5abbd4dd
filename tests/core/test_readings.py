"""Errors in variables: the light's reading noise in calibration and estimate (issue 23).

The simulated bench's LEDs, reported every 10 nm with noise of 0.3 % of each peak
(two readings averaged, clipped at zero, cleaned as the readers clean them); the
camera renders the SG and the 190 test reflectances on a 1 nm grid.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from tunespec.core.calibration import Calibration
from tunespec.core.colorimetry import lab_d50
from tunespec.core.datasets import (
    DEFAULT_CAMERA,
    load_camera_database,
    load_colorchecker_sg,
    load_led_set,
    load_training_reflectances_190,
)
from tunespec.core.errors import InputError
from tunespec.core.metering import (
    READING_STEP_META,
    reading_noise_fractions,
    suppress_meter_floor,
)
from tunespec.core.readings import (
    REPLICATES,
    ReadingReplicates,
    draw_noise,
    replicate_spectra,
)
from tunespec.core.sensitivity import estimate_camera_sensitivity
from tunespec.core.simulate import NoiseModel, scale_to_exposure, simulate_responses
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra
from tunespec.core.uncertainty import (
    budget_summary,
    readings_response_covariance,
    wiener_with_uncertainty,
)
from tunespec.core.wiener import on_integration_grid

FINE = Grid(380.0, 730.0, 1.0)
NOISE = 0.003


def _read(leds: Spectra, rng: np.random.Generator) -> Spectra:
    """Every 10 nm, two noisy readings clipped at zero and averaged, cleaned as a
    reader of the instrument's file cleans them."""
    at10 = leds.resample(Grid(380.0, 730.0, 10.0))
    peak = at10.values.max(axis=1, keepdims=True)
    reads = [
        np.maximum(
            at10.values + NOISE * peak * rng.standard_normal(at10.values.shape), 0
        )
        for _ in range(2)
    ]
    return suppress_meter_floor(at10.with_values(np.mean(reads, axis=0)))


def _reported(leds: Spectra, rng: np.random.Generator) -> Spectra:
    """:func:`_read`, on the calibration's grid."""
    return _read(leds, rng).resample(DEFAULT_GRID, average=True)


@pytest.fixture(scope="module")
def bench():
    truth = load_camera_database(FINE)[DEFAULT_CAMERA]
    sg_fine = load_colorchecker_sg(FINE)
    leds = scale_to_exposure(sg_fine, load_led_set(FINE), truth, target=0.8)
    rng = np.random.default_rng(5)
    chart = simulate_responses(sg_fine, leds, truth, noise=NoiseModel(), rng=rng)
    test_fine = load_training_reflectances_190(FINE)
    test = simulate_responses(test_fine, leds, truth, noise=NoiseModel(), rng=rng)
    native = _read(leds, rng)
    reported = native.resample(DEFAULT_GRID, average=True)
    est = estimate_camera_sensitivity(
        chart,
        reported,
        load_colorchecker_sg(DEFAULT_GRID),
        database=load_camera_database(DEFAULT_GRID),
        exclude=DEFAULT_CAMERA,
    )
    return {
        "est": est,
        "chart": chart,
        "leds": leds,  # as they shone
        "reported": reported,
        "native": native,  # the same readings at the instrument's 10 nm
        "other": _reported(leds, rng),  # another session's readings
        "test": load_training_reflectances_190(DEFAULT_GRID),
        "test_responses": test,
        "test_lab": lab_d50(test_fine),
    }


def test_the_cleaning_keeps_the_instruments_step_and_noise_through_resampling(
    bench,
) -> None:
    reported = bench["reported"]
    assert float(reported.meta[READING_STEP_META]) == 10.0
    fractions = np.array(list(reading_noise_fractions(reported).values()))
    # two readings of 0.3 % averaged: 0.21 %, measured on the clipped floor
    assert 0.0005 < np.median(fractions) < 0.003, fractions
    # cleaning again after resampling keeps what the first cleaning measured
    again = suppress_meter_floor(reported)
    assert again.meta.get(READING_STEP_META) == reported.meta[READING_STEP_META]
    assert reading_noise_fractions(again) == reading_noise_fractions(reported)


def test_a_noisy_calibration_is_fitted_again_per_replicate(bench) -> None:
    reps = bench["est"].readings
    assert reps is not None and reps.n_replicates == REPLICATES
    assert reps.names == tuple(bench["reported"].names)
    # the replicates move the sensitivities by a little, not by nothing
    rel = np.abs(reps.sensitivity_delta).max() / bench["est"].sensitivity.values.max()
    assert 1e-4 < rel < 0.2, rel
    assert np.all(np.abs(np.log(reps.gain)) < 0.2)
    # the sensitivities' bands carry the replicates' spread beside the covariance's
    est = bench["est"]
    n = est.sensitivity.wavelength_nm.size
    cov_only = np.sqrt(np.maximum(np.diag(est.covariance)[: 3 * n], 0)).reshape(3, n)
    assert np.all(est.std >= cov_only) and np.any(est.std > 1.01 * cov_only)
    # noise-free readings: nothing to replicate
    assert replicate_spectra(load_led_set(DEFAULT_GRID)) == []


def test_the_same_draw_for_the_same_key() -> None:
    wl = DEFAULT_GRID.wavelength_nm
    led = np.exp(-0.5 * ((wl - 520.0) / 12.0) ** 2)
    led[led < 1e-3] = 0.0  # cleaned: zero outside the band
    a = draw_noise(wl, led, 0.002, 10.0, (3, 4))
    assert np.array_equal(a, draw_noise(wl, led, 0.002, 10.0, (3, 4)))
    assert not np.array_equal(a, draw_noise(wl, led, 0.002, 10.0, (3, 5)))
    # nothing far from the band (the cleaning zeroes the readings there) but the
    # cubic spline's ripples from 10 nm onto 5 nm
    far = np.abs(a[np.abs(wl - 520.0) > 60.0]).max()
    assert far < 0.05 * np.abs(a).max(), (far, np.abs(a).max())
    assert np.all(draw_noise(wl, led, 0.0, 10.0, (0, 0)) == 0.0)


def test_the_readings_term_shares_the_calibrations_draw(bench) -> None:
    est, test = bench["est"], bench["test"]
    same = readings_response_covariance(est, bench["reported"], test)
    other = readings_response_covariance(est, bench["other"], test)
    n = same.shape[1]
    assert same.shape == (len(test), n, n) and n == 3 * 22
    var_same = np.diagonal(same, axis1=1, axis2=2)
    var_other = np.diagonal(other, axis1=1, axis2=2)
    assert np.all(var_same >= 0) and np.median(var_same) > 0
    # under its own readings the calibration absorbed part of their noise, which
    # cancels; another session's readings bring noise of their own
    assert np.median(var_same) < np.median(var_other), (
        np.median(var_same),
        np.median(var_other),
    )


def test_the_calibrations_readings_are_recognised_at_their_own_step(bench) -> None:
    # ``tunespec estimate`` reads the calibration's 10 nm file again: resampled
    # after their cleaning, the readings kept the spline's tails (up to 0.3 % of a
    # peak), were taken for other readings and drew noise of their own; the
    # readings' term was then 0.37 of u(L*)^2, not 0.05, and the CLI's intervals
    # covered L* 0.98-1.00 (benchmarks/cli_protocol.py)
    est, test = bench["est"], bench["test"]
    on_grid = readings_response_covariance(est, bench["reported"], test)
    native = readings_response_covariance(est, bench["native"], test)
    assert np.allclose(native, on_grid, rtol=1e-9, atol=1e-18)


def test_replicates_survive_save_and_load(tmp_path, bench) -> None:
    est = bench["est"]
    back = Calibration.load(est.save(tmp_path / "cal.json"))
    assert back.readings is not None
    assert np.array_equal(back.readings.gain, est.readings.gain)
    a = readings_response_covariance(est, bench["reported"], bench["test"])
    b = readings_response_covariance(back, bench["reported"], bench["test"])
    assert np.allclose(a, b, rtol=1e-9, atol=0.0)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("gain"), "gain"),
        (lambda d: d.update(noise_fraction=[2.0] * len(d["names"])), "outside"),
        (lambda d: d.update(shift_nm=[[0.0]]), "shape"),
        (lambda d: d.update(readings=True), "expected"),
    ],
)
def test_a_malformed_replicate_block_is_refused_in_one_line(
    bench, edit, message
) -> None:
    doc = json.loads(json.dumps(bench["est"].readings.as_dict()))
    edit(doc)
    with pytest.raises(InputError, match=message) as err:
        ReadingReplicates.from_dict(doc, path="cal.meta.json")
    assert "\n" not in str(err.value) and "reading_replicates" in str(err.value)


def test_the_budget_has_the_readings_row_and_the_intervals_hold(bench) -> None:
    est, reported = bench["est"], bench["reported"]
    grid = Grid(400.0, 700.0, 10.0)
    illum, sens, _ = on_integration_grid(
        est.correct_illuminants(reported), est.sensitivity, grid
    )
    prior = load_colorchecker_sg(grid)
    _, unc = wiener_with_uncertainty(
        bench["test_responses"], illum, sens, prior, reported, est
    )
    budget = budget_summary(unc)
    assert "readings" in budget and budget["readings"]["share_L"] > 0.002, budget
    assert abs(sum(b["share_L"] for b in budget.values()) - 1.0) < 1e-9
    # the surfaces' own colour (1 nm) inside the 95 % intervals (0.3 % readings
    # at 10 nm, an ideal sensor, 190 reflectances: 0.984 / 0.926 / 0.995 measured)
    inside = np.abs(unc.lab - bench["test_lab"]) <= 1.96 * unc.lab_std
    assert np.all(inside.mean(axis=0) >= 0.88), inside.mean(axis=0)


def test_the_readings_noise_survives_a_spectral_csv(tmp_path, bench) -> None:
    from tunespec.core.io.spectral import read_spectral
    from tunespec.core.io.spectral_csv import write_spectra_csv

    reported = bench["reported"]
    path = tmp_path / "illuminants.csv"
    write_spectra_csv(reported, path)
    back = read_spectral(path, kind="illuminant")
    assert back.meta[READING_STEP_META] == "10.0"
    assert reading_noise_fractions(back) == pytest.approx(
        reading_noise_fractions(reported), rel=1e-12
    )
    # the comments follow the data: colour-science's reader (numpy's genfromtxt,
    # names from the first line) reads the file as it reads any spectral CSV
    import colour

    sds = colour.io.read_sds_from_csv_file(str(path))
    assert list(sds) == list(reported.names)
    # a comment that says something impossible is refused, naming its line
    lines = path.read_text().splitlines()
    at = lines.index("# reading_step_nm: 10.0")
    lines[at] = "# reading_step_nm: -3"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"reading_step_nm: step -3 nm") as err:
        read_spectral(path, kind="illuminant")
    assert err.value.line == at + 1 and "\n" not in str(err.value)


def test_the_excess_leaves_the_readings_noise_to_the_readings_term(bench) -> None:
    """The readings' noise moves the chart's residuals too; the calibration's
    replicates measure that, and the excess is fitted beside it: the fitted sensor
    terms are those of the same chart read without noise (a relative response
    error of 0.019 % was fitted to the noise instead before): the same chart read
    without noise."""
    exact = suppress_meter_floor(bench["leds"].resample(Grid(380.0, 730.0, 10.0)))
    clean = estimate_camera_sensitivity(
        bench["chart"],
        exact.resample(DEFAULT_GRID, average=True),
        load_colorchecker_sg(DEFAULT_GRID),
        database=load_camera_database(DEFAULT_GRID),
        exclude=DEFAULT_CAMERA,
    )
    noisy, quiet = bench["est"].excess, clean.excess
    assert noisy.response_relative <= quiet.response_relative + 5e-5, (noisy, quiet)
    assert noisy.common_relative <= quiet.common_relative + 5e-5, (noisy, quiet)
