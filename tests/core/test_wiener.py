"""Wiener reflectance estimation (Eq. 5) with patch-wise noise covariance (Eq. 6)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tolerances import ATOL_EXACT, ATOL_WIENER_LOOP
from tunespec.core import wiener
from tunespec.core.colorimetry import reflectance_stats
from tunespec.core.datasets import (
    load_camera,
    load_colorchecker_sg,
    load_led_set,
    load_training_reflectances_190,
)
from tunespec.core.errors import InputError, SingularSystemError
from tunespec.core.forward_model import lighting_matrix, render_rgb
from tunespec.core.responses import Responses
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra
from tunespec.core.wiener import WienerEstimate, wiener_reflectance


@pytest.fixture(scope="module")
def bench() -> dict[str, Spectra]:
    """5D Mark III + the 22-LED set on DEFAULT_GRID, LEDs scaled like exposures.

    Each LED is scaled so that a perfect white gives 0.9 full scale in its strongest
    channel, as the capture's exposure control would.
    """
    led = load_led_set(DEFAULT_GRID)
    cam = load_camera("Canon EOS 5D Mark III", DEFAULT_GRID)
    white = render_rgb(np.ones((1, DEFAULT_GRID.n)), led.values, cam.values, 5.0)
    illum = led.with_values(0.9 * led.values / white[0].max(axis=1)[:, None])
    return {
        "illum": illum,
        "cam": cam,
        "sg": load_colorchecker_sg(DEFAULT_GRID),
        "t190": load_training_reflectances_190(DEFAULT_GRID),
    }


def _responses(bench: dict[str, Spectra], refl: Spectra, **kw: object) -> Responses:
    rgb = render_rgb(refl.values, bench["illum"].values, bench["cam"].values, 5.0)
    return Responses(refl.names, bench["illum"].names, rgb, **kw)  # type: ignore[arg-type]


def _wiener_loop(
    rgb: np.ndarray,
    noise_var: np.ndarray,
    F: np.ndarray,
    prior: np.ndarray,
    center: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Reference: Eq. 5 one patch at a time, posterior covariance written out."""
    if center:
        m, K = prior.mean(0), np.cov(prior, rowvar=False)
    else:
        m, K = np.zeros(prior.shape[1]), prior.T @ prior / len(prior)
    est, var = [], []
    for c, s2 in zip(
        rgb.reshape(len(rgb), -1), noise_var.reshape(len(rgb), -1), strict=True
    ):
        A = F @ K @ F.T + np.diag(s2)
        est.append(m + K @ F.T @ np.linalg.solve(A, c - F @ m))
        var.append(np.diag(K - K @ F.T @ np.linalg.solve(A, F @ K)))
    return np.array(est), np.array(var)


def test_closed_loop_noise_free_recovers_reflectances(bench) -> None:
    # Noise-free responses: K_e = 0, so only the documented ridge floor regularises.
    sg, t190 = bench["sg"], bench["t190"]
    est_sg = wiener_reflectance(
        _responses(bench, sg), bench["illum"], bench["cam"], sg, noise_std=0.0
    )
    assert est_sg.ridge > 0 and est_sg.params["n_ridged"] == sg.values.size // 71 * 66
    s_sg = reflectance_stats(est_sg.reflectance, sg)
    # Measured: mean 0.0011, max 0.0051 dE00; RMS mean 0.0005, max 0.0026.
    assert s_sg.max_delta_e00 < 0.02 and s_sg.max_spectral_rms < 0.005

    # The 190-patch set is independent of the SG prior.
    est = wiener_reflectance(
        _responses(bench, t190), bench["illum"], bench["cam"], sg, noise_std=0.0
    )
    s = reflectance_stats(est.reflectance, t190)
    # Measured: mean 0.0049, max 0.023 dE00; RMS mean 0.0115, max 0.080.
    assert s.mean_delta_e00 < 0.02 and s.max_delta_e00 < 0.1
    assert s.mean_spectral_rms < 0.02 and s.max_spectral_rms < 0.12


def test_closed_loop_with_a_realistic_noise_level(bench) -> None:
    t190 = bench["t190"]
    est = wiener_reflectance(
        _responses(bench, t190), bench["illum"], bench["cam"], None, noise_std=1e-3
    )
    assert est.params["n_prior"] == 140  # the default prior is the SG
    s = reflectance_stats(est.reflectance, t190)
    # Measured: mean 0.033, max 0.36 dE00; RMS mean 0.024.
    assert s.mean_delta_e00 < 0.1 and s.max_delta_e00 < 1.0
    assert s.mean_spectral_rms < 0.035


def test_patchwise_noise_beats_a_global_level_on_heteroscedastic_data(bench) -> None:
    # Eq. 6: each patch has its own noise level (log-uniform over 2.5 decades) and
    # rgb_std reports it. Wiener minimises the expected squared spectral error, so
    # that is the measure; the single-level competitors include the RMS noise level
    # and a grid around it.
    sg = bench["sg"]
    clean = _responses(bench, sg).rgb
    mse_patch, mse_global = [], []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        std = 10 ** rng.uniform(-4, -1.5, (len(sg), 1, 1)) * np.ones_like(clean)
        resp = Responses(
            sg.names,
            bench["illum"].names,
            clean + rng.normal(size=clean.shape) * std,
            std,
        )
        args = (resp, bench["illum"], bench["cam"], sg)
        err = wiener_reflectance(*args).reflectance.values - sg.values
        mse_patch.append(np.mean(err**2))
        levels = [np.sqrt(np.mean(std**2)), *np.geomspace(3e-4, 3e-2, 5)]
        mse_global.append(
            [
                np.mean(
                    (
                        wiener_reflectance(*args, noise_std=g).reflectance.values
                        - sg.values
                    )
                    ** 2
                )
                for g in levels
            ]
        )
    best_global = np.min(np.mean(mse_global, axis=0))
    # Measured: patch-wise 9.3e-5, best single level 1.38e-4 (ratio 0.67).
    assert np.mean(mse_patch) < 0.75 * best_global


def test_vectorised_equals_per_patch_loop(bench) -> None:
    sg = bench["sg"]
    rng = np.random.default_rng(1)
    pick = sg.select(sg.names[::7])
    base = _responses(bench, pick)
    std = rng.uniform(1e-4, 1e-2, base.rgb.shape)
    resp = Responses(base.patches, base.illuminants, base.rgb + 0.3 * std, std)
    F = lighting_matrix(bench["illum"].values, bench["cam"].values, 5.0)
    for center in (True, False):
        est = wiener_reflectance(
            resp, bench["illum"], bench["cam"], sg, center_prior=center, clip=False
        )
        ref, var = _wiener_loop(resp.rgb, std**2, F, sg.values, center)
        np.testing.assert_allclose(
            est.reflectance.values, ref, rtol=0, atol=ATOL_WIENER_LOOP
        )
        np.testing.assert_allclose(est.variance, var, rtol=0, atol=ATOL_WIENER_LOOP)
        np.testing.assert_array_equal(est.noise_variance, std**2)


def test_chunked_solve_equals_one_batch(bench, monkeypatch) -> None:
    resp = _responses(bench, bench["sg"])
    args = (resp, bench["illum"], bench["cam"], bench["sg"])
    whole = wiener_reflectance(*args, noise_std=1e-3)
    monkeypatch.setattr(wiener, "_CHUNK", 7)
    parts = wiener_reflectance(*args, noise_std=1e-3)
    np.testing.assert_allclose(
        parts.reflectance.values, whole.reflectance.values, rtol=0, atol=ATOL_EXACT
    )


def test_noise_from_mean_divides_by_n_pixels(bench) -> None:
    sg = bench["sg"].select(["A1", "E5", "J7"])
    base = _responses(bench, sg)
    rng = np.random.default_rng(2)
    std = rng.uniform(1e-3, 2e-2, base.rgb.shape)
    n_pix = rng.integers(50, 500, base.rgb.shape[:2]).astype(float)
    resp = Responses(base.patches, base.illuminants, base.rgb, std, n_pix)
    by_mean = wiener_reflectance(
        resp, bench["illum"], bench["cam"], bench["sg"], noise_from="mean"
    )
    scaled = Responses(
        base.patches, base.illuminants, base.rgb, std / np.sqrt(n_pix[..., None])
    )
    by_pixel = wiener_reflectance(scaled, bench["illum"], bench["cam"], bench["sg"])
    np.testing.assert_allclose(
        by_mean.reflectance.values, by_pixel.reflectance.values, rtol=0, atol=ATOL_EXACT
    )
    assert by_mean.params["noise_from"] == "mean" and by_mean.params["noise"] == "patch"


def test_illuminant_order_and_subsets_follow_the_responses(bench) -> None:
    sg = bench["sg"].select(["B3", "H8"])
    resp = _responses(bench, sg)
    illum = bench["illum"]
    shuffled = illum.select(illum.names[::-1])
    a = wiener_reflectance(resp, illum, bench["cam"], bench["sg"], noise_std=1e-3)
    b = wiener_reflectance(resp, shuffled, bench["cam"], bench["sg"], noise_std=1e-3)
    np.testing.assert_allclose(
        a.reflectance.values, b.reflectance.values, rtol=0, atol=ATOL_EXACT
    )
    sub = resp.subset(illuminants=list(illum.names[:10]))
    c = wiener_reflectance(sub, illum, bench["cam"], bench["sg"], noise_std=1e-3)
    assert c.noise_variance.shape == (2, 10, 3)
    assert c.reflectance.names == ("B3", "H8")


def test_posterior_variance_shrinks_with_less_noise(bench) -> None:
    resp = _responses(bench, bench["sg"].select(["D4"]))
    args = (resp, bench["illum"], bench["cam"], bench["sg"])
    prior_var = np.var(bench["sg"].values, axis=0, ddof=1)
    noisy = wiener_reflectance(*args, noise_std=1e-2)
    quiet = wiener_reflectance(*args, noise_std=1e-4)
    assert np.all(noisy.variance <= prior_var + ATOL_EXACT)
    assert np.all(quiet.variance <= noisy.variance + ATOL_EXACT)
    assert quiet.std.mean() < 0.5 * noisy.std.mean()


def test_clipping_is_reported(bench) -> None:
    wl = DEFAULT_GRID.wavelength_nm
    refl = Spectra(
        wl,
        np.stack([np.full(wl.size, 1.08), bench["sg"]["E5"]]),  # fluorescent-like white
        ("bright", "grey"),
    )
    resp = _responses(bench, refl)
    args = (resp, bench["illum"], bench["cam"], bench["sg"])
    est = wiener_reflectance(*args, noise_std=1e-4)
    assert isinstance(est, WienerEstimate)
    assert est.clipped == ("bright",)
    assert est.n_clipped_samples > 0
    assert est.reflectance.values.max() == 1.0
    raw = wiener_reflectance(*args, noise_std=1e-4, clip=False)
    assert raw.clipped == () and raw.n_clipped_samples == 0
    assert raw.reflectance.values.max() > 1.0
    np.testing.assert_array_equal(
        np.clip(raw.reflectance.values, 0, 1), est.reflectance.values
    )
    assert est.n_clipped_samples == np.count_nonzero(raw.reflectance.values > 1.0)


def test_input_errors_name_the_source(bench) -> None:
    sg = bench["sg"].select(["A1"])
    resp = _responses(bench, sg)
    illum, cam = bench["illum"], bench["cam"]
    prior = bench["sg"]
    with pytest.raises(
        InputError, match=r"cal1_model_22.csv: illuminant spectra: 1 name"
    ):
        wiener_reflectance(
            resp, illum.select(illum.names[1:]), cam, prior, noise_std=0.01
        )
    with pytest.raises(InputError, match=r"Mark_III.*camera sensitivity: 1 name.*: B"):
        wiener_reflectance(resp, illum, cam.select(["R", "G"]), prior, noise_std=0.01)
    narrow = Grid(400.0, 700.0, 5.0)
    with pytest.raises(
        InputError, match=r"colorchecker_sg.csv: prior .* 380-730 nm .* beyond"
    ):
        wiener_reflectance(
            resp, illum.resample(narrow), cam.resample(narrow), prior, noise_std=0.01
        )
    nan_illum = illum.with_values(
        np.where(np.arange(22)[:, None] == 3, np.nan, illum.values)
    )
    with pytest.raises(InputError, match="non-finite values in LED450"):
        wiener_reflectance(resp, nan_illum, cam, prior, noise_std=0.01)
    nan_rgb = Responses(
        resp.patches, resp.illuminants, np.where(resp.rgb > 0.5, np.nan, resp.rgb)
    )
    with pytest.raises(InputError, match="non-finite rgb for patch 'A1'"):
        wiener_reflectance(nan_rgb, illum, cam, prior, noise_std=0.01)
    with pytest.raises(InputError, match="no noise level"):
        wiener_reflectance(resp, illum, cam, prior)
    with pytest.raises(InputError, match="noise_std"):
        wiener_reflectance(resp, illum, cam, prior, noise_std=-1.0)
    with pytest.raises(InputError, match="noise_from"):
        wiener_reflectance(resp, illum, cam, prior, noise_std=0.01, noise_from="std")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="n_pixels"):
        wiener_reflectance(resp, illum, cam, prior, noise_std=0.01, noise_from="mean")
    neg = Responses(resp.patches, resp.illuminants, resp.rgb, -np.ones_like(resp.rgb))
    with pytest.raises(InputError, match="negative standard deviation"):
        wiener_reflectance(neg, illum, cam, prior)
    with pytest.raises(InputError, match="at least 2"):
        wiener_reflectance(resp, illum, cam, prior.select(["A1"]), noise_std=0.01)


def test_degenerate_systems_raise_singular(bench) -> None:
    sg = bench["sg"].select(["A1", "B2"])
    resp = _responses(bench, sg)
    illum, cam, prior = bench["illum"], bench["cam"], bench["sg"]
    dark = illum.with_values(np.zeros_like(illum.values))
    with pytest.raises(SingularSystemError, match="F K F"):
        wiener_reflectance(resp, dark, cam, prior, noise_std=0.0)
    blind = cam.with_values(np.zeros_like(cam.values))
    with pytest.raises(SingularSystemError):
        wiener_reflectance(resp, illum, blind, prior, noise_std=0.01)
    flat = prior.with_values(
        np.tile(prior.values[0], (5, 1)), [f"p{i}" for i in range(5)]
    )
    with pytest.raises(SingularSystemError, match="no variance"):
        wiener_reflectance(resp, illum, cam, flat, noise_std=0.0)
    # Exactly rank-deficient F K F^T (rank(K) = 36 < 66 rows) with zero noise is
    # solved through the ridge floor, not refused.
    est = wiener_reflectance(resp, illum, cam, prior, noise_std=0.0)
    assert np.isfinite(est.reflectance.values).all() and est.ridge > 0


def test_saturated_responses_are_ignored() -> None:
    """A clipped response must not pull the estimate (it would, with its tiny std)."""
    from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
    from tunespec.core.forward_model import render_rgb
    from tunespec.core.responses import Responses
    from tunespec.core.wiener import wiener_reflectance

    sg, leds, cam = load_colorchecker_sg(), load_led_set(), load_camera()
    patches = sg.select(["A1", "E5", "J7"])
    raw = render_rgb(patches.values, leds.values, cam.values, sg.step_nm)
    scale = 0.8 / raw.max()
    rgb = raw * scale
    std = np.full_like(rgb, 1e-3)
    clean = Responses(patches.names, leds.names, rgb, std)
    bad_rgb, bad_std = rgb.copy(), std.copy()
    sat = np.zeros(rgb.shape[:2])
    bad_rgb[:, 3] = 1.0  # LED450 clipped for every patch
    bad_std[:, 3] = 1e-6
    sat[:, 3] = 0.5
    sens = cam.with_values(cam.values * scale)
    ref = wiener_reflectance(clean, leds, sens, sg).reflectance.values
    est_ign = wiener_reflectance(
        Responses(patches.names, leds.names, bad_rgb, bad_std, None, sat),
        leds,
        sens,
        sg,
    ).reflectance.values
    est_raw = wiener_reflectance(
        Responses(patches.names, leds.names, bad_rgb, bad_std), leds, sens, sg
    ).reflectance.values
    err_ign = np.sqrt(np.mean((est_ign - ref) ** 2))
    err_raw = np.sqrt(np.mean((est_raw - ref) ** 2))
    assert err_ign < 0.01 < err_raw


def test_integration_on_the_fine_grid_resolves_a_steep_edge() -> None:
    """Eq. 1 integrated at 1 nm with the reflectance on a 10 nm grid (a spline
    through its samples) against everything sampled at 10 nm: an IR-cut edge inside
    LED bands."""
    fine, coarse = Grid(380.0, 730.0, 1.0), Grid(400.0, 700.0, 10.0)
    led = load_led_set(fine)
    cam = load_camera("Canon EOS 5D Mark III", fine)
    wl = fine.wavelength_nm
    cam = cam.with_values(cam.values / (1.0 + np.exp((wl - 652.0) / 2.0)))
    white = render_rgb(np.ones((1, fine.n)), led.values, cam.values, 1.0)
    illum = led.with_values(0.9 * led.values / white[0].max(axis=1)[:, None])
    test = load_training_reflectances_190(fine)
    rgb = render_rgb(test.values, illum.values, cam.values, 1.0)
    resp = Responses(test.names, illum.names, rgb)
    prior = load_colorchecker_sg(coarse)
    truth = test.resample(coarse)
    integrated = wiener_reflectance(resp, illum, cam, prior, noise_std=1e-4)
    sampled = wiener_reflectance(
        resp,
        illum.resample(coarse, average=True),
        cam.resample(coarse),
        prior,
        noise_std=1e-4,
    )
    assert integrated.reflectance.wavelength_nm.size == coarse.n
    assert integrated.lighting.shape == (66, coarse.n)
    good = reflectance_stats(integrated.reflectance, truth).mean_delta_e00
    bad = reflectance_stats(sampled.reflectance, truth).mean_delta_e00
    assert good < 0.25 * bad, (good, bad)


def test_the_integration_grid_is_never_coarser_than_the_calibrations() -> None:
    """Sensitivities that come at 5 nm (rawtoaces JSON) are integrated at 2 nm, with
    the LEDs band-averaged there, not on a 5 nm grid; finer inputs keep their step."""
    est = Grid(400.0, 700.0, 5.0)
    sens5 = load_camera("Canon EOS 5D Mark III", Grid(380.0, 780.0, 5.0))
    assert wiener.integration_grid(sens5, est) == Grid(380.0, 780.0, 2.0)
    sens1 = load_camera("Canon EOS 5D Mark III", Grid(380.0, 730.0, 1.0))
    assert wiener.integration_grid(sens1, est).step_nm == 1.0
    basis = wiener.reflectance_basis(
        est.wavelength_nm, Grid(380.0, 780.0, 2.0).wavelength_nm
    )
    # the spline through the samples passes through them and holds the ends
    assert basis[10] == pytest.approx(np.eye(est.n)[0])  # 400 nm
    assert basis[0] == pytest.approx(np.eye(est.n)[0])  # 380 nm: held
    assert basis.sum(axis=1) == pytest.approx(np.ones(basis.shape[0]))
