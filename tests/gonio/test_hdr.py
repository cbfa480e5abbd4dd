"""HDR merging (core.hdr) against the truth it was simulated from."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
from tunespec.core.errors import InputError
from tunespec.core.forward_model import render_rgb
from tunespec.core.hdr import fit_bracket_bend, hdr_patch_responses, merge_brackets
from tunespec.core.plausibility import bracket_bend_warning
from tunespec.core.responses import Responses
from tunespec.core.simulate import NoiseModel
from tunespec.core.wiener import SATURATED_VARIANCE, wiener_reflectance

NOISE = NoiseModel(full_well_e=67_000.0, read_noise_e=30.0)


def _expose(x, t, rng, noise=NOISE, clip=1.0):
    """Photon (Poisson) + read noise of a linear sensor, clipped at full scale."""
    g = noise.full_well_e
    electrons = rng.poisson(np.maximum(x * t, 0) * g).astype(float)
    c = (electrons + noise.read_noise_e * rng.standard_normal(x.shape)) / g
    return np.minimum(c, clip)


def test_merge_is_unbiased_and_its_variance_is_right():
    rng = np.random.default_rng(0)
    x = np.geomspace(2e-3, 40.0, 60)  # 4.3 decades at the reference exposure
    t = [1.0, 1 / 8, 1 / 64]
    reps = 4000
    frames = np.stack([_expose(np.tile(x, (reps, 1)), tk, rng) for tk in t])
    hdr = merge_brackets(frames, t, noise=NOISE)
    assert not hdr.saturated.any()
    z = (hdr.value - x) / hdr.std
    # unbiased: |mean z| within 4 standard errors; calibrated: std(z) = 1 +- 5 %
    assert np.all(np.abs(z.mean(axis=0)) < 4 / np.sqrt(reps) + 0.03)
    assert np.all(np.abs(z.std(axis=0) - 1) < 0.05)
    # relative error at the reference exposure's noise floor, and below it where
    # several brackets overlap (noise weighting beats picking one bracket)
    single = np.where(x < 0.98, x, np.nan)
    one = np.sqrt(
        single / NOISE.full_well_e + (NOISE.read_noise_e / NOISE.full_well_e) ** 2
    )
    both = ~np.isnan(single)
    assert np.all(hdr.std.mean(axis=0)[both] <= one[both] * 1.001)
    assert hdr.n_used.max() == 3 and hdr.n_used.min() == 1


def test_pixels_clipped_everywhere_are_flagged():
    frames = np.array([[1.0, 0.5], [1.0, 0.0625]])
    hdr = merge_brackets(frames, [1.0, 0.125], saturation=0.98)
    assert hdr.saturated.tolist() == [True, False]
    assert hdr.value[0] == pytest.approx(0.98 / 0.125)  # a lower bound
    assert np.isinf(hdr.variance[0])
    assert hdr.value[1] == pytest.approx(0.5, rel=1e-9)


def test_one_bracket_is_the_frame_with_the_model_noise():
    c = np.array([0.01, 0.2, 0.7])
    hdr = merge_brackets(c[None], [1.0], noise=NOISE)
    np.testing.assert_allclose(hdr.value, c)
    np.testing.assert_allclose(hdr.std, NOISE.pixel_std(c), rtol=1e-12)


def test_bad_brackets_give_one_line():
    with pytest.raises(InputError, match="one relative exposure per bracket"):
        merge_brackets(np.zeros((2, 3)), [1.0])
    with pytest.raises(InputError, match="positive"):
        merge_brackets(np.zeros((1, 3)), [0.0])
    with pytest.raises(InputError, match="finite"):
        merge_brackets(np.full((1, 3), np.nan), [1.0])


def _bracketed(tone: float, seed: int = 0):
    """Brackets of a noisy linear sensor's scene (0.2 % to 3x full scale at the
    reference exposure), then a tone ``c^tone`` on them."""
    rng = np.random.default_rng(seed)
    x = np.geomspace(2e-3, 3.0, 4000)
    t = [1.0, 1 / 8, 1 / 64]
    frames = np.stack([_expose(x, tk, rng) for tk in t])
    return np.sign(frames) * np.abs(frames) ** tone, t


def test_bracket_bend_is_zero_on_a_linear_sensor_and_found_on_a_tone_curve():
    gamma, se = fit_bracket_bend(*_bracketed(1.0), noise=NOISE)
    # clipped and noisy brackets left out, so nothing is read as a bend
    assert abs(gamma) < 3 * se + 0.002 and se < 0.003
    assert bracket_bend_warning(gamma, se) is None
    for tone in (1 / 1.2, 1.1, 1 / 1.05):
        gamma, se = fit_bracket_bend(*_bracketed(tone), noise=NOISE)
        assert gamma == pytest.approx(tone - 1, abs=0.004)
    said = bracket_bend_warning(*fit_bracket_bend(*_bracketed(1.1), noise=NOISE))
    assert said is not None and "tone curve" in said
    assert re.search(r"gamma \+0\.(09[6-9]|10[0-4]) \+- ", said)
    # a tone a chart would pass (a bend under 0.05) is said by the brackets
    assert bracket_bend_warning(*fit_bracket_bend(*_bracketed(1 / 1.05), noise=NOISE))
    # a bend under the brackets' limit, or not told from noise, is not
    assert bracket_bend_warning(0.015, 0.0001) is None
    assert bracket_bend_warning(0.1, 0.04) is None


def test_bracket_bend_needs_two_usable_brackets():
    # one bracket, or every pixel clipped or lost in the noise in all but one
    assert fit_bracket_bend(np.full((1, 5), 0.5), [1.0]) == (0.0, float("inf"))
    frames = np.array([[0.99, 0.99], [0.5, 1e-6]])
    assert fit_bracket_bend(frames, [1.0, 0.5]) == (0.0, float("inf"))
    with pytest.raises(InputError, match="one relative exposure per bracket"):
        fit_bracket_bend(np.zeros((2, 3)), [1.0])


def test_hdr_responses_carry_into_eq6():
    """A glossy target 20x over full scale: HDR recovers the reflectances."""
    rng = np.random.default_rng(1)
    cam, leds, sg = load_camera(), load_led_set(), load_colorchecker_sg()
    sub = sg.select(sg.names[:30])
    leds6 = leds.select(leds.names[::4])
    clean = render_rgb(sub.values, leds6.values, cam.values, 5.0)
    scale = 0.8 / clean.max(axis=(0, 2))  # the brightest patch at 0.8 per LED
    gloss = np.where(np.arange(30) % 3 == 0, 20.0, 1.0)  # every third patch glints
    x = clean * scale[None, :, None] * gloss[:, None, None]
    t = [1.0, 1 / 4, 1 / 32]
    n_px = 64
    merged = []
    for p in range(30):
        row = []
        for i in range(len(leds6.names)):
            xi = np.repeat(x[p, i][:, None], n_px, axis=1)
            frames = np.stack([_expose(xi, tk, rng) for tk in t])
            row.append(merge_brackets(frames, t, noise=NOISE))
        merged.append(row)
    resp = hdr_patch_responses(merged, sub.names, leds6.names)
    assert resp.saturated.max() == 0.0  # nothing clipped in every bracket
    assert resp.rgb.max() > 5.0  # well beyond one exposure's range
    # each ROI mean within 5 of its own standard errors of the truth
    assert np.all(np.abs(resp.rgb - x) < 5 * resp.rgb_std / np.sqrt(n_px))
    # Eq. 6 takes the merged per-pixel noise as it is
    illum = leds6.with_values(leds6.values * scale[:, None])
    truth = sub.with_values(sub.values * gloss[:, None])
    est = wiener_reflectance(resp, illum, cam, truth, center_prior=True, clip=False)
    np.testing.assert_allclose(
        est.noise_variance, np.maximum(resp.rgb_std**2, est.ridge)
    )
    # and estimates what the noise-free responses give, to the merged noise
    clean = wiener_reflectance(
        Responses(sub.names, leds6.names, x),
        illum,
        cam,
        truth,
        noise_std=1e-5,
        clip=False,
    )
    diff = np.abs(est.reflectance.values - clean.reflectance.values)
    rel = diff.mean(axis=1) / truth.values.mean(axis=1)
    # the glinting patches (up to 20x over full scale): measured median 0.8 %, max 7 %
    assert np.median(rel[gloss > 1]) < 0.01
    assert rel[gloss > 1].max() < 0.1
    # without HDR, the glinting patches clip at the reference exposure and Eq. 6
    # drops those responses (the saturated variance)
    one = hdr_patch_responses(
        [[merge_brackets(np.stack([_expose(np.repeat(x[p, i][:, None], n_px, 1), 1.0, rng)]), [1.0], noise=NOISE)
          for i in range(len(leds6.names))] for p in range(30)],
        sub.names, leds6.names,
    )  # fmt: skip
    assert (one.saturated[gloss > 1] > 0).mean() > 0.7
    est1 = wiener_reflectance(one, illum, cam, truth, clip=False)
    assert np.all(est1.noise_variance[one.saturated > 0] == SATURATED_VARIANCE)
