"""The whole measurement on the simulated bench: the paper's numbers, resume, config.

One demo run (module fixture, 768 x 512 frames) serves most tests; the thresholds are
the paper's own figures (Table 1 and Table 2 averages).
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from tunespec.app.pipeline.plan import ESTIMATION_GRID, load_config
from tunespec.app.pipeline.run import run_config, run_demo
from tunespec.core.colorimetry import lab_d50
from tunespec.core.errors import InputError
from tunespec.core.io.responses_csv import read_responses_csv
from tunespec.core.io.session import Session
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.progress import Cancelled

#: Paper, Table 1: mean RGB RMS prediction error of the SG under all LEDs.
PAPER_TABLE1_RGB_RMS = 0.0024
#: Paper, Table 2 averages: CIEDE2000 (D50) and spectral RMS of the sample target.
PAPER_TABLE2_DE00 = 0.67
PAPER_TABLE2_SPECTRAL_RMS = 0.0286
#: Automatic corners against the simulation's truth, mosaic pixels.
MAX_CORNER_ERROR_PX = 1.0
#: Small frames keep the test fast; the demo default is 1536 x 1024.
RESOLUTION = (768, 512)


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    fractions: list[float] = []
    result = run_demo(out, resolution=RESOLUTION, progress=fractions.append)
    return result, fractions


def test_demo_reaches_the_papers_numbers(demo) -> None:
    result, _ = demo
    assert result.table1.mean[3] <= PAPER_TABLE1_RGB_RMS
    assert result.table1.n_stimuli == 140 * 22 - 22 * len(
        result.calibration.estimate.excluded_patches
    )
    assert result.table2.mean_delta_e00 <= PAPER_TABLE2_DE00
    assert result.table2.mean_spectral_rms <= PAPER_TABLE2_SPECTRAL_RMS
    for err in result.truth["corner_error_px"].values():
        assert err < MAX_CORNER_ERROR_PX
    assert result.chart.corners_source == "auto"


def test_calibration_meets_the_bench_truth_within_its_uncertainty(demo) -> None:
    """The bench's spectroradiometer has no gain error, only noise that it clips at
    zero. Before that floor was taken out of the reported spectra (core.metering) the
    per-LED gains absorbed it (0.61-1.14), the sensitivities came out 11 % low and
    their 95 % bands held 50-93 % of the true curves.

    The responses fix the product of sensitivities and light, not how a common
    factor splits between them (the gains' geometric mean is held at 1): the scale is
    checked to 3 %, the bands against the true curves at the estimate's scale."""
    result, _ = demo
    est = result.calibration.estimate
    gain = np.asarray(est.led_correction.gain)
    assert np.all(np.abs(gain - 1.0) < 0.05), gain
    truth = read_spectra_csv(
        result.out_dir / "truth" / "truth_sensitivity_absolute.csv"
    )
    t = truth.resample(est.sensitivity.grid).values
    s = est.sensitivity.values
    scale = np.sum(s * t) / np.sum(t * t)
    assert scale == pytest.approx(1.0, abs=0.03)
    inside = t > 0.01 * t.max(axis=1, keepdims=True)
    covered = np.abs(s - scale * t) <= 1.96 * est.std
    for k in range(3):
        assert np.mean(covered[k][inside[k]]) >= 0.9, "RGB"[k]


def test_demo_outputs_share_one_file_mode_and_leave_no_tmp_folder(demo) -> None:
    """Manifests and summary.json were 0600 (mkstemp) beside 0644 outputs, and each
    finished session kept an empty tmp/ folder (issue 13)."""
    import os

    result, _ = demo
    umask = os.umask(0)
    os.umask(umask)
    everything = list(result.out_dir.rglob("*"))
    modes = {
        str(p.relative_to(result.out_dir)): p.stat().st_mode & 0o777
        for p in everything
        if p.is_file()
    }
    assert "summary.json" in modes and "chart/manifest.json" in modes
    odd = {k: oct(v) for k, v in modes.items() if v != 0o666 & ~umask}
    assert not odd
    assert not [p for p in everything if p.is_dir() and p.name == "tmp"]


def test_demo_progress_and_outputs(demo) -> None:
    result, fractions = demo
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    out = result.out_dir / "export"  # every export under export/, as the wizard's
    assert (result.out_dir / "summary.json").is_file()
    assert json.loads((out / "exports.json").read_text()) == {
        k: p.name for k, p in result.files.items() if k != "summary_json"
    }
    assert not list(result.out_dir.glob("*.csv"))  # none left at the root
    for name in (
        "chart_responses.csv",
        "chart_illuminants.csv",
        "responses.csv",
        "illuminants.csv",
        "sensitivities.csv",
        "reflectances.csv",
        "reflectances.ti3",
        "table1_prediction.csv",
        "table2_reflectance.csv",
        "report.html",
        "report.pdf",
    ):
        assert (out / name).is_file(), name
    # what `tunespec calibrate` / `estimate` read
    chart = read_responses_csv(out / "chart_responses.csv")
    assert chart.rgb.shape == (140, 22, 3)
    illum = read_spectra_csv(out / "chart_illuminants.csv")
    assert illum.names == chart.illuminants
    refl = read_spectra_csv(out / "reflectances.csv")
    assert refl.wavelength_nm[0] == ESTIMATION_GRID.start_nm
    summary = json.loads((result.out_dir / "summary.json").read_text())
    assert summary["table1_rgb_rms_mean"] == pytest.approx(result.table1.mean[3])
    # the uncertainties beside the values (issue 10)
    u = read_spectra_csv(out / "reflectances_uncertainty.csv")
    assert u.names == refl.names and np.all(u.values > 0) and np.all(u.values <= 0.5)
    rows = (out / "colorimetry.csv").read_text().splitlines()
    assert rows[0] == "patch,X,Y,Z,L,a,b,u_X,u_Y,u_Z,u_L,u_a,u_b"
    lab = np.array([[float(x) for x in r.split(",")[4:7]] for r in rows[1:]])
    assert np.allclose(lab, lab_d50(refl), atol=1e-4)
    ti3 = (out / "reflectances.ti3").read_text()
    assert "LAB_L_U" in ti3 and "TUNESPEC_UNCERTAINTY" in ti3
    meta = json.loads((out / "sensitivities.csv.meta.json").read_text())
    assert len(meta["led_correction"]["leds"]) == 22
    n_par = 3 * read_spectra_csv(out / "sensitivities.csv").wavelength_nm.size + 44
    assert np.array(meta["covariance"]["values"]).shape == (n_par, n_par)
    # both sessions complete and checksummed
    for name in ("chart", "sample"):
        assert Session.open(result.out_dir / name).missing() == []


def test_illuminants_are_measured_spd_times_exposure(demo) -> None:
    # ... with the spectroradiometer's clipped noise floor taken out (core.metering)
    result, _ = demo
    session = Session.open(result.out_dir / "chart")
    rec = session.frame("target_LED540")
    spd = session.read_spd(rec).values[0]
    got = result.chart.illuminants["LED540"] / rec.exposure_s
    kept = got > 0
    np.testing.assert_allclose(got[kept], spd[kept])
    removed = spd[~kept]
    assert removed.size > 100  # the floor far from 540 nm
    assert removed.max() < 0.005 * spd.max()
    assert 0.001 < removed.sum() / spd.sum() < 0.02


@pytest.mark.slow
def test_rerun_resumes_without_capturing(demo, tmp_path) -> None:
    result, _ = demo
    out = tmp_path / "again"
    shutil.copytree(result.out_dir, out)
    # a folder of the layout before the exports moved under export/: at the root
    for f in (out / "export").iterdir():
        f.rename(out / f.name)
    (out / "export").rmdir()
    before = {
        p.name: p.stat().st_mtime_ns for p in (out / "chart" / "frames").iterdir()
    }
    again = run_demo(out, resolution=RESOLUTION, report_files=False)
    after = {p.name: p.stat().st_mtime_ns for p in (out / "chart" / "frames").iterdir()}
    assert after == before
    # resumed, and the exports written again where they now belong
    assert again.files["reflectances_csv"] == out / "export" / "reflectances.csv"
    assert (out / "export" / "exports.json").is_file()
    assert again.table1.mean[3] == pytest.approx(result.table1.mean[3])


@pytest.mark.slow
def test_config_run_on_existing_sessions(demo, tmp_path) -> None:
    result, _ = demo
    shutil.copytree(result.out_dir / "chart", tmp_path / "run" / "chart")
    shutil.copytree(result.out_dir / "sample", tmp_path / "run" / "sample")
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        'out = "run"\n[bench]\nlight = "sim"\nresolution = "768x512"\n'
        "[export]\nreport = false\n"
    )
    run = run_config(cfg)
    assert run.table1.mean[3] == pytest.approx(result.table1.mean[3])
    assert (tmp_path / "run" / "export" / "sensitivities.csv").is_file()


def test_config_errors_name_the_file(tmp_path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[bench]\nlamp = 'sim'\n")
    with pytest.raises(InputError, match="lamp"):
        load_config(bad)
    bad.write_text("[bench\n")
    with pytest.raises(InputError, match="TOML"):
        load_config(bad)
    with pytest.raises(InputError, match="not found"):
        load_config(tmp_path / "none.json")


def test_cancel_stops_the_demo_and_keeps_frames(tmp_path) -> None:
    seen: list[str] = []
    with pytest.raises(Cancelled):
        run_demo(
            tmp_path / "d",
            resolution=(384, 256),
            on_frame=lambda rec, _: seen.append(rec.id),
            should_stop=lambda: len(seen) >= 5,
        )
    assert len(Session.open(tmp_path / "d" / "chart").frames) == 5


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ('[capture]\niso = "abc"\n', "capture.iso"),
        ('[capture]\nbrackets = "x"\n', "capture.brackets"),
        ('[capture]\nbrackets = [1.0, "a"]\n', "capture.brackets"),
        ("[capture]\nexposure = [1]\n", "capture.exposure"),
        ('[bench]\nseed = "x"\n', "bench.seed"),
        ("[bench]\nresolution = 5\n", "bench.resolution"),
        ("[chart]\nlayout = 5\n", "chart.layout"),
        ("[calibrate]\ngrid = 5\n", "calibrate.grid"),
        ('[export]\nreport = "no"\n', "export.report"),
    ],
)
def test_config_values_of_the_wrong_type_are_one_line_errors(
    tmp_path, text, key
) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    with pytest.raises(InputError, match=key) as info:
        run_config(cfg)
    assert "bad.toml" in str(info.value)
    assert not (tmp_path / "run").exists()  # nothing captured


def test_sample_bench_keeps_the_bench_and_camera_constants() -> None:
    from tunespec.app.pipeline.plan import sample_layout
    from tunespec.app.pipeline.steps import bench_for_target
    from tunespec.core.spectra import Spectra
    from tunespec.devices.registry import open_bench

    grey = Spectra(np.linspace(380.0, 780.0, 81), np.full((1, 81), 0.6), ("board",))
    with open_bench(
        "sim",
        resolution=(256, 192),
        scene_options={"background": grey, "falloff": 0.2, "keystone": 0.0},
    ) as bench:
        bench.camera.read_noise_e = 5.0  # the bench's own camera, not the default
        bench.camera.electrons_per_unit = 1.0e5
        sample = bench_for_target(bench, sample_layout(), seed=7)
        try:
            # the white board, the light field and the camera are the bench's
            np.testing.assert_allclose(
                sample.stage.materials.values[0],
                np.interp(sample.stage.materials.wavelength_nm, [380, 780], [0.6, 0.6]),
            )
            assert sample.stage.falloff == 0.2
            assert sample.stage.keystone == 0.0
            assert sample.camera.read_noise_e == 5.0
            assert sample.camera.electrons_per_unit == 1.0e5
            assert sample.camera.resolution == (256, 192)
            assert sample.truth["camera"]["seed"] == 7
            xy = np.array([[10.0, 20.0], [128.0, 96.0]])
            np.testing.assert_array_equal(
                sample.camera.shading(xy), bench.camera.shading(xy)
            )
            # only the target changed
            assert sample.stage.layout.name == sample_layout().name
        finally:
            sample.camera.close()
