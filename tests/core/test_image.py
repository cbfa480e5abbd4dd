"""Per-pixel Wiener estimation (core.image) and the image writers (core.io.image_formats)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tolerances import ATOL_COLOUR, RTOL_NOISE_STATS
from tunespec.core.colorimetry import xyz_to_lab_d50
from tunespec.core.datasets import (
    load_camera,
    load_colorchecker_sg,
    load_led_set,
    load_training_reflectances_190,
)
from tunespec.core.errors import InputError
from tunespec.core.forward_model import lighting_matrix
from tunespec.core.image import (
    NoiseModel,
    block_noise_stats,
    build_wiener_bank,
    estimate_pixels,
    lab_from_xyz,
    photon_transfer_fit,
    srgb8_from_xyz_d50,
    wiener_pixels_exact,
)
from tunespec.core.spectra import Grid

GRID = Grid(400.0, 700.0, 10.0)
#: The 5D Mark III at ISO 100 (devices.sim.camera defaults), one dark subtracted.
CAMERA_NOISE = NoiseModel.from_camera(full_well_e=67000.0, read_noise_e=30.0)
#: Binned vs. exact per-pixel solution, RMS over the reflectance samples, relative
#: to the exact solution's RMS error against the truth (measured 0.13 here: 0.0018
#: vs 0.0138; more bins do not change it, the pixels' colour does it).
RTOL_BINNING = 0.2
#: Fraction of true values inside +-1.96 u: nominal 0.95; 2000 draws give a
#: binomial standard error of 0.005, the prior is only approximately Gaussian.
COVERAGE_RANGE = (0.92, 0.98)


@pytest.fixture(scope="module")
def system() -> dict:
    """F of the 22 LEDs and the 5D Mark III, scaled so the white board (0.9) lands
    at 0.75 full scale in each LED's strongest channel, and the white levels."""
    led = load_led_set(GRID).values
    cam = load_camera(grid=GRID).values
    F = lighting_matrix(led, cam, GRID.step_nm)
    white = F @ np.full(GRID.n, 0.9)
    scale = 0.75 / white.reshape(-1, 3).max(axis=1)
    F = F * np.repeat(scale, 3)[:, None]
    return {"F": F, "white": F @ np.full(GRID.n, 0.9), "sg": load_colorchecker_sg(GRID)}


def _noisy(F, truth, phi, rng, noise=CAMERA_NOISE):
    """Flat-fielded responses with the model's photon + read noise, (n, m)."""
    c = truth @ F.T
    channel = np.tile(np.arange(3), F.shape[0] // 3)
    var = noise.variance(c, phi[:, None], channel)
    return (c + rng.standard_normal(c.shape) * np.sqrt(var)).astype(np.float32)


def test_camera_noise_model_values() -> None:
    # 67 000 e- per full scale: shot variance 1/67000 per unit signal, the G plane
    # (mean of two photosites) half that; read noise twice (frame and dark)
    assert np.allclose(CAMERA_NOISE.shot_gain * 67000.0, [1.0, 0.5, 1.0])
    assert np.allclose(CAMERA_NOISE.read_var[0], 2 * (30 / 67000) ** 2)
    with pytest.raises(InputError):
        NoiseModel([-1.0, 0, 0], [1e-5] * 3)


def test_photon_transfer_fit_recovers_the_sensor() -> None:
    """White frames at 12 levels with the camera's noise: the fit returns it."""
    rng = np.random.default_rng(0)
    level, var = [], []
    for s in np.geomspace(0.005, 0.8, 12):
        # a smooth light field (10 % over the frame) under the noise
        yy, xx = np.mgrid[0:128, 0:128]
        field = s * (1.0 - 0.1 * ((xx - 64) ** 2 + (yy - 64) ** 2) / 64**2)
        planes = np.stack([field] * 3)
        sd = np.sqrt(CAMERA_NOISE.variance(planes.transpose(1, 2, 0))).transpose(
            2, 0, 1
        )
        noisy = (planes + rng.standard_normal(planes.shape) * sd).astype(np.float32)
        lv, vr = block_noise_stats(noisy, None, 16)
        level.append(lv)
        var.append(vr)
    fit = photon_transfer_fit(np.concatenate(level, 1), np.concatenate(var, 1))
    np.testing.assert_allclose(
        fit.shot_gain, CAMERA_NOISE.shot_gain, rtol=RTOL_NOISE_STATS
    )
    np.testing.assert_allclose(fit.read_var, CAMERA_NOISE.read_var, rtol=0.15)
    assert fit.source == "photon-transfer fit"


def test_photon_transfer_fit_rejects_flat_noise() -> None:
    lv = np.tile(np.linspace(0.01, 0.8, 100), (3, 1))
    with pytest.raises(InputError, match="photon"):
        photon_transfer_fit(lv, np.full_like(lv, 1e-6) - 1e-7 * lv)


def test_bin_centre_pixel_equals_the_exact_solve(system) -> None:
    """A pixel whose responses are exactly the bin's model gets the exact Eq. 5."""
    F, white = system["F"], system["white"]
    bank = build_wiener_bank(F, system["sg"].values, white, CAMERA_NOISE, GRID.wavelength_nm,
                             phi_range=(0.9, 1.4), n_levels=16, n_phi=3)  # fmt: skip
    rho, phi = bank.centres()
    b = 20
    c = (rho[b] * white)[None, :].astype(np.float32)
    got = estimate_pixels(bank, c, np.array([phi[b]]), clip=False)
    assert got.bins[0] == b
    exact = wiener_pixels_exact(bank, c.astype(np.float64), np.array([phi[b]]))
    np.testing.assert_allclose(got.reflectance[0], exact[0], atol=1e-5)


def test_binned_estimate_is_close_to_exact_and_to_truth(system) -> None:
    """Noisy pixels of the 190 training reflectances (not the prior's): binned and
    exact per-pixel solutions agree far better than either agrees with the truth,
    and the uncertainty covers the truth about 95 % of the time."""
    rng = np.random.default_rng(1)
    F, white = system["F"], system["white"]
    truth = load_training_reflectances_190(GRID).values
    truth = np.repeat(truth, 10, axis=0)
    phi = rng.uniform(1.0, 1.5, len(truth))
    c = _noisy(F, truth, phi, rng)
    bank = build_wiener_bank(F, system["sg"].values, white, CAMERA_NOISE, GRID.wavelength_nm,
                             phi_range=(1.0, 1.5))  # fmt: skip
    binned = estimate_pixels(bank, c, phi, clip=False)
    exact = estimate_pixels(bank, c, phi, clip=False, exact=True)
    diff = np.sqrt(np.mean((binned.reflectance - exact.reflectance) ** 2))
    err_exact = np.sqrt(np.mean((exact.reflectance - truth) ** 2))
    err_binned = np.sqrt(np.mean((binned.reflectance - truth) ** 2))
    assert diff < RTOL_BINNING * err_exact
    # the exact K_e uses the noisy responses (a low draw gets more weight), the
    # binned one a smooth level: binning is not less accurate against the truth
    assert err_binned < err_exact
    assert (exact.bins == -1).all() and (binned.bins >= 0).all()


def test_uncertainty_is_calibrated_on_prior_like_pixels(system) -> None:
    """Pixels drawn from the prior's own distribution (the SG, 2000 noisy draws):
    95 % intervals of the spectrum and of L* hold the truth about 95 % of the time."""
    rng = np.random.default_rng(2)
    F, white, sg = system["F"], system["white"], system["sg"].values
    truth = sg[rng.integers(0, len(sg), 2000)]
    phi = rng.uniform(1.0, 1.5, len(truth))
    c = _noisy(F, truth, phi, rng)
    bank = build_wiener_bank(F, sg, white, CAMERA_NOISE, GRID.wavelength_nm,
                             phi_range=(1.0, 1.5), flat_residual=0.0)  # fmt: skip
    est = estimate_pixels(bank, c, phi, clip=False)
    z = (est.reflectance - truth) / est.u_rms[:, None]
    cover = np.mean(np.abs(z) < 1.96)
    lab_true = xyz_to_lab_d50(truth @ bank.T)
    zl = (est.lab[:, 0] - lab_true[:, 0]) / est.u_lab_l
    cover_l = np.mean(np.abs(zl) < 1.96)
    assert COVERAGE_RANGE[0] < cover < COVERAGE_RANGE[1]
    assert COVERAGE_RANGE[0] < cover_l < COVERAGE_RANGE[1]


def test_a_bank_reports_some_of_its_samples() -> None:
    """Solved on 380-730 nm and reported on 400-700 nm (as a session solves on the
    range Eq. 1 integrates, ``core.wiener.support_grid``): the reported pixels, the
    exactly solved ones (a clipped response) among them, are the whole bank's on
    those samples, and the uncertainty and colour are theirs."""
    rng = np.random.default_rng(3)
    wide = Grid(380.0, 730.0, 10.0)
    F = lighting_matrix(load_led_set(wide).values, load_camera(grid=wide).values, 10.0)
    F = F / (F @ np.full(wide.n, 0.9)).max()
    white, sg = F @ np.full(wide.n, 0.9), load_colorchecker_sg(wide).values
    truth = load_training_reflectances_190(wide).values[:50]
    phi = rng.uniform(1.0, 1.5, len(truth))
    c = _noisy(F, truth, phi, rng)
    c[:5, 7] = np.nan  # clipped: solved exactly
    kw = {"phi_range": (1.0, 1.5)}
    whole = build_wiener_bank(F, sg, white, CAMERA_NOISE, wide.wavelength_nm, **kw)
    part = build_wiener_bank(
        F, sg, white, CAMERA_NOISE, wide.wavelength_nm, report_nm=GRID.wavelength_nm,
        **kw,
    )  # fmt: skip
    keep = np.isin(wide.wavelength_nm, GRID.wavelength_nm)
    assert np.array_equal(part.wavelength_nm, GRID.wavelength_nm)
    assert np.array_equal(part.Wt, whole.Wt[:, :, keep])
    got, ref = estimate_pixels(part, c, phi), estimate_pixels(whole, c, phi)
    assert got.saturated[:5].all() and (got.bins[:5] == -1).all()
    np.testing.assert_allclose(got.reflectance, ref.reflectance[:, keep], atol=1e-6)
    np.testing.assert_allclose(got.xyz, got.reflectance @ part.T, rtol=1e-5)
    assert np.all(got.u_rms > 0) and np.all(np.isfinite(got.u_lab_l))


def test_saturated_response_is_left_out(system) -> None:
    F, white, sg = system["F"], system["white"], system["sg"]
    bank = build_wiener_bank(F, sg.values, white, CAMERA_NOISE, GRID.wavelength_nm)
    truth = sg.values[:3]
    c = (truth @ F.T).astype(np.float32)
    clean = estimate_pixels(bank, c.copy(), np.ones(3), clip=False)
    c[1, 5] = np.nan  # one clipped response of pixel 1
    got = estimate_pixels(bank, c, np.ones(3), clip=False)
    assert got.saturated.tolist() == [False, True, False]
    assert got.bins[1] == -1 and np.all(np.isfinite(got.reflectance))
    # 65 of 66 noise-free responses still pin the spectrum down
    assert np.abs(got.reflectance[1] - clean.reflectance[1]).max() < 0.02


def test_bank_rejects_mismatched_inputs(system) -> None:
    F, white, sg = system["F"], system["white"], system["sg"]
    with pytest.raises(InputError):
        build_wiener_bank(F, sg.values, white[:-3], CAMERA_NOISE, GRID.wavelength_nm)
    with pytest.raises(InputError):
        build_wiener_bank(F, sg.values, -white, CAMERA_NOISE, GRID.wavelength_nm)
    bank = build_wiener_bank(F, sg.values, white, CAMERA_NOISE, GRID.wavelength_nm)
    with pytest.raises(InputError):
        estimate_pixels(bank, np.zeros((2, 5), np.float32), np.ones(2))


def test_lab_and_srgb_match_colour_science() -> None:
    import colour

    rng = np.random.default_rng(3)
    xyz = rng.uniform(0.0, 100.0, (3, 50))
    xyz[:, :5] *= 0.001  # the linear segment of L* near black
    np.testing.assert_allclose(
        lab_from_xyz(xyz).T, xyz_to_lab_d50(xyz.T), atol=1e-3
    )  # float32 output
    d50 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D50"]
    ref = colour.XYZ_to_sRGB(
        xyz.T / 100.0, illuminant=d50, chromatic_adaptation_transform="Bradford"
    )
    ref8 = np.round(np.clip(ref, 0, 1) * 255)
    assert np.abs(srgb8_from_xyz_d50(xyz).astype(float) - ref8).max() <= 1.0
    assert ATOL_COLOUR > 0


def test_image_outputs_round_trip(tmp_path) -> None:
    """Blocks written at their offsets read back identically from ENVI (Spectral
    Python), Zarr and the TIFFs, wavelengths included."""
    import spectral
    import tifffile
    import zarr

    from tunespec.core.io.image_formats import ImageOutputs, read_provenance

    rng = np.random.default_rng(4)
    rows, cols, wl = 10, 7, np.arange(400.0, 430.0, 5.0)
    cube = rng.uniform(0, 1, (rows, cols, wl.size)).astype(np.float32)
    xyz = rng.uniform(0, 100, (rows, cols, 3)).astype(np.float32)
    lab = rng.uniform(-50, 100, (rows, cols, 3)).astype(np.float32)
    unc = rng.uniform(0, 1, (rows, cols, 2)).astype(np.float32)
    out = ImageOutputs.create(tmp_path / "img", (rows, cols), wl, block_rows=4,
                              provenance={"session": "s", "grid_nm": [400, 425, 5]})  # fmt: skip
    for r0 in (8, 0, 4):  # any order, as parallel workers finish
        sl = slice(r0, r0 + 4)
        out.write_rows(r0, cube[sl], xyz[sl], lab[sl], unc[sl])
    assert read_provenance(tmp_path / "img") is None  # not finished yet
    envi = spectral.open_image(str(tmp_path / "img" / "cube.hdr"))
    np.testing.assert_allclose(envi.bands.centers, wl)
    np.testing.assert_array_equal(np.array(envi.open_memmap()), cube)
    z = zarr.open_array(str(tmp_path / "img" / "cube.zarr" / "reflectance"), mode="r")
    np.testing.assert_array_equal(z[:], cube)
    assert z.attrs["wavelength_nm"] == wl.tolist()
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "img" / "xyz.tif"),
                                  xyz)  # fmt: skip
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "img" / "uncertainty.tif"),
                                  unc)  # fmt: skip
    out.write_provenance({"session": "s"})
    assert read_provenance(tmp_path / "img") == {"session": "s"}
    with pytest.raises(InputError):
        out.write_rows(3, cube[:4], xyz[:4], lab[:4], unc[:4])


def test_scratch_buffers_are_per_thread_and_released() -> None:
    import threading

    from tunespec.core.scratch import release_scratch, scratch

    a = scratch("t", (4, 5))
    a[:] = 1.0
    assert scratch("t", (2, 5)).base is a.base  # reused, smaller view
    other = {}
    t = threading.Thread(target=lambda: other.setdefault("b", scratch("t", (4, 5))))
    t.start()
    t.join()
    assert other["b"].base is not a.base
    assert release_scratch() >= 2 * 4 * 5 * 4
    assert scratch("t", (4, 5)).base is not a.base
    assert float(a.sum()) == 20.0  # still valid for whoever holds it


@pytest.mark.parametrize("tile", [32768, 700])
@pytest.mark.parametrize("layout", ["neighbours", "shuffled", "mixed"])
def test_bins_applied_in_either_write_order(
    system, layout: str, tile: int, monkeypatch
) -> None:
    # pixels of a bin side by side (as in a photograph: the tiles wait and each
    # run's rows are put straight into pixel order), scattered (sorted tile by tile,
    # written sorted, gathered back) or both in one block (the last third
    # shuffled); tiles of 700 pixels: several, the last one short
    from tunespec.core import image_bins

    monkeypatch.setattr(image_bins, "SCATTERED_TILE", tile)
    ran = set()

    def spied(name):  # records that the write order ``name`` ran
        f = getattr(image_bins, name)

        def spy(*args):
            ran.add(name)
            return f(*args)

        return spy

    for name in ("_apply_tile", "_apply_in_order"):
        monkeypatch.setattr(image_bins, name, spied(name))

    F, sg = system["F"], system["sg"].values
    bank = build_wiener_bank(F, sg, system["white"], CAMERA_NOISE, GRID.wavelength_nm,
                             phi_range=(1.0, 1.5))  # fmt: skip
    rng = np.random.default_rng(3)
    n = 3000
    phi = np.repeat(rng.uniform(1.0, 1.5, 30), n // 30)
    c = _noisy(F, sg[np.repeat(np.arange(30), n // 30)], phi, rng)
    c[7, 3] = np.nan  # a clipped response: level NaN, binned at level 0
    first = {"neighbours": n, "shuffled": 0, "mixed": n * 2 // 3}[layout]
    perm = np.r_[np.arange(first), first + rng.permutation(n - first)]
    c, phi = c[perm], phi[perm]
    got = np.full((n, bank.mean.size), -9.0, dtype=np.float32)
    bins, nan_level = image_bins.apply_bank(bank, c, phi, got, clip=True)
    in_order, tiled = {"_apply_in_order"}, {"_apply_tile"}
    expected_paths = {
        "neighbours": in_order,
        "shuffled": tiled,
        "mixed": in_order | tiled if tile == 700 else in_order,  # one tile: in order
    }
    assert ran == expected_paths[layout]
    bad = np.isnan(c).any(axis=1)
    assert np.array_equal(nan_level, bad) and bad.sum() == 1
    assert np.array_equal(bins[~bad], bank.bins_of(c[~bad], phi[~bad]))
    assert bins[bad] == bank.bins_of_level(np.zeros(1), phi[bad])
    exact = (
        np.einsum("pm,pml->pl", c.astype(np.float64), bank.Wt[bins]) + bank.offset[bins]
    )
    assert np.isnan(got[bad]).all()
    np.testing.assert_allclose(
        got[~bad], np.clip(exact[~bad], 0.0, 1.0), rtol=0, atol=1e-5
    )


def test_scratch_phase_places_the_array_for_direct_writes(tmp_path) -> None:
    from tunespec.core.io.image_formats import pwrite_direct
    from tunespec.core.scratch import SCRATCH_ALIGN, release_scratch, scratch

    for phase in (0, 2304, 4092):
        a = scratch("phase_test", (1000, 61), phase=phase)
        assert a.ctypes.data % SCRATCH_ALIGN == phase and a.flags.c_contiguous
    with pytest.raises(ValueError, match="phase"):
        scratch("phase_test", (10,), phase=2)
    # a placed buffer goes to the file without the bounce copy, the same bytes
    offset = 5 * SCRATCH_ALIGN + 2304
    data = scratch("phase_test", (3 << 18,), phase=offset % SCRATCH_ALIGN)
    data[:] = np.arange(data.size, dtype=np.float32)
    path = tmp_path / "direct.bin"
    path.write_bytes(b"")
    pwrite_direct(path, offset, data)
    back = np.fromfile(path, dtype=np.float32, offset=offset)
    np.testing.assert_array_equal(back, data)
    release_scratch()
