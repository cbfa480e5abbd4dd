"""Per-pixel images of sessions on the simulated bench (app.pipeline.image, CLI).

The bench renders the ColorChecker SG with a CMY halftone and strokes of measured
reflectances beside it (devices.sim.scene.default_regions), so every superpixel's
reflectance is known. Small images keep the tests to seconds; they are marked slow.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tunespec.app.cli import main
from tunespec.app.pipeline.plan import ESTIMATION_GRID as GRID

pytestmark = pytest.mark.slow

RESOLUTION = (384, 256)
#: 95 % intervals: fraction of true values inside (nominal 0.95; patches and
#: regions of one small session, pixels correlated through the calibration;
#: measured L* 0.928-0.958 and reflectance 0.938-0.966 with the flat field the
#: calibration fitted; with the nominal 0.3 %, ten times the bench's, L* 0.977-0.998).
COVERAGE_RANGE = (0.90, 0.999)


@pytest.fixture(scope="module")
def bench_session(tmp_path_factory) -> dict:
    """A session of the SG with mixed regions, its truth and a bayes calibration."""
    from tunespec.app.pipeline.processing import process_session, write_processed
    from tunespec.core.io.session import Session
    from tunespec.devices.capture import capture, new_session
    from tunespec.devices.registry import open_bench
    from tunespec.devices.sim.scene import default_regions

    root = tmp_path_factory.mktemp("image_bench")
    bench = open_bench(
        "sim", resolution=RESOLUTION, seed=0,
        scene_options={"regions": default_regions()},
    )  # fmt: skip
    session = new_session(
        root / "session", bench.light, bench.camera, layout=bench.truth["layout"],
        exposure="auto",
    )  # fmt: skip
    capture(session, bench.light, bench.camera, bench.stage)
    bench.sim_camera.write_truth(root / "truth")
    processed = process_session(Session.open(root / "session"))
    write_processed(processed, root / "resp.csv", root / "ill.csv")
    sens = root / "cal" / "S.csv"
    assert main([
        "calibrate", "--responses", str(root / "resp.csv"), "--illuminants",
        str(root / "ill.csv"), "--reflectances", "resources/charts/colorchecker_sg.csv",
        "-o", str(sens),
    ]) == 0  # fmt: skip
    materials = bench.sim_stage.materials.resample(GRID)
    plane = bench.sim_stage.plane_materials(*RESOLUTION)
    bench.close()
    return {
        "root": root,
        "session": root / "session",
        "processed": processed,
        "sens": sens,
        "materials": materials,
        "plane_materials": plane,
    }


def _read(folder: Path) -> dict[str, np.ndarray]:
    import spectral
    import tifffile
    import zarr

    envi = spectral.open_image(str(folder / "cube.hdr"))
    return {
        "wl": np.asarray(envi.bands.centers),
        "cube": np.array(envi.open_memmap()),
        "zarr": zarr.open_array(str(folder / "cube.zarr" / "reflectance"), mode="r")[:],
        "xyz": tifffile.imread(folder / "xyz.tif"),
        "lab": tifffile.imread(folder / "lab.tif"),
        "unc": tifffile.imread(folder / "uncertainty.tif"),
    }


@pytest.fixture(scope="module")
def images(bench_session) -> dict:
    out = bench_session["root"] / "images"
    code = main([
        "estimate-image", str(bench_session["session"]), "--sensitivities",
        str(bench_session["sens"]), "--out", str(out),
    ])  # fmt: skip
    assert code == 0
    return {"out": out, **_read(out)}


def test_outputs_agree_and_carry_provenance(images, bench_session) -> None:
    import json

    from tunespec.core.colorimetry import astm_e308_weights_d50
    from tunespec.core.image import lab_from_xyz

    np.testing.assert_allclose(images["wl"], GRID.wavelength_nm)
    h, w = RESOLUTION[1] // 2, RESOLUTION[0] // 2
    assert images["cube"].shape == (h, w, GRID.n) and images["cube"].dtype == np.float32
    np.testing.assert_array_equal(images["zarr"], images["cube"])
    xyz = images["cube"].astype(np.float64) @ astm_e308_weights_d50(GRID.wavelength_nm)
    np.testing.assert_allclose(images["xyz"], xyz, atol=2e-3)  # float32 sums
    lab = lab_from_xyz(images["xyz"].reshape(-1, 3).T).T.reshape(h, w, 3)
    np.testing.assert_allclose(images["lab"], lab, atol=1e-4)
    prov = json.loads((images["out"] / "provenance.json").read_text())
    assert prov["grid_nm"] == [400.0, 700.0, 5.0]
    assert prov["session_fingerprint"] and prov["calibration_sha256"]
    assert prov["noise_model"]["source"] == "photon-transfer fit"
    assert prov["led_corrections"] == "per-LED"
    assert (images["out"] / "srgb.png").stat().st_size > 1000
    assert not (images["out"] / ".work").exists()
    # the white board against the calibration's chart session (here the same one)
    assert prov["white_scale"].startswith("1.00") and prov["forced"] == []
    assert prov["warnings"] == []  # a linear sensor's board: nothing to say


def test_a_session_on_another_scale_is_refused(bench_session, tmp_path, capsys):
    """The images check the session's white board against the calibration's chart
    session as ``estimate`` does: a side file whose board is half (the session
    twice as bright as recorded) is refused, and ``--force`` lists the override.
    What the calibration found about itself is said once, where its file is read."""
    import json

    sens = tmp_path / "S.csv"
    shutil.copy(bench_session["sens"], sens)
    doc = json.loads(Path(str(bench_session["sens"]) + ".meta.json").read_text())
    doc["white_background"] = {k: v / 2 for k, v in doc["white_background"].items()}
    doc["warnings"] = ["Table 1 is poor"]
    Path(str(sens) + ".meta.json").write_text(json.dumps(doc))
    argv = ["estimate-image", str(bench_session["session"]), "--sensitivities",
            str(sens), "--formats", "envi"]  # fmt: skip
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "refused")]) == 2
    err = capsys.readouterr().err
    assert "white background reflects 2x" in err and "--force to accept" in err, err
    assert err.count(f"warning: the calibration {sens} warned: Table 1 is poor") == 1
    assert not (tmp_path / "refused" / "cube.hdr").exists()
    assert main([*argv, "--out", str(tmp_path / "forced"), "--force"]) == 0
    prov = json.loads((tmp_path / "forced" / "provenance.json").read_text())
    assert prov["white_scale"].startswith("2.0") and len(prov["forced"]) == 1


def test_pixel_means_agree_with_patchwise_estimates(images, bench_session) -> None:
    """The mean of the per-pixel spectra over each patch's central 20 % agrees with
    the patch-wise estimate (tunespec estimate on the processed session) within the
    patch-wise uncertainty."""
    from tunespec.core.io.raw import full_to_plane_px
    from tunespec.core.processing import RoiSet

    p = bench_session["processed"]
    est, unc = _patchwise(bench_session)
    rois = RoiSet.from_quads(
        p.layout.patch_names, full_to_plane_px(p.layout.roi_quads_px()),
        images["cube"].shape[:2],
    )  # fmt: skip
    starts = np.concatenate([[0], np.cumsum(rois.n_pixels)[:-1]])
    n = rois.n_pixels[:, None]
    pix = images["cube"][rois.rows, rois.cols].astype(np.float64)
    means = np.add.reduceat(pix, starts, axis=0) / n
    # the mean's own noise: the pixels' RMS uncertainty over sqrt(n)
    u_pix = images["unc"][rois.rows, rois.cols, 1].astype(np.float64)
    u_mean = np.sqrt(np.add.reduceat(u_pix**2, starts) / n[:, 0]) / np.sqrt(n[:, 0])
    u_mean = u_mean[:, None]
    z = (means - est) / np.sqrt(unc**2 + u_mean**2)
    assert np.mean(np.abs(z) < 1.96) > 0.95
    assert np.sqrt(np.mean((means - est) ** 2)) < 0.005


def _patchwise(bench_session) -> tuple[np.ndarray, np.ndarray]:
    """Patch-wise estimate and uncertainty, as ``tunespec estimate`` computes them."""
    from tunespec.core.calibration import Calibration, correct_illuminants_from_meta
    from tunespec.core.datasets import load_colorchecker_sg, read_sensitivities
    from tunespec.core.io.export import read_sensitivity_meta
    from tunespec.core.uncertainty import reflectance_uncertainty
    from tunespec.core.wiener import on_integration_grid, wiener_reflectance

    p = bench_session["processed"]
    meta = read_sensitivity_meta(bench_session["sens"])
    sens = read_sensitivities(bench_session["sens"])
    corrected = correct_illuminants_from_meta(p.illuminants, meta)
    illum_fine, sens_fine, _ = on_integration_grid(corrected, sens, GRID)
    est = wiener_reflectance(
        p.responses, illum_fine, sens_fine, load_colorchecker_sg(GRID)
    )
    cal = Calibration.load(bench_session["sens"])
    unc = reflectance_uncertainty(est, p.responses, p.illuminants, cal)
    return est.reflectance.values, unc.reflectance_std


def test_pixels_against_truth(images, bench_session) -> None:
    """Per-pixel CIEDE2000 against the truth and the uncertainty's calibration."""
    from tunespec.core.colorimetry import delta_e_2000, lab_d50

    mats, pm = bench_session["materials"], bench_session["plane_materials"]
    lab_true = lab_d50(mats.values, GRID.wavelength_nm)
    est, _ = _patchwise(bench_session)
    names = bench_session["processed"].layout.patch_names
    truth_patch = mats.select(names).values
    de_patch = delta_e_2000(
        lab_d50(est, GRID.wavelength_nm), lab_d50(truth_patch, GRID.wavelength_nm)
    ).mean()
    patches = (pm >= 2) & (pm < 2 + len(names))
    regions = pm >= 2 + len(names)
    for sel in (patches, regions):
        m = pm[sel]
        de = delta_e_2000(images["lab"][sel].astype(np.float64), lab_true[m])
        z_l = (images["lab"][sel][:, 0] - lab_true[m][:, 0]) / images["unc"][sel][:, 0]
        z_r = (images["cube"][sel] - mats.values[m]) / images["unc"][sel][:, 1:2]
        assert COVERAGE_RANGE[0] < np.mean(np.abs(z_l) < 1.96) < COVERAGE_RANGE[1]
        assert COVERAGE_RANGE[0] < np.mean(np.abs(z_r) < 1.96) < COVERAGE_RANGE[1]
        # single-superpixel noise: measured 0.38 (patches) and 0.22 (regions)
        # against 0.11 patch-wise; the goal of 1.5x is not met (docs/validation.md)
        assert de.mean() < 5.0 * de_patch
        assert de.mean() < 0.6


def test_rectified_images(bench_session, tmp_path) -> None:
    out = tmp_path / "rect"
    assert main([
        "estimate-image", str(bench_session["session"]), "--sensitivities",
        str(bench_session["sens"]), "--out", str(out), "--rectify",
    ]) == 0  # fmt: skip
    import tifffile

    layout = bench_session["processed"].layout
    lab = tifffile.imread(out / "lab.tif")
    # square pixels on the chart: the aspect ratio is the chart's
    assert abs(lab.shape[1] / lab.shape[0] - layout.width_mm / layout.height_mm) < 0.02
    # the centre of patch A1 (top-left, a light neutral) in the rectified image
    cx, cy = layout.patch_centers_mm()[0] * lab.shape[1] / layout.width_mm
    l_a1 = lab[int(cy), int(cx), 0]
    from tunespec.core.colorimetry import lab_d50

    truth = lab_d50(bench_session["materials"].select(layout.patch_names[:1]).values,
                    GRID.wavelength_nm)[0, 0]  # fmt: skip
    assert abs(l_a1 - truth) < 2.0


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.filterwarnings("ignore::ResourceWarning")
def test_local_cluster_gives_identical_images(bench_session, images, tmp_path) -> None:
    """``--scheduler ADDRESS`` of a dask.distributed LocalCluster with 2 worker
    processes computes exactly the images of the local threaded scheduler."""
    from distributed import LocalCluster

    out = tmp_path / "cluster"
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        code = main([
            "estimate-image", str(bench_session["session"]), "--sensitivities",
            str(bench_session["sens"]), "--out", str(out),
            "--scheduler", cluster.scheduler_address,
        ])  # fmt: skip
    assert code == 0
    got = _read(out)
    for key in ("cube", "zarr", "xyz", "lab", "unc"):
        np.testing.assert_array_equal(got[key], images[key], err_msg=key)


def test_batch_resumes_after_kill(bench_session, tmp_path) -> None:
    """Three sessions; the batch is killed (SIGKILL) once the first is finished, and
    the second run skips it and does the other two."""
    folder = tmp_path / "week"
    for name in ("a", "b", "c"):
        shutil.copytree(bench_session["session"], folder / name)
    out = tmp_path / "out"
    cmd = [
        sys.executable, "-m", "tunespec.app.cli", "batch", str(folder),
        "--sensitivities", str(bench_session["sens"]), "--out", str(out),
        "--sessions-at-once", "1",
    ]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    first = out / "a" / "provenance.json"
    deadline = time.monotonic() + 120
    while not first.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    # sessions b and c take seconds more: the batch is still running
    assert proc.poll() is None, "the batch finished before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert first.exists()
    stamp = first.stat().st_mtime_ns
    from tunespec.app.pipeline.image import batch_images

    result = batch_images(folder, bench_session["sens"], out)
    assert result["skipped"][0].endswith("a")
    assert first.stat().st_mtime_ns == stamp
    assert sorted(Path(s).name for s in result["done"] + result["skipped"]) == [
        "a",
        "b",
        "c",
    ]
    assert len(result["done"]) == 2
    for name in ("a", "b", "c"):
        assert (out / name / "provenance.json").exists()
        assert not (out / name / ".work").exists()
    again = batch_images(folder, bench_session["sens"], out)
    assert again["done"] == [] and len(again["skipped"]) == 3


def test_exposure_brackets_are_merged(tmp_path) -> None:
    """A session shot with brackets (1, 1/8) at 60 s, which clips the white board in
    the long frames, gives the images of a single 7.5 s exposure: the clipped
    superpixels take the short frame, scaled."""
    import tifffile

    from tunespec.devices.capture import capture, new_session
    from tunespec.devices.registry import open_bench

    lab = {}
    for name, exposure, brackets in (("hdr", 60.0, (1.0, 0.125)), ("one", 7.5, (1.0,))):
        bench = open_bench("sim", resolution=(256, 192), seed=3)
        session = new_session(
            tmp_path / name, bench.light, bench.camera,
            layout=bench.truth["layout"], exposure=exposure, brackets=brackets,
        )  # fmt: skip
        capture(session, bench.light, bench.camera, bench.stage)
        bench.sim_camera.write_truth(tmp_path / "truth")
        board = bench.sim_stage.plane_materials(256, 192) == 0
        bench.close()
        assert main([
            "estimate-image", str(tmp_path / name), "--sensitivities",
            str(tmp_path / "truth" / "truth_sensitivity_absolute.csv"), "--out",
            str(tmp_path / f"img_{name}"), "--quiet",
        ]) == 0  # fmt: skip
        lab[name] = tifffile.imread(tmp_path / f"img_{name}" / "lab.tif")
    assert np.all(np.isfinite(lab["hdr"]))
    board_l = {k: float(np.median(v[board][:, 0])) for k, v in lab.items()}
    # measured 0.73 (2.7 before cells near the full well counted as clipped); the
    # merged values come from frames taken a minute after the reference frame
    # whose SPD x exposure is the illuminant
    assert abs(board_l["hdr"] - board_l["one"]) < 1.0, board_l


def test_camera_noise_model_option(bench_session, images, tmp_path) -> None:
    """``--noise-model camera:...`` (the simulated sensor's figures) replaces the
    photon-transfer fit; the fit found the same photon term, so the images agree."""
    import json

    out = tmp_path / "camera"
    assert main([
        "estimate-image", str(bench_session["session"]), "--sensitivities",
        str(bench_session["sens"]), "--out", str(out), "--quiet",
        "--noise-model", "camera:67000,30", "--level-bins", "16",
    ]) == 0  # fmt: skip
    prov = json.loads((out / "provenance.json").read_text())
    fitted = json.loads((images["out"] / "provenance.json").read_text())
    nm = prov["noise_model"]
    assert nm["source"] == "camera" and nm["n_level_bins"] == 16
    np.testing.assert_allclose(nm["shot_gain_fs"], [1 / 67000, 0.5 / 67000, 1 / 67000])
    # the photon-transfer fit of the white frames against the sensor's truth
    np.testing.assert_allclose(
        fitted["noise_model"]["shot_gain_fs"], nm["shot_gain_fs"], rtol=0.25
    )
    lab = _read(out)["lab"]
    assert np.median(np.abs(lab[..., 0] - images["lab"][..., 0])) < 0.05


def test_per_pixel_error_is_noise_not_bias(images, bench_session) -> None:
    """Decomposed over the SG's patches: the mean of each patch's per-pixel spectra
    is as close to the truth as the patch-wise estimate (no bias from the flat
    field, the binning or the stack's half precision), and what the per-pixel
    CIEDE2000 adds is the single superpixel's photon and read noise (the spread of
    the pixels around their patch's mean), which the uncertainty image covers."""
    from tunespec.core.colorimetry import delta_e_2000, lab_d50

    mats, pm = bench_session["materials"], bench_session["plane_materials"]
    names = bench_session["processed"].layout.patch_names
    wl = GRID.wavelength_nm
    est, _ = _patchwise(bench_session)
    lab_truth = lab_d50(mats.select(names).values, wl)
    de_patch = delta_e_2000(lab_d50(est, wl), lab_truth).mean()
    sel = (pm >= 2) & (pm < 2 + len(names))
    idx = pm[sel] - 2
    sums = np.zeros((len(names), GRID.n))
    np.add.at(sums, idx, images["cube"][sel].astype(np.float64))
    means = sums / np.bincount(idx, minlength=len(names))[:, None]
    lab_means = lab_d50(means, wl)
    de_bias = delta_e_2000(lab_means, lab_truth).mean()
    de_noise = delta_e_2000(images["lab"][sel].astype(np.float64), lab_means[idx])
    de_pixels = delta_e_2000(images["lab"][sel].astype(np.float64), lab_truth[idx])
    # measured at 384x256: patch-wise 0.19, bias 0.11, noise 0.36 (768x512, the
    # accuracy benchmark: 0.115, 0.081, 0.356; without noise the pixels are at 0.082)
    assert de_bias < 1.0 * de_patch
    assert de_pixels.mean() < de_bias + de_noise.mean()
    assert de_noise.mean() > 0.8 * de_pixels.mean()


def test_smooth_dark_takes_the_dark_frames_noise_out(
    images, bench_session, tmp_path
) -> None:
    """``--dark smooth``: the single dark frame's read noise no longer adds to every
    pixel; the per-pixel CIEDE2000 of the patches drops (measured 0.37 -> 0.27 at
    768x512, the accuracy benchmark), the uncertainty stays calibrated."""
    import json

    from tunespec.core.colorimetry import delta_e_2000, lab_d50

    out = tmp_path / "smooth"
    assert main([
        "estimate-image", str(bench_session["session"]), "--sensitivities",
        str(bench_session["sens"]), "--out", str(out), "--quiet", "--dark", "smooth",
    ]) == 0  # fmt: skip
    got = _read(out)
    assert json.loads((out / "provenance.json").read_text())["dark"] == "smooth"
    mats, pm = bench_session["materials"], bench_session["plane_materials"]
    n = len(bench_session["processed"].layout.patch_names)
    sel = (pm >= 2) & (pm < 2 + n)
    truth = lab_d50(mats.values, GRID.wavelength_nm)[pm[sel]]
    de = {
        k: delta_e_2000(v["lab"][sel].astype(np.float64), truth).mean()
        for k, v in (("pixel", images), ("smooth", got))
    }
    assert de["smooth"] < 0.85 * de["pixel"], de
    z_l = (got["lab"][sel][:, 0] - truth[:, 0]) / got["unc"][sel][:, 0]
    assert COVERAGE_RANGE[0] < np.mean(np.abs(z_l) < 1.96) < COVERAGE_RANGE[1]
