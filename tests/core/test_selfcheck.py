"""The calibration's self-check (issue 23, item 4): it stays quiet where the models
hold and flags what they lack.

The bench: the default camera renders the SG under the 22 LEDs on a 1 nm grid with
photon and read noise and a 0.3 % flat-field residual, the noise model the check
assumes. With the true sensitivities the reduced chi-square is then 1 within its
spread; an injected problem (1 % response noise the ROI statistics do not know, a
2 % non-linearity, an LED spectrum reported 1.3 times too bright, a noisy
spectroradiometer) must be flagged, through a real calibration too (slow tests).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tunespec.core.datasets import (
    DEFAULT_CAMERA,
    load_camera_database,
    load_colorchecker_sg,
    load_led_set,
)
from tunespec.core.excess import ExcessVariance
from tunespec.core.led_correction import LedCorrection
from tunespec.core.metering import reading_noise_fractions
from tunespec.core.responses import Responses
from tunespec.core.selfcheck import (
    CHI2_LIMIT,
    METER_NOISE_LIMIT,
    NONLINEARITY_LIMIT,
    SYSTEMATIC_LIMIT,
    ChiSquare,
    led_correction_warnings,
    residual_chi_square,
    response_variance,
    self_check,
    systematic_warnings,
)
from tunespec.core.sensitivity import SensitivityEstimate, estimate_camera_sensitivity
from tunespec.core.simulate import NoiseModel, scale_to_exposure, simulate_responses
from tunespec.core.spectra import CALIBRATION_GRID, Grid, Spectra
from tunespec.core.verdict import self_check_findings

FINE = Grid(380.0, 730.0, 1.0)


@pytest.fixture(scope="module")
def bench() -> dict:
    truth = load_camera_database(FINE)[DEFAULT_CAMERA]
    sg = load_colorchecker_sg(FINE)
    leds = scale_to_exposure(sg, load_led_set(FINE), truth, target=0.8)
    rng = np.random.default_rng(3)
    chart = simulate_responses(sg, leds, truth, noise=NoiseModel(), rng=rng)
    return {
        "truth": SensitivityEstimate(truth, "truth"),
        "sg": sg,
        "leds": leds,
        "chart": chart,
        "rng": rng,
    }


def _with_noise(chart: Responses, rng: np.random.Generator, rel: float) -> Responses:
    """``chart`` with extra relative noise that ``rgb_std`` does not report."""
    return replace(
        chart, rgb=chart.rgb * (1.0 + rel * rng.standard_normal(chart.rgb.shape))
    )


def _non_linear(chart: Responses, power: float = 1.02) -> Responses:
    return replace(chart, rgb=np.sign(chart.rgb) * np.abs(chart.rgb) ** power)


def _sensor_effects(chart: Responses, rng: np.random.Generator) -> Responses:
    """Stray light (0.2 % of the mean response under the LED, per patch and LED),
    cross-talk (0.2 % of the other channels, per response) and ``signal^1.003``."""
    rgb = chart.rgb
    out = rgb + 0.002 * rng.standard_normal(rgb.shape[:2])[..., None] * rgb.mean(0)
    out += (
        0.002 * rng.standard_normal(rgb.shape) * (rgb.sum(2, keepdims=True) - rgb) / 2
    )
    return replace(chart, rgb=np.maximum(out, 0.0) ** 1.003)


def test_chi_square_is_one_where_the_noise_model_holds(bench) -> None:
    chi = residual_chi_square(
        bench["truth"], bench["chart"], bench["leds"], bench["sg"], fitted=False
    )
    assert chi.n_stimuli == chi.dof == 140 * 22
    assert chi.spread == pytest.approx(np.sqrt(2 / 3080))
    # 0.99, 1.00, 1.02 at this seed: within 3 of its standard deviations (0.025)
    assert np.all(np.abs(chi.reduced - 1.0) < 3 * chi.spread), chi.reduced
    assert chi.flagged == ()


@pytest.mark.parametrize(
    ("problem", "at_least"),
    [("noise", 6.0), ("non-linear", 100.0)],
)
def test_chi_square_flags_what_the_noise_model_lacks(bench, problem, at_least) -> None:
    chart = (
        _with_noise(bench["chart"], np.random.default_rng(5), 0.01)
        if problem == "noise"
        else _non_linear(bench["chart"])
    )
    chi = residual_chi_square(
        bench["truth"], chart, bench["leds"], bench["sg"], fitted=False
    )
    # 1 % noise: 8.4-9.4; signal^1.02: 217-288
    assert np.all(chi.reduced > at_least), chi.reduced
    assert chi.flagged == ("R", "G", "B")


def _one_response() -> Responses:
    """One patch under one LED: RGB 0.5, 0.1, 0 with ROI std 0.02 over 400 px."""
    return Responses(
        ("A1",),
        ("L1",),
        np.array([[[0.5, 0.1, 0.0]]]),
        rgb_std=np.full((1, 1, 3), 0.02),
        n_pixels=np.full((1, 1), 400.0),
    )


def test_chi_square_limit_and_variance_model() -> None:
    # many stimuli: the fixed limit; few: five standard deviations above 1
    assert ChiSquare(np.ones(3), dof=3000, n_stimuli=3000).limit == CHI2_LIMIT
    few = ChiSquare(np.array([2.5, 1.0, 3.0]), dof=20, n_stimuli=20)
    assert few.limit == pytest.approx(1 + 5 * np.sqrt(0.1))  # 2.58
    assert few.flagged == ("B",)
    r = _one_response()
    # 0.02^2 / 400 + (0.003 c)^2 + 1e-6^2
    assert response_variance(r)[0, 0] == pytest.approx(
        np.array([1e-6 + 2.25e-6, 1e-6 + 9e-8, 1e-6]) + 1e-12, rel=1e-12
    )


def test_the_error_model_with_fitted_terms() -> None:
    r = _one_response()
    fitted = ExcessVariance(
        response_relative=0.004, common_relative=0.0, flat_field_relative=0.001
    )
    # the fitted flat field replaces the nominal one, the relative term adds
    expected = 1e-6 + (0.001**2 + 0.004**2) * np.array([0.25, 0.01, 0.0]) + 1e-12
    assert response_variance(r, fitted)[0, 0] == pytest.approx(expected, rel=1e-12)
    est = SensitivityEstimate(
        Spectra(np.array([500.0]), np.ones((3, 1)), ("R", "G", "B")),
        "truth",
        excess=replace(fitted, nonlinearity=0.006, flat_field_relative=0.0051),
    )
    found = systematic_warnings(est)
    assert list(found) == [
        "flat-field residual",
        "non-linearity (response^(1 + gamma))",
    ]
    assert "flat-field residual of 0.51 % (limit 0.5 %)" in found["flat-field residual"]
    assert SYSTEMATIC_LIMIT == NONLINEARITY_LIMIT == 0.005


def test_led_corrections_far_from_none_are_flagged(bench) -> None:
    names = ("LED450", "LED540", "LED630")
    corr = LedCorrection(
        names,
        gain=(1.02, 0.77, 1.0),
        shift_nm=(0.5, 0.1, -2.6),
        gain_std=(0.002, 0.002, 0.002),
        shift_std_nm=(0.05, 0.05, 0.05),
    )
    est = replace(bench["truth"], led_correction=corr)
    lines = led_correction_warnings(est)
    assert len(lines) == 2
    assert lines[0].startswith("LED540: ") and "0.770" in lines[0]
    assert lines[1].startswith("LED630: ") and "-2.6 nm" in lines[1]
    # a large correction that is poorly determined is no finding
    vague = replace(corr, gain_std=(0.002, 0.1, 0.002), shift_std_nm=(0.05, 0.05, 1.0))
    assert led_correction_warnings(replace(est, led_correction=vague)) == ()


def test_noisy_readings_of_the_light_are_flagged(bench) -> None:
    leds = bench["leds"]
    assert max(reading_noise_fractions(leds).values()) == 0.0
    rng = np.random.default_rng(2)
    peak = leds.values.max(axis=1, keepdims=True)
    noisy = leds.with_values(
        np.maximum(
            leds.values + 0.005 * peak * rng.standard_normal(leds.values.shape), 0
        )
    )
    found = reading_noise_fractions(noisy)
    # a single clipped reading of 0.5 % of the peak, measured on the 20 narrow LEDs'
    # floors; a white is broad, with no floor to measure, and gets their median
    narrow = [n for n in leds.names if n.startswith("LED")]
    assert len(narrow) == 20
    assert all(found[n] > METER_NOISE_LIMIT for n in narrow), found
    checked = self_check(
        bench["truth"], bench["chart"], leds, bench["sg"], reported_illuminants=noisy
    )
    assert len(checked.warnings) == 1, checked.warnings
    assert checked.warnings[0].startswith("the light's readings carry noise")
    assert checked.held_out is None  # no way to calibrate again was given


# -- through a real calibration ---------------------------------------------------------
def _calibrated_check(chart: Responses, leds, sg, *, refit: bool):
    grid = CALIBRATION_GRID
    illum, refl = leds.resample(grid, average=True), load_colorchecker_sg(grid)
    est = estimate_camera_sensitivity(chart, illum, refl)
    fit = (lambda r: estimate_camera_sensitivity(r, illum, refl)) if refit else None
    return est, self_check(est, chart, illum, refl, reported_illuminants=leds, fit=fit)


@pytest.mark.slow
def test_a_good_bench_passes_every_check(bench) -> None:
    _, checked = _calibrated_check(
        bench["chart"], bench["leds"], bench["sg"], refit=True
    )
    assert checked.passed, checked.warnings
    # against the fitted error model (flat field 0.28 %): 1.12-1.15 fitted, the
    # maximum-likelihood variance a little low for the parameters the fit spent
    assert np.all(np.abs(checked.residuals.reduced - 1.0) < 0.2)
    held = checked.held_out
    assert held is not None and len(held.patches) == 28
    assert held.prediction.mean[3] < 2 * held.training.mean[3]
    assert np.all(np.abs(held.chi_square.reduced - 1.0) < 0.25)
    assert checked.as_dict()["passed"] is True


@pytest.mark.slow
@pytest.mark.parametrize(
    ("problem", "terms"),
    [
        # fitted 1.02 % (the ROI statistics miss it)
        ("noise", ("relative error of each response beyond its ROI noise",)),
        # gamma 0.0192, and 0.74 % relative that the fit gives it besides
        ("non-linear", ("non-linearity (response^(1 + gamma))",)),
        ("flat field", ("flat-field residual",)),  # 1.02 %
        ("led", ()),
    ],
)
def test_a_bench_with_a_problem_is_flagged(bench, problem, terms) -> None:
    chart, leds = bench["chart"], bench["leds"]
    if problem == "noise":
        chart = _with_noise(chart, np.random.default_rng(5), 0.01)
    elif problem == "non-linear":
        chart = _non_linear(chart)
    elif problem == "flat field":  # 1 % of the irradiance per patch and LED
        rng = np.random.default_rng(9)
        chart = replace(
            chart,
            rgb=chart.rgb
            * (1 + 0.01 * rng.standard_normal(chart.rgb.shape[:2]))[..., None],
        )
    else:  # LED540's spectrum reported 1.3 times too bright
        values = leds.values.copy()
        values[leds.names.index("LED540")] *= 1.3
        leds = leds.with_values(values)
    _, checked = _calibrated_check(chart, leds, bench["sg"], refit=False)
    assert not checked.passed
    # the fitted systematic terms take the problem up: the residuals then match the
    # error model the error bars use (no flag), and the term is named instead
    assert checked.residuals.flagged == ()
    if problem == "led":
        assert checked.implausible_leds == ("LED540",)
        assert checked.large_systematic == ()
    else:
        assert set(terms) <= set(checked.large_systematic), checked.large_systematic
        assert checked.warnings[0].startswith("the calibration's residuals show a")
        findings = self_check_findings(checked.as_dict())
        assert any(f.startswith("large systematic errors") for f in findings)


@pytest.mark.slow
def test_the_benchmarks_sensor_effects_are_no_finding(bench) -> None:
    # stray light and cross-talk of 0.2 % and signal^1.003 (the generalisation
    # benchmark's --systematic): against the 0.3 % flat field alone the residuals'
    # chi-square was 22-58; the fitted terms (stray 0.21 %, cross-talk 0.18 %,
    # gamma 0.0028) carry them, and they are below the limits
    chart = _sensor_effects(bench["chart"], np.random.default_rng(7))
    _, checked = _calibrated_check(chart, bench["leds"], bench["sg"], refit=False)
    assert checked.residuals.flagged == ()
    assert np.all(checked.residuals.reduced < 1.4), checked.residuals.reduced
    assert checked.large_systematic == ()
    assert [w for w in checked.warnings if "residuals" in w] == []
