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
from tunespec.core.spectra import Spectra
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


def test_each_target_gets_eq5_with_the_prior_scaled_to_it(system) -> None:
    """``with_target_priors``: Eq. 5 with ``alpha_p^2 K`` per target (the generic
    component ``sigma_p`` stays out of the estimate), its posterior variance, and
    with ``alpha = 1`` the shared-prior estimate itself."""
    from tunespec.core.target_prior import matern32
    from tunespec.core.wiener import TargetPriors, with_target_priors

    led, cam, sg, rgb = system
    rows = [3, 40, 77]
    resp = _responses(sg, led, rgb, rows)
    w = wiener_reflectance(resp, led, cam, sg, clip=False, noise_std=1e-3)
    F, K, mean = w.lighting, w.prior_covariance, w.prior_mean
    generic = matern32(sg.wavelength_nm, 40.0)
    alpha = np.array([1.0, 2.0, 0.5])
    priors = TargetPriors(alpha, np.full(3, 0.1), generic, 40.0, np.ones(3))
    out = with_target_priors(w, resp, priors)
    c = resp.rgb.reshape(3, -1)
    for p, a in enumerate(alpha):
        Kp = a**2 * K
        A = F @ Kp @ F.T + 1e-6 * np.eye(F.shape[0])
        want = mean + Kp @ F.T @ np.linalg.solve(A, c[p] - F @ mean)
        post = np.diag(Kp - Kp @ F.T @ np.linalg.solve(A, F @ Kp))
        assert np.allclose(out.reflectance.values[p], want, atol=1e-9)
        assert np.allclose(out.variance[p], np.maximum(post, 0.0), atol=1e-12)
    assert np.allclose(out.reflectance.values[0], w.reflectance.values[0], atol=1e-12)
    assert out.target_priors is priors and out.params["prior"] == "per target"


def test_a_target_beyond_the_chart_gets_a_wider_prior_and_a_better_colour(
    system,
) -> None:
    """Targets three times as far from the SG's mean as its patches (clipped to
    [0, 1]): the evidence gives them ``alpha`` about 2, the SG's own patches about
    1, and Eq. 5 with the scaled prior estimates the far ones' colour closer to the
    truth while the SG's stay as they were."""
    from tunespec.core.colorimetry import reflectance_stats
    from tunespec.core.target_prior import fit_target_priors
    from tunespec.core.wiener import with_target_priors

    led, cam, sg, rgb = system
    rng = np.random.default_rng(3)
    rows = np.arange(1, 140, 4)
    mean = sg.values.mean(0)
    far_values = np.clip(mean + 3.0 * (sg.values[rows] - mean), 0.0, 1.0)
    far = render_rgb(far_values, led.values, cam.values, led.step_nm)
    both = np.concatenate([rgb[rows], far])
    n_p, m = len(both), 3 * len(led.names)
    noise = 1e-3 * np.maximum(both, 1e-3)
    names = tuple(f"p{i}" for i in range(n_p))
    resp = Responses(names, led.names, both + noise * rng.standard_normal(both.shape))
    cov = np.zeros((n_p, m, m))
    cov[:, np.arange(m), np.arange(m)] = noise.reshape(n_p, m) ** 2
    w = wiener_reflectance(resp, led, cam, sg, noise_covariance=cov)
    priors = fit_target_priors(w, resp, resp.rgb.reshape(n_p, m), cov)
    k = len(rows)
    # measured: median alpha 1.02 (the SG's) and 2.05 (three times as far)
    assert np.median(priors.alpha[:k]) < 1.2 < 1.8 < np.median(priors.alpha[k:])
    out = with_target_priors(w, resp, priors)
    truth = Spectra(
        sg.wavelength_nm, np.concatenate([sg.values[rows], far_values]), names
    )

    def de00(e, part):
        est = Spectra(sg.wavelength_nm, e.reflectance.values[part], names[part])
        ref = Spectra(sg.wavelength_nm, truth.values[part], names[part])
        return reflectance_stats(est, ref).mean_delta_e00

    far_part, sg_part = slice(k, None), slice(0, k)
    # measured: far 0.075 -> 0.057, the SG's 0.018 -> 0.018
    assert de00(out, far_part) < 0.85 * de00(w, far_part)
    assert abs(de00(out, sg_part) - de00(w, sg_part)) < 0.002
