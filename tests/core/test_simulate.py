"""The simulated capture: noise statistics match the noise model (seeded draws)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from tests.tolerances import ATOL_EXACT, RTOL_NOISE_STATS
from tunespec.core.datasets import (
    load_camera,
    load_colorchecker_sg,
    load_led_set,
)
from tunespec.core.errors import InputError
from tunespec.core.forward_model import render_rgb
from tunespec.core.simulate import (
    NoiseModel,
    perturb_spd,
    scale_to_exposure,
    simulate_capture,
    simulate_responses,
)
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra

WL = np.array([500.0, 510.0])
RGB = ("R", "G", "B")


def _flat_scene(
    level: float, n_patches: int, n_illuminants: int = 1
) -> tuple[Spectra, Spectra, Spectra]:
    """Identical grey patches whose noise-free response is ``level`` in every channel."""
    refl = Spectra(
        WL, np.full((n_patches, 2), 0.5), tuple(f"P{i}" for i in range(n_patches))
    )
    # 0.5 * p * 1 * 2 samples * 10 nm = level
    illum = Spectra(
        WL,
        np.full((n_illuminants, 2), level / 10.0),
        tuple(f"L{i}" for i in range(n_illuminants)),
    )
    sens = Spectra(WL, np.ones((3, 2)), RGB)
    return refl, illum, sens


def test_noise_free_responses_are_eq1() -> None:
    sg, leds, cam = load_colorchecker_sg(), load_led_set(), load_camera()
    leds = scale_to_exposure(sg, leds, cam)
    r = simulate_responses(sg, leds, cam, noise=None, rng=0)
    np.testing.assert_allclose(
        r.rgb, render_rgb(sg.values, leds.values, cam.values, 5.0), atol=ATOL_EXACT
    )
    assert r.rgb_std is None and not np.any(r.saturated)


def test_shot_and_read_noise_of_the_roi_mean_match_the_model() -> None:
    noise = NoiseModel(flat_field_residual=0.0)
    for level in (0.002, 0.05, 0.6):
        refl, illum, sens = _flat_scene(level, 4000)
        r = simulate_responses(refl, illum, sens, noise=noise, rng=1)
        err = r.rgb - level
        sigma_px = np.sqrt(level * 67_000 + 30**2) / 67_000
        expected = sigma_px / np.sqrt(400)
        np.testing.assert_allclose(err.std(), expected, rtol=RTOL_NOISE_STATS)
        assert abs(err.mean()) < 5 * expected / np.sqrt(err.size)
        # The reported per-pixel std scatters like a sample std over 400 pixels.
        np.testing.assert_allclose(r.rgb_std.mean(), sigma_px, rtol=RTOL_NOISE_STATS)
        np.testing.assert_allclose(
            r.rgb_std.std() / sigma_px,
            1 / np.sqrt(2 * 399),
            rtol=4 * RTOL_NOISE_STATS,  # a std of a std: 1/sqrt(2N) of 12 000 draws
        )
        np.testing.assert_array_equal(r.n_pixels, 400.0)
        assert not np.any(r.saturated)


def test_flat_field_residual_is_relative_and_shared_by_the_channels() -> None:
    # No photon or read noise to speak of: only the multiplicative residual.
    noise = NoiseModel(full_well_e=1e15, read_noise_e=0.0, flat_field_residual=0.003)
    refl, illum, sens = _flat_scene(0.5, 1000, n_illuminants=5)
    r = simulate_responses(refl, illum, sens, noise=noise, rng=2)
    rel = r.rgb / 0.5 - 1.0
    np.testing.assert_allclose(rel.std(), 0.003, rtol=RTOL_NOISE_STATS)
    # One draw per patch and illuminant, the same in R, G and B (up to the shot noise
    # of a 1e15 e- well, ~2e-9 relative).
    np.testing.assert_allclose(rel[..., 0], rel[..., 2], atol=1e-7)
    assert np.corrcoef(rel[:, 0, 0], rel[:, 1, 0])[0, 1] < 0.1  # independent LEDs
    # rgb_std knows nothing about the flat field (it is invisible inside one ROI).
    assert r.rgb_std.max() < 1e-6


def test_saturation_is_flagged_and_clipped() -> None:
    noise = NoiseModel(flat_field_residual=0.0)
    sigma_px = float(noise.pixel_std(np.array(1.0)))
    for level in (0.99, 1.0, 1.2):
        refl, illum, sens = _flat_scene(level, 2000)
        r = simulate_responses(refl, illum, sens, noise=noise, rng=3)
        assert np.all(r.rgb <= 1.0)
        # The expected clipped fraction is the normal tail above full scale (the mean
        # of 2000 binomial fractions scatters by < 0.002).
        p = norm.sf((1.0 - level) / sigma_px)
        np.testing.assert_allclose(r.saturated.mean(), p, atol=0.01)
    assert np.all(r.saturated > 0.99) and np.all(r.rgb == 1.0)
    # Mean at full scale: half of the pixels clip, the mean is E[min(X, 1)].
    refl, illum, sens = _flat_scene(1.0, 2000)
    r = simulate_responses(refl, illum, sens, noise=noise, rng=4)
    # (the ROI-mean noise averages out to ~1e-6 over 6000 values)
    np.testing.assert_allclose(
        r.rgb.mean(), 1.0 - sigma_px / np.sqrt(2 * np.pi), rtol=1e-4
    )
    np.testing.assert_allclose(r.saturated.mean(), 0.5, atol=0.01)
    # Noise-free: flagged wherever a channel reaches full scale.
    refl, illum, sens = _flat_scene(1.0, 1)
    assert simulate_responses(refl, illum, sens, noise=None, rng=0).saturated[0, 0] == 1


def test_simulation_is_reproducible_with_a_seed() -> None:
    refl, illum, sens = _flat_scene(0.3, 50, 3)
    a = simulate_responses(refl, illum, sens, rng=7)
    b = simulate_responses(refl, illum, sens, rng=np.random.default_rng(7))
    np.testing.assert_array_equal(a.rgb, b.rgb)
    c = simulate_responses(refl, illum, sens, rng=8)
    assert not np.array_equal(a.rgb, c.rgb)


def test_grids_must_match() -> None:
    refl, illum, sens = _flat_scene(0.3, 2)
    other = Spectra(
        np.array([500.0, 520.0]), illum.values, illum.names, {"source": "leds.csv"}
    )
    with pytest.raises(InputError, match=r"^leds\.csv: wavelength grids differ"):
        simulate_responses(refl, other, sens, rng=0)
    with pytest.raises(InputError, match="3 sensitivity curves"):
        simulate_responses(refl, illum, sens.select(["R", "G"]), rng=0)


def test_perturb_spd_shifts_and_scales() -> None:
    wl = np.arange(380.0, 731.0, 0.5)
    peaks = np.arange(420.0, 681.0, 20.0)
    leds = Spectra(
        wl,
        np.exp(-0.5 * ((wl[None, :] - peaks[:, None]) / 10.0) ** 2),
        tuple(f"L{p:g}" for p in peaks),
    )
    shifted = perturb_spd(leds, shift_nm=1.0, scale_sigma=0.0, rng=0)
    np.testing.assert_allclose(wl[np.argmax(shifted.values, axis=1)], peaks + 1.0)
    np.testing.assert_allclose(shifted.values.max(axis=1), 1.0, atol=ATOL_EXACT)
    many = Spectra(wl, np.ones((5000, wl.size)), tuple(f"x{i}" for i in range(5000)))
    scaled = perturb_spd(many, shift_nm=0.0, scale_sigma=0.01, rng=1)
    np.testing.assert_allclose(scaled.values[:, 0].std(), 0.01, rtol=RTOL_NOISE_STATS)
    assert scaled.names == many.names


def test_exposure_reaches_the_target_per_illuminant() -> None:
    sg, leds, cam = load_colorchecker_sg(), load_led_set(), load_camera()
    per_led = scale_to_exposure(sg, leds, cam, target=0.8)
    c = render_rgb(sg.values, per_led.values, cam.values, 5.0)
    np.testing.assert_allclose(c.max(axis=(0, 2)), 0.8, atol=ATOL_EXACT)
    common = scale_to_exposure(sg, leds, cam, target=0.5, per_illuminant=False)
    c = render_rgb(sg.values, common.values, cam.values, 5.0)
    assert c.max() == pytest.approx(0.5)
    assert c.max(axis=(0, 2)).min() < 0.05  # a dim LED stays dim
    with pytest.raises(InputError, match="target"):
        scale_to_exposure(sg, leds, cam, target=1.5)
    dark = leds.with_values(np.where(np.arange(22)[:, None] == 3, 0.0, leds.values))
    with pytest.raises(InputError, match="LED450"):
        scale_to_exposure(sg, dark, cam)


def test_simulate_capture_reports_on_the_working_grid() -> None:
    fine = Grid(380.0, 730.0, 1.0)
    sg, leds, cam = (
        load_colorchecker_sg(fine),
        load_led_set(fine),
        load_camera(grid=fine),
    )
    responses, reported = simulate_capture(sg, leds, cam, grid=DEFAULT_GRID, rng=0)
    assert responses.rgb.shape == (140, 22, 3)
    assert reported.wavelength_nm.size == DEFAULT_GRID.n
    assert reported.names == leds.names
    assert 0.7 < responses.rgb.max() < 0.9 and not np.any(responses.saturated)


def test_noise_model_validates() -> None:
    with pytest.raises(InputError):
        NoiseModel(full_well_e=0.0)
    with pytest.raises(InputError):
        NoiseModel(n_pixels=1)
    assert NoiseModel().mean_std(np.array(0.0)) == pytest.approx(30 / 67_000 / 20)


def test_a_black_patch_without_read_noise_is_exactly_dark() -> None:
    # sigma_px = 0 there: no divide-by-zero warning (an error under filterwarnings),
    # no NaN, no noise, no saturation.
    refl, illum, sens = _flat_scene(0.4, 2)
    refl = refl.with_values([[0.0, 0.0], [0.5, 0.5]])
    noise = NoiseModel(read_noise_e=0.0, flat_field_residual=0.0)
    r = simulate_responses(refl, illum, sens, noise=noise, rng=0)
    np.testing.assert_array_equal(r.rgb[0], 0.0)
    np.testing.assert_array_equal(r.rgb_std[0], 0.0)
    assert r.saturated[0, 0] == 0.0
    assert np.all(r.rgb_std[1] > 0)  # the lit patch keeps its shot noise


def test_exposure_needs_rgb_sensitivities() -> None:
    refl, illum, _ = _flat_scene(0.3, 2)
    two = Spectra(WL, np.ones((2, 2)), ("R", "G"), {"source": "sens.csv"})
    with pytest.raises(InputError, match=r"^sens\.csv: expected 3 sensitivity curves"):
        scale_to_exposure(refl, illum, two)
