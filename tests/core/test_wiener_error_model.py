"""Eq. 5 with a whole response error covariance as ``K_e`` (issue 23): the estimate is
the linear minimum-variance one under the stated error model, saturated responses are
still removed, and errors a patch's responses share are weighted as shared."""

from __future__ import annotations

import numpy as np
import pytest

from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
from tunespec.core.errors import InputError
from tunespec.core.forward_model import render_rgb
from tunespec.core.responses import Responses
from tunespec.core.wiener import wiener_reflectance


@pytest.fixture(scope="module")
def system():
    led, cam, sg = load_led_set(), load_camera(), load_colorchecker_sg()
    rgb = render_rgb(sg.values, led.values, cam.values, led.step_nm)
    scale = 0.8 / rgb.max()
    return led.with_values(led.values * scale), cam, sg, rgb * scale


def _responses(sg, led, rgb, rows, **kw) -> Responses:
    return Responses(tuple(sg.names[i] for i in rows), led.names, rgb[rows], **kw)


def test_a_whole_covariance_gives_the_gls_wiener_estimate(system) -> None:
    led, cam, sg, rgb = system
    rows = [3, 40, 77]
    rng = np.random.default_rng(0)
    m = 3 * len(led.names)
    a = rng.standard_normal((len(rows), m, m)) * 1e-3
    cov = a @ a.transpose(0, 2, 1) + 1e-6 * np.eye(m)
    resp = _responses(sg, led, rgb, rows)
    w = wiener_reflectance(resp, led, cam, sg, clip=False, noise_covariance=cov)
    F, K, mean = w.lighting, w.prior_covariance, w.prior_mean
    c = resp.rgb.reshape(len(rows), m)
    for p in range(len(rows)):
        want = mean + K @ F.T @ np.linalg.solve(F @ K @ F.T + cov[p], c[p] - F @ mean)
        assert np.allclose(w.reflectance.values[p], want, atol=1e-9)
    assert w.params["noise"] == "covariance"
    assert np.allclose(w.noise_variance.reshape(len(rows), m), cov.diagonal(0, 1, 2))


def test_saturated_responses_are_removed_from_a_whole_covariance(system) -> None:
    led, cam, sg, rgb = system
    rows = [10, 11]
    m = 3 * len(led.names)
    cov = np.broadcast_to(1e-6 * np.eye(m) + 1e-7, (2, m, m))
    sat = np.zeros((2, len(led.names)))
    sat[:, 5] = 1.0
    bad = rgb[rows].copy()
    bad[:, 5] = 1.0  # clipped: what the saturated response reads
    resp = _responses(sg, led, rgb, rows, saturated=sat)
    resp = Responses(resp.patches, resp.illuminants, bad, saturated=sat)
    clean = _responses(sg, led, rgb, rows)
    w = wiener_reflectance(resp, led, cam, sg, noise_covariance=cov)
    ref = wiener_reflectance(clean, led, cam, sg, noise_covariance=cov)
    # the clipped LED carries no weight: close to the estimate with its true value
    assert np.max(np.abs(w.reflectance.values - ref.reflectance.values)) < 0.01
    with pytest.raises(InputError, match="noise covariance"):
        wiener_reflectance(clean, led, cam, sg, noise_covariance=cov[:, :-1])


def test_an_error_the_responses_share_is_weighted_as_shared(system) -> None:
    """An irradiance error of 2 % per patch and LED (what a flat-field residual
    does: all three channels under that LED at once) beside 0.1 % independent
    noise: stated as shared, the channels' ratios under each LED still count, and the
    estimate is far closer than with the same variance counted per response (a
    diagonal ``K_e`` such as Eq. 6's)."""
    led, cam, sg, rgb = system
    rng = np.random.default_rng(1)
    rows = np.arange(0, 140, 2)
    n_p, n_i = len(rows), len(led.names)
    m = 3 * n_i
    c = rgb[rows].reshape(n_p, m)
    per_led = np.repeat(0.02 * rng.standard_normal((n_p, n_i)), 3, axis=1)
    noisy = c * (1.0 + per_led) + 1e-3 * c * rng.standard_normal(c.shape)
    resp = Responses(
        tuple(sg.names[i] for i in rows), led.names, noisy.reshape(rgb[rows].shape)
    )
    idx = np.arange(m)
    block = np.kron(np.eye(n_i), np.ones((3, 3)))[None]
    whole = 0.02**2 * c[:, :, None] * c[:, None, :] * block
    whole[:, idx, idx] += (1e-3 * c) ** 2
    diagonal = np.zeros_like(whole)
    diagonal[:, idx, idx] = whole[:, idx, idx]
    err = {}
    for name, cov in (("whole", whole), ("diagonal", diagonal)):
        w = wiener_reflectance(resp, led, cam, sg, noise_covariance=cov)
        err[name] = float(
            np.sqrt(np.mean((w.reflectance.values - sg.values[rows]) ** 2))
        )
    # measured: whole 0.0039, diagonal 0.0095
    assert err["whole"] < 0.6 * err["diagonal"], err


def test_the_prior_term_is_widened_only_where_eq1_is_blind(system) -> None:
    from tunespec.core.uncertainty import BLIND_EDGE_SCALE, blind_edge_factor

    led, cam, sg, rgb = system
    w = wiener_reflectance(
        _responses(sg, led, rgb, [5, 6]), led, cam, sg, noise_std=1e-3
    )
    F = w.lighting.copy()
    F[:, 0] = 0.0  # a wavelength no LED and channel sees
    F[:, 1] = 0.05 * F[:, 30]  # one they barely see
    edge = blind_edge_factor(F, w.noise_variance.reshape(2, -1))
    assert np.allclose(edge[:, 0], 1.0 + BLIND_EDGE_SCALE)
    assert np.all(edge[:, 1] > 1.0)
    # where the LEDs see well (the middle of the spectrum) nothing changes
    assert np.all(edge[:, 20:40] == 1.0)
