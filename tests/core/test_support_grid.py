"""The reflectance is solved for wherever Eq. 1 integrates and reported on the grid
asked for (``core.wiener.support_grid``): light that a camera sees beyond a reported
range still enters its responses, and a surface need not stay at its end value
there."""

from __future__ import annotations

import numpy as np
import pytest

from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
from tunespec.core.errors import InputError
from tunespec.core.forward_model import render_rgb
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid
from tunespec.core.uncertainty import wiener_with_uncertainty
from tunespec.core.wiener import support_grid

REPORT = Grid(400.0, 700.0, 10.0)


@pytest.fixture(scope="module")
def red_edge():
    """The shipped LEDs (the deepest red has half its light past 700 nm), a camera
    whose red channel reaches past 700 nm (8 % of its area), and 40 SG patches given
    a foliage-like rise at 712 nm."""
    led, cam, sg = load_led_set(), load_camera(), load_colorchecker_sg()
    wl = led.wavelength_nm
    tail = np.exp(-0.5 * ((wl - 705.0) / 15.0) ** 2) * cam.values.max(axis=1)[0]
    cam = cam.with_values(cam.values + np.outer([0.4, 0.1, 0.0], tail))
    rng = np.random.default_rng(0)
    base = sg.values[rng.choice(len(sg), 40)]
    edge = 1.0 / (1.0 + np.exp(-(wl - 712.0) / 6.0))
    at_700 = base[:, [int(np.searchsorted(wl, 700.0))]]
    truth = base * (1.0 - edge) + np.clip(at_700 + 0.5, 0.0, 0.95) * edge
    rgb = render_rgb(truth, led.values, cam.values, led.step_nm)
    scale = 0.8 / rgb.max()
    led = led.with_values(led.values * scale)
    resp = Responses(tuple(f"p{i}" for i in range(len(truth))), led.names, rgb * scale)
    reported = (wl >= 400.0) & (wl <= 700.0) & (np.round(wl) % 10 == 0)
    return led, cam, sg, resp, truth[:, reported]


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def test_light_past_the_reported_range_is_solved_for(red_edge) -> None:
    led, cam, sg, resp, truth = red_edge
    held, _ = wiener_with_uncertainty(
        resp, led, cam, sg.resample(REPORT), led, None, noise_std=1e-4
    )
    solved, _ = wiener_with_uncertainty(
        resp, led, cam, sg, led, None, noise_std=1e-4, grid=REPORT
    )
    assert np.allclose(solved.reflectance.wavelength_nm, REPORT.wavelength_nm)
    assert solved.support is not None
    assert solved.support.reflectance.grid == Grid(380.0, 730.0, 10.0)
    # measured: 0.0139 -> 0.0093 over 400-700 nm, 0.031 -> 0.020 at 650-700 nm
    err_held = held.reflectance.values - truth
    err_solved = solved.reflectance.values - truth
    assert _rms(err_solved) < 0.75 * _rms(err_held), (_rms(err_solved), _rms(err_held))
    assert _rms(err_solved[:, -6:]) < 0.75 * _rms(err_held[:, -6:])


def test_a_restricted_estimate_is_the_wider_one_on_its_samples(red_edge) -> None:
    led, cam, sg, resp, _ = red_edge
    w, _ = wiener_with_uncertainty(
        resp, led, cam, sg, led, None, noise_std=1e-4, grid=REPORT
    )
    whole = w.support
    keep = np.isin(whole.reflectance.wavelength_nm, REPORT.wavelength_nm)
    assert np.array_equal(w.reflectance.values, whole.reflectance.values[:, keep])
    assert np.array_equal(w.variance, whole.variance[:, keep])
    assert w.lighting.shape == (66, REPORT.n)
    assert w.prior_covariance.shape == (REPORT.n, REPORT.n)
    assert whole.restricted(whole.reflectance.grid) is whole
    # the clipping report counts the reported samples at 0 or 1
    at_bounds = (w.reflectance.values <= 0.0) | (w.reflectance.values >= 1.0)
    assert w.n_clipped_samples == int(at_bounds.sum())
    with pytest.raises(InputError, match="not among the estimate's"):
        whole.restricted(Grid(401.0, 701.0, 10.0))


def test_the_support_stays_where_the_prior_and_eq1_reach() -> None:
    fine = np.arange(380.0, 731.0, 2.0)
    sg_nm = np.arange(380.0, 731.0, 10.0)
    assert support_grid(REPORT, fine, sg_nm) == Grid(380.0, 730.0, 10.0)
    # the prior stops at the reported range: nothing beyond it to solve for
    assert support_grid(REPORT, fine, np.arange(400.0, 701.0, 5.0)) == REPORT
    # whole steps of the reported grid only
    assert support_grid(Grid(405.0, 695.0, 10.0), fine, sg_nm) == Grid(
        385.0, 725.0, 10.0
    )
    assert support_grid(
        Grid(400.0, 700.0, 5.0), np.arange(390.0, 711.0, 2.0), sg_nm
    ) == (Grid(390.0, 710.0, 5.0))
