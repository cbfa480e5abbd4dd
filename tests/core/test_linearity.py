"""A sensor's non-linearity found in the chart's residuals and undone (issue 23): the
calibration finds ``gamma`` of ``signal^(1 + gamma)`` with its sign, fits again on the
linearised responses, and every estimate linearises its own responses the same way."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from tunespec.core.calibration import Calibration, linearise_from_meta
from tunespec.core.colorimetry import delta_e_2000, lab_d50
from tunespec.core.datasets import (
    DEFAULT_CAMERA,
    load_camera_database,
    load_colorchecker_sg,
    load_led_set,
    load_training_reflectances_190,
)
from tunespec.core.errors import InputError
from tunespec.core.excess import (
    LINEARITY_GAMMA_MAX,
    ExcessVariance,
    fit_linearity,
    linearise,
    log_profile,
)
from tunespec.core.plausibility import (
    Implausible,
    board_bend,
    board_bend_warning,
    check_chart_linearity,
    white_response,
)
from tunespec.core.responses import Responses
from tunespec.core.selfcheck import self_check
from tunespec.core.sensitivity import estimate_camera_sensitivity
from tunespec.core.simulate import NoiseModel, scale_to_exposure, simulate_responses
from tunespec.core.spectra import CALIBRATION_GRID, Grid
from tunespec.core.uncertainty import wiener_with_uncertainty
from tunespec.core.wiener import on_integration_grid


def _responses(rgb: np.ndarray, std: np.ndarray | None = None) -> Responses:
    n_p, n_i, _ = rgb.shape
    return Responses(
        tuple(f"P{p}" for p in range(n_p)),
        tuple(f"L{i}" for i in range(n_i)),
        rgb,
        rgb_std=std,
        n_pixels=None if std is None else np.full((n_p, n_i), 400.0),
    )


def test_linearise_undoes_a_power_law_and_carries_the_noise() -> None:
    x = np.array([[[0.5, 0.02, 1e-4], [0.9, -1e-3, 0.0]]])
    std = np.full(x.shape, 1e-3)
    bent = _responses(np.sign(x) * np.abs(x) ** 1.003, std)
    flat = linearise(bent, 0.003)
    assert np.allclose(flat.rgb, x, rtol=1e-12, atol=1e-15)
    # the noise through the derivative p c^(p - 1) (about the noise's own scale at 0)
    p = 1 / 1.003
    c = np.maximum(np.abs(bent.rgb), std)
    assert np.allclose(flat.rgb_std, std * p * c ** (p - 1), rtol=1e-12)
    assert flat.rgb_std[0, 0, 2] > std[0, 0, 2]  # a dark response's noise grows
    assert linearise(bent, 0.0) is bent


@pytest.mark.parametrize("gamma", [0.003, -0.002, 0.0])
def test_the_fit_finds_the_bend_with_its_sign(gamma: float) -> None:
    rng = np.random.default_rng(4)
    c = rng.uniform(0.02, 0.8, (140, 66))
    ex = ExcessVariance(0.002, 0.0, log_reference_by_response=tuple(np.log(c).mean(0)))
    u = log_profile(c, np.asarray(ex.log_reference_by_response)[None])
    noise = np.full(c.shape, 1e-8)
    r = gamma * u + 0.002 * c * rng.standard_normal(c.shape)
    r += np.sqrt(noise) * rng.standard_normal(c.shape)
    g, se = fit_linearity(c + r, c, noise, ex)
    assert 1e-5 < se < 2e-4
    assert abs(g - gamma) < 3 * se, (g, se)


def test_a_bend_no_sensor_has_is_refused() -> None:
    """A significant bend of LINEARITY_GAMMA_MAX or more is a tone curve or a black
    level, not undone: the calibration refuses it (``--force`` to accept)."""
    check_chart_linearity({})  # no fit (the paper's estimators, a linear chart)
    check_chart_linearity({"linearity_gamma_found": 0.003, "linearity_gamma_se": 1e-4})
    check_chart_linearity({"linearity_gamma_found": 0.049, "linearity_gamma_se": 1e-4})
    # as large, but not significant: nothing to say
    check_chart_linearity({"linearity_gamma_found": -0.2, "linearity_gamma_se": 0.1})
    for gamma in (LINEARITY_GAMMA_MAX, -0.148, 0.09):
        with pytest.raises(Implausible, match=re.escape(f"gamma {gamma:+.3f} ")):
            check_chart_linearity(
                {"linearity_gamma_found": gamma, "linearity_gamma_se": 1e-3}
            )


def test_side_file_keeps_the_exponent_and_refuses_an_implausible_one() -> None:
    ex = ExcessVariance(0.001, 0.0, 140, 9240, linearity_gamma=-0.004)
    assert ExcessVariance.from_dict(ex.as_dict()) == ex
    assert ExcessVariance.from_dict({"response_relative": 0.0}).linearity_gamma == 0.0
    for bad in (0.2, -0.06, True, "0.003"):
        with pytest.raises(InputError, match="linearity_gamma") as err:
            ExcessVariance.from_dict({"linearity_gamma": bad}, path="S.csv.meta.json")
        assert "S.csv.meta.json" in str(err.value)


FINE = Grid(380.0, 730.0, 1.0)


@pytest.fixture(scope="module")
def bent_bench() -> dict:
    """The default camera under the 22 LEDs with photon and read noise, the 0.3 %
    flat field and ``signal^1.003`` on the SG and on 190 other surfaces."""
    truth = load_camera_database(FINE)[DEFAULT_CAMERA]
    sg, tests = load_colorchecker_sg(FINE), load_training_reflectances_190(FINE)
    leds = scale_to_exposure(sg, load_led_set(FINE), truth, target=0.8)
    rng = np.random.default_rng(11)

    def bent(refl):
        r = simulate_responses(refl, leds, truth, noise=NoiseModel(), rng=rng)
        return replace(r, rgb=np.maximum(r.rgb, 0.0) ** 1.003)

    grid = CALIBRATION_GRID
    illum = leds.resample(grid, average=True)
    chart, test = bent(sg), bent(tests)
    return {
        "cal": estimate_camera_sensitivity(chart, illum, load_colorchecker_sg(grid)),
        "illum": illum,
        "sg": load_colorchecker_sg(grid),
        "chart": chart,
        "test": test,
        "tests": tests,
    }


@pytest.mark.slow
def test_a_bent_sensor_is_found_linearised_and_estimated_better(
    bent_bench, tmp_path
) -> None:
    cal, illum = bent_bench["cal"], bent_bench["illum"]
    assert cal.excess is not None
    # 0.00266 measured (+-0.00015); after the second fit the residuals show 0.0001
    assert 0.0022 <= cal.excess.linearity_gamma <= 0.0038, cal.excess
    assert cal.excess.nonlinearity <= 0.001, cal.excess
    # the bend as fitted travels in the params, and a sensor's passes the check
    assert cal.params["linearity_gamma_found"] == cal.excess.linearity_gamma
    assert cal.params["linearity_gamma_se"] < 0.0005, cal.params
    check_chart_linearity(cal.params)
    # it travels with the calibration, and the file path undoes it too
    back = Calibration.load(cal.save(tmp_path / "cal.json"))
    assert back.excess is not None
    assert back.excess.linearity_gamma == cal.excess.linearity_gamma
    # the self-check says so, and the linearised residuals match the error model
    checked = self_check(cal, bent_bench["chart"], illum, bent_bench["sg"])
    assert checked.linearity_gamma == cal.excess.linearity_gamma
    assert "undone in every response" in checked.format_text()
    assert checked.as_dict()["linearity_gamma"] == cal.excess.linearity_gamma
    assert checked.residuals.flagged == () and checked.passed, checked.warnings
    test = bent_bench["test"]
    via_meta = linearise_from_meta(test, back.sensitivity.meta)
    assert np.array_equal(via_meta.rgb, cal.linearise(test).rgb)
    assert not np.allclose(via_meta.rgb, test.rgb)
    # the 190 surfaces, estimated with and without their responses linearised
    grid = Grid(400.0, 700.0, 10.0)
    il, sens, _ = on_integration_grid(
        cal.correct_illuminants(illum), cal.sensitivity, grid
    )
    prior = bent_bench["sg"].resample(grid)
    truth = lab_d50(bent_bench["tests"].resample(grid))
    de = {
        name: float(
            np.mean(
                delta_e_2000(
                    wiener_with_uncertainty(r, il, sens, prior, illum, cal)[1].lab,
                    truth,
                )
            )
        )
        for name, r in (("linearised", cal.linearise(test)), ("as measured", test))
    }
    # 0.040 against 0.102 measured: every estimate has to undo what the chart's did
    assert de["linearised"] < de["as measured"] - 0.005, de


@pytest.mark.slow
def test_a_linear_sensor_is_left_as_measured(bent_bench) -> None:
    chart = replace(
        bent_bench["chart"], rgb=bent_bench["chart"].rgb ** (1 / 1.003)
    )  # the same draws, straight
    cal = estimate_camera_sensitivity(chart, bent_bench["illum"], bent_bench["sg"])
    assert cal.excess is not None and cal.excess.linearity_gamma == 0.0
    assert cal.linearise(chart) is chart


@pytest.mark.slow
@pytest.mark.parametrize("method", ["smooth", "pca"])
def test_the_papers_estimators_are_not_linearised(bent_bench, method) -> None:
    """Their misfit of percents leaves nothing to take a slight bend up: the
    sensor's ``signal^1.003`` is found (``fit_bend``) and kept as measured; a chart on
    a tone curve is refused, as with ``"bayes"``."""
    chart, illum, sg = bent_bench["chart"], bent_bench["illum"], bent_bench["sg"]
    cal = estimate_camera_sensitivity(chart, illum, sg, method=method)
    assert cal.excess is not None and cal.excess.linearity_gamma == 0.0
    found, se = cal.params["linearity_gamma_found"], cal.params["linearity_gamma_se"]
    assert 0.0015 <= found <= 0.0045 and se < 0.001, cal.params
    check_chart_linearity(cal.params)
    toned = replace(chart, rgb=np.maximum(chart.rgb, 1e-6) ** (1 / 1.2))
    cal = estimate_camera_sensitivity(toned, illum, sg, method=method)
    assert cal.excess is not None and cal.excess.linearity_gamma == 0.0
    assert -0.26 <= cal.params["linearity_gamma_found"] <= -0.17, cal.params
    with pytest.raises(Implausible, match=r"gamma -0\.2"):
        check_chart_linearity(cal.params)


def test_a_white_board_on_a_tone_curve_is_said() -> None:
    """The sample's board alone: under one LED one reflectance in every channel, so
    its channels tilt against Eq. 1 on a tone curve (``board_bend_warning``)."""
    grid = CALIBRATION_GRID
    truth = load_camera_database(grid)[DEFAULT_CAMERA]
    leds = scale_to_exposure(load_colorchecker_sg(grid), load_led_set(grid), truth)
    perfect = white_response(leds, truth)
    rng = np.random.default_rng(3)
    # the board 0.9, a 1 % misfit per channel (the curves, the readings)
    board = 0.9 * perfect * (1 + 0.01 * rng.standard_normal(perfect.shape))
    gamma, se = board_bend(board**1.003, perfect)  # a sensor's bend: found, not said
    assert abs(gamma - 0.003) < 3 * se and se < 0.003, (gamma, se)
    assert board_bend_warning(board**1.003, perfect) is None
    gamma, se = board_bend(board ** (1 / 1.2), perfect)
    assert -0.175 <= gamma <= -0.16 and se < 0.003, (gamma, se)
    said = board_bend_warning(board ** (1 / 1.2), perfect)
    assert said is not None and "gamma -0.16" in said, said
    # a board too dark under every light to tell anything: nothing to say
    assert board_bend_warning(board * 1e-3, perfect) is None
