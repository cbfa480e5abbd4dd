"""``capture --repeats N``: N frames per LED and bracket, averaged in processing and
in the per-pixel images (1/N of a frame's photon and read-noise variance)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tunespec.app.cli import main
from tunespec.core.errors import InputError
from tunespec.core.spectra import Spectra

RESOLUTION = (256, 192)


def _bench(resolution: tuple[int, int] = RESOLUTION):
    from tunespec.devices.registry import open_bench
    from tunespec.devices.sim.scene import default_regions

    return open_bench(
        "sim", resolution=resolution, seed=0,
        scene_options={"regions": default_regions()},
    )  # fmt: skip


def test_repeats_are_stored_as_repeated_bracket_factors(tmp_path) -> None:
    from tunespec.devices.capture import new_session

    bench = _bench()
    try:
        s = new_session(
            tmp_path / "a", bench.light, bench.camera, layout=bench.truth["layout"],
            brackets=(1.0, 0.125), repeats=2,
        )  # fmt: skip
        assert s.settings.bracket_factors == (1.0, 1.0, 0.125, 0.125)
        for bad in (0, 9):
            with pytest.raises(InputError, match="repeats: expected 1 to 8"):
                new_session(
                    tmp_path / f"b{bad}", bench.light, bench.camera,
                    layout=bench.truth["layout"], brackets=(1.0, 0.125), repeats=bad,
                )  # fmt: skip
    finally:
        bench.close()


def _capture(
    root: Path, repeats: int, resolution: tuple[int, int] = RESOLUTION
) -> tuple[Path, np.ndarray, Spectra]:
    """The session, the material of each plane pixel and the materials' spectra."""
    from tunespec.app.pipeline.plan import ESTIMATION_GRID
    from tunespec.devices.capture import capture, new_session

    bench = _bench(resolution)
    session = new_session(
        root / "session", bench.light, bench.camera, layout=bench.truth["layout"],
        exposure="auto", repeats=repeats, n_darks=repeats,
    )  # fmt: skip
    capture(session, bench.light, bench.camera, bench.stage)
    bench.sim_camera.write_truth(root / "truth")
    plane = bench.sim_stage.plane_materials(*resolution)
    materials = bench.sim_stage.materials.resample(ESTIMATION_GRID)
    bench.close()
    return root / "session", plane, materials


@pytest.mark.slow
def test_repeats_shrink_the_pixel_noise(tmp_path) -> None:
    """Four frames per LED (and four darks): the pixels' spread around their patch's
    mean and the patches' per-pixel standard deviation (Eq. 6) halve; the camera's
    noise model knows the frames were averaged."""
    import tifffile

    from tunespec.app.pipeline.processing import process_session
    from tunespec.core.colorimetry import delta_e_2000
    from tunespec.core.io.session import Session

    spread, eq6 = {}, {}
    for n in (1, 4):
        session, pm, _ = _capture(tmp_path / f"r{n}", n)
        sens = tmp_path / f"r{n}" / "truth" / "truth_sensitivity_absolute.csv"
        out = tmp_path / f"img{n}"
        assert main([
            "estimate-image", str(session), "--sensitivities", str(sens), "--out",
            str(out), "--quiet", "--noise-model", "camera:67000,30",
        ]) == 0  # fmt: skip
        lab = tifffile.imread(out / "lab.tif").astype(np.float64)
        patches = pm >= 2
        de = []
        for m in np.unique(pm[patches]):
            px = lab[pm == m]
            de.append(delta_e_2000(px, px.mean(axis=0, keepdims=True)))
        spread[n] = float(np.concatenate(de).mean())
        std = process_session(Session.open(session)).responses.rgb_std
        eq6[n] = float(np.nanmedian(std))
        noise = json.loads((out / "provenance.json").read_text())["noise_model"]
        np.testing.assert_allclose(noise["shot_gain_fs"][0], 1 / 67000 / n)
    # measured 0.52 and 0.50 (sqrt(1/4) = 0.5)
    assert 0.4 < spread[4] / spread[1] < 0.6, spread
    assert 0.4 < eq6[4] / eq6[1] < 0.6, eq6


@pytest.mark.slow
def test_four_frames_and_the_smooth_dark_bring_pixels_near_patchwise(tmp_path) -> None:
    """Issue 14's accuracy goal: with four frames per LED (and four darks) and
    ``--dark smooth``, the per-pixel CIEDE2000 against the truth, over the SG's
    patches and over every pixel of known material, is within 1.5x of the
    patch-wise estimate's (measured at 384x256: 1.2x and 1.3x; one frame and the
    pixel dark: 3.2x at 768x512, ``benchmarks/bench_image_accuracy.py``)."""
    import tifffile

    from tunespec.app.pipeline.plan import ESTIMATION_GRID as GRID
    from tunespec.app.pipeline.processing import process_session, write_processed
    from tunespec.core.calibration import correct_illuminants_from_meta
    from tunespec.core.colorimetry import delta_e_2000, lab_d50
    from tunespec.core.datasets import load_colorchecker_sg, read_sensitivities
    from tunespec.core.io.export import read_sensitivity_meta
    from tunespec.core.io.session import Session
    from tunespec.core.wiener import wiener_reflectance

    session, pm, mats = _capture(tmp_path, 4, (384, 256))
    processed = process_session(Session.open(session))
    write_processed(processed, tmp_path / "resp.csv", tmp_path / "ill.csv")
    sens = tmp_path / "S.csv"
    assert main([
        "calibrate", "--responses", str(tmp_path / "resp.csv"), "--illuminants",
        str(tmp_path / "ill.csv"), "--reflectances",
        "resources/charts/colorchecker_sg.csv", "-o", str(sens), "--quiet",
    ]) == 0  # fmt: skip
    assert main([
        "estimate-image", str(session), "--sensitivities", str(sens), "--out",
        str(tmp_path / "img"), "--quiet", "--dark", "smooth",
    ]) == 0  # fmt: skip
    wl = GRID.wavelength_nm
    ill = correct_illuminants_from_meta(
        processed.illuminants.resample(GRID, average=True), read_sensitivity_meta(sens)
    )
    names = processed.layout.patch_names
    est = wiener_reflectance(
        processed.responses, ill, read_sensitivities(sens, GRID),
        load_colorchecker_sg(GRID),
    ).reflectance.values  # fmt: skip
    de_patch = delta_e_2000(lab_d50(est, wl), lab_d50(mats.select(names).values, wl))
    lab = tifffile.imread(tmp_path / "img" / "lab.tif").astype(np.float64)
    truth = lab_d50(mats.values, wl)
    patches = (pm >= 2) & (pm < 2 + len(names))
    for sel in (patches, pm >= 0):
        ratio = delta_e_2000(lab[sel], truth[pm[sel]]).mean() / de_patch.mean()
        assert ratio < 1.5, ratio
