"""The excess-variance model of a calibration's residuals (issue 23): each systematic
effect is found by its own term, the flat-field residual among them."""

from __future__ import annotations

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.excess import (
    FLAT_FIELD_RESIDUAL,
    ExcessVariance,
    fit_excess_variance,
    led_blocks,
    log_profile,
    other_channels,
)

N_P, N_I = 140, 22


def _chart(seed: int) -> tuple[np.random.Generator, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    c = rng.uniform(0.05, 0.8, (N_P, 3 * N_I))
    c[:, 2::9] *= 1e-3  # channels that barely see some LEDs
    return rng, c, (1e-3 * c) ** 2 + 1e-10


def test_cross_talk_is_not_taken_for_a_relative_error() -> None:
    rng, c, v = _chart(1)
    e = 0.002 * other_channels(c) * rng.standard_normal(c.shape)
    fit = fit_excess_variance(c + e + np.sqrt(v) * rng.standard_normal(c.shape), c, v)
    assert 0.0015 <= fit.crosstalk_relative <= 0.0026, fit
    assert fit.response_relative <= 3e-4 and fit.common_relative <= 3e-4, fit


@pytest.mark.parametrize("residual", [0.001, 0.003, 0.01])
def test_the_flat_field_residual_is_fitted_not_assumed(residual: float) -> None:
    """One irradiance error per patch and LED, shared by its channels, is found at the
    size it has (a lab's flat field is not always the nominal 0.3 %), and not taken
    for a relative error, stray light or a shared gain."""
    rng, c, v = _chart(2)
    ff = residual * np.repeat(rng.standard_normal((N_P, N_I)), 3, axis=1)
    measured = c * (1 + ff) + np.sqrt(v) * rng.standard_normal(c.shape)
    fit = fit_excess_variance(measured, c, v)
    assert 0.85 * residual <= fit.flat_field_relative <= 1.15 * residual, fit
    assert max(fit.level_relative, fit.common_relative, fit.response_relative) <= (
        0.15 * residual
    ), fit


def test_stray_light_and_a_non_linearity_are_found() -> None:
    rng, c, v = _chart(3)
    level = c.mean(axis=0)
    stray = 0.002 * np.repeat(rng.standard_normal((N_P, N_I)), 3, axis=1) * level
    measured = c**1.003 + stray + np.sqrt(v) * rng.standard_normal(c.shape)
    fit = fit_excess_variance(measured, c, v)
    assert 0.0015 <= fit.level_relative <= 0.0026, fit
    # the gain part of c^1.003 is not removed here: the whole log profile is seen
    assert 0.002 <= fit.nonlinearity <= 0.004, fit
    assert fit.log_reference < 0


def test_covariance_has_the_model_s_structure() -> None:
    ex = ExcessVariance(0.001, 0.002, level_relative=0.003, crosstalk_relative=0.004,
                        nonlinearity=0.005, log_reference=-1.0)  # fmt: skip
    rgb = np.array([[0.2, 0.4, 0.6, 0.1, 0.3, 0.5]])
    cov = ex.covariance(rgb, level=np.full(6, 0.5))
    u = log_profile(rgb, -1.0)[0]
    expect = 0.002**2 * np.outer(rgb[0], rgb[0]) + 0.005**2 * np.outer(u, u)
    expect += 0.003**2 * led_blocks(np.full((1, 6), 0.5))[0]
    expect += np.diag((0.001 * rgb[0]) ** 2 + (0.004 * other_channels(rgb)[0]) ** 2)
    assert np.allclose(cov[0], expect)
    assert cov[0, 0, 3] == pytest.approx(expect[0, 3]) and cov[0, 0, 1] > cov[0, 0, 3]


def test_side_file_round_trip_old_files_and_bad_values() -> None:
    ex = ExcessVariance(0.001, 0.002, 140, 9240, 0.003, 0.004, 0.005, -1.7)
    assert ExcessVariance.from_dict(ex.as_dict()) == ex
    old = {"response_relative": 0.001, "level_relative": 0.0, "common_relative": 0.002}
    assert ExcessVariance.from_dict(old).nonlinearity == 0.0
    # written before the flat field was fitted: the residual it assumed
    assert ExcessVariance.from_dict(old).flat_field_relative == FLAT_FIELD_RESIDUAL
    for bad in ({"nonlinearity": -0.1}, {"log_reference": 1e9},
                {"crosstalk_relative": True}, {"log_reference": "x"}):  # fmt: skip
        with pytest.raises(InputError, match="excess_variance"):
            ExcessVariance.from_dict(bad, path="S.csv.meta.json")


def test_a_non_linearity_whose_gains_the_calibration_absorbed_is_found() -> None:
    """The per-LED gains and the sensitivities take each LED and channel's mean part
    of ``c^1.003``; what is left is found about each one's own mean log response."""
    rng, c, v = _chart(4)
    measured = c**1.003
    gain = np.exp(np.mean(np.log(measured / c), axis=0))  # absorbed per column
    measured = measured / gain + np.sqrt(v) * rng.standard_normal(c.shape)
    fit = fit_excess_variance(measured, c, v)
    assert 0.0022 <= fit.nonlinearity <= 0.0038, fit
    assert fit.common_relative <= 5e-4, fit
    assert len(fit.log_reference_by_response) == c.shape[1]
    cov = fit.covariance(c[:1])
    own = ExcessVariance(0.0, 0.0, nonlinearity=fit.nonlinearity,
                         log_reference=fit.log_reference)  # fmt: skip
    assert not np.allclose(cov, own.covariance(c[:1]))  # the per-column means count
