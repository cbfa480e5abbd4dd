"""``tunespec gonio-run``: a gonio session on devices opened by spec.

The CAL1 emulator (the real CAL1 driver over TCP), the Zaber emulator (the real Zaber
ASCII driver over TCP) and the registry's simulated camera (rendering the sample
under the SPD the CAL1 reports, DNG files read back by the raw loader): the path a
real session takes, with no hardware.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from tests.helpers import without_progress
from tunespec.app.cli import main
from tunespec.app.pipeline import gonio_devices
from tunespec.app.pipeline.gonio import GeometryStep, GonioPlan, frame_names
from tunespec.core.colorimetry import delta_e_2000, lab_d50, xyz_to_lab_d50
from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.spectra import DEFAULT_GRID
from tunespec.devices.cal1.emulator import Cal1Emulator
from tunespec.devices.clock import VirtualClock
from tunespec.devices.goniometer import Geometry
from tunespec.devices.registry import open_bench
from tunespec.devices.sim.led_physics import LedPhysics
from tunespec.devices.zaber.emulator import ZaberEmulator

LAYOUT = resource_path("layouts", "neugebauer_cmy.json")


@pytest.fixture
def emulators():
    with (
        Cal1Emulator(physics=LedPhysics(clock=VirtualClock(), seed=0)) as cal1,
        ZaberEmulator(n_devices=4) as zaber,
    ):
        yield cal1, zaber
    assert cal1.errors == [] and not zaber.errors


def _plan(tmp_path):
    """4 geometries, 2 spectral, one with HDR brackets; light at normal incidence
    (the registry's simulated camera renders a matte target, no BRDF)."""
    steps = tuple(
        GeometryStep(Geometry(0.0, 0.0, t, 180.0), spectral=t in (10, 30), hdr=t == 20)
        for t in (10.0, 20.0, 30.0, 40.0)
    )
    path = tmp_path / "plan.json"
    GonioPlan(steps).save(path)
    return path


def _sensitivities(tmp_path):
    """Stand-in for 'tunespec calibrate': the simulated camera's absolute ones."""
    layout = TargetLayout.load(LAYOUT)
    with open_bench("sim", "sim", layout=layout, layout_path=LAYOUT) as bench:
        S = bench.camera.absolute_sensitivity()
    path = tmp_path / "cal.csv"
    write_spectra_csv(S, path)
    # the calibration's side file: per-LED corrections (here: none to make)
    leds = [{"name": f"LED{w}", "gain": 1.0, "shift_nm": 0.0} for w in (410, 420)]
    (tmp_path / "cal.csv.meta.json").write_text(
        json.dumps({"led_correction": {"common_shift_nm": 0.0, "leds": leds}})
    )
    return path


@pytest.mark.slow
def test_gonio_run_on_cal1_and_zaber_emulators_resumes_after_a_drop(
    tmp_path, emulators, monkeypatch, capsys
):
    cal1, zaber = emulators
    out = tmp_path / "s"
    args = ["gonio-run", "--out", str(out), "--light", cal1.spec, "--camera", "sim",
            "--gonio", zaber.spec(), "--layout", str(LAYOUT),
            "--resolution", "640x480"]  # fmt: skip
    new = [
        "--plan",
        str(_plan(tmp_path)),
        "--sensitivities",
        str(_sensitivities(tmp_path)),
    ]
    # the stage's connection drops on the move to g02 (after g00's 24 frames and 2
    # of g01's 4)
    capture, n = gonio_devices.DeviceGonioBench.capture, [0]

    def stalling(self, exposure, key=None):
        n[0] += 1
        if n[0] == 26:
            zaber.inject_fault("drop")
        return capture(self, exposure, key)

    monkeypatch.setattr(gonio_devices.DeviceGonioBench, "capture", stalling)
    assert main([*args, *new]) == 3
    err = without_progress(capsys.readouterr().err).splitlines()
    assert len(err) == 1 and "continue with --resume" in err[0]
    before = {p: p.read_bytes() for p in out.rglob("*.npy")}
    assert len(before) == 28 and not any("g02" in str(p) for p in before)
    assert main(args) == 2  # a session is there: --resume needed
    assert main([*args, "--resume", "--mix", "camera"]) == 2  # it keeps its mix
    capsys.readouterr()
    # ... and its ISO: frames at two gains would not share Eq. 1's scale
    assert main([*args, "--resume", "--iso", "200"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "camera.json" in err[0], err
    assert "frames are at ISO 100: resume it with --iso 100, not 200" in err[0]
    # the session kept its layout: --resume needs no --layout (issue 27)
    assert (out / "layout.json").exists()
    k = args.index("--layout")
    assert main([*args[:k], *args[k + 2 :], "--resume"]) == 0
    assert "4 geometries (2 spectral, d50 mix), 26 frames taken now" in (
        capsys.readouterr().out
    )
    plan = GonioPlan.load(out / "plan.json")
    n_total = sum(len(frame_names(s, [f"L{i}" for i in range(22)])) for s in plan.steps)
    assert len(list(out.rglob("*.npy"))) == n_total == 54
    assert len(list((out / "raw").glob("*.dng"))) == n_total  # every raw file kept
    for p, data in before.items():  # nothing taken before was taken again
        assert p.read_bytes() == data
    # the positions are the Zaber driver's read-back (steps of 1/128 deg ... )
    summary = json.loads((out / "summary.json").read_text())
    theta_r = [p["theta_r"] for p in summary["positions"]]
    assert theta_r == pytest.approx([10, 20, 30, 40], abs=0.01)
    corr = json.loads((out / "led_correction.json").read_text())  # kept, and used
    assert [d["name"] for d in corr["leds"]] == ["LED410", "LED420"]
    mix = json.loads((out / "mix.json").read_text())
    assert mix["mix"] == "d50" and mix["measured"]["delta_uv"] < 1e-3
    assert "/1 1 move abs" in " ".join(zaber.received)
    # ... and the numbers: the sample's model reflectances are the truth
    layout = TargetLayout.load(LAYOUT)
    truth = read_spectra_csv(resource_path("charts", "neugebauer_cmy_model.csv"))
    truth = truth.select(layout.patch_names).resample(DEFAULT_GRID)
    with xr.open_dataset(out / "gonio.nc", engine="scipy") as ds:
        R, xyz = ds.reflectance.values, ds.XYZ.values
        spectral = ds.spectral.values.astype(bool)
    rms = np.sqrt(np.mean((R - truth.values[:, None]) ** 2, axis=(0, 2)))
    de = delta_e_2000(xyz_to_lab_d50(xyz), lab_d50(truth)[:, None])
    # measured: spectral RMS 0.024 / 0.030, fused 0.044 / 0.033; single-shot mean
    # dE00 0.66-0.68 (no flat field in a gonio session: the scene's 10 % fall-off)
    assert rms[spectral].max() < 0.04 and rms[~spectral].max() < 0.06
    assert de.mean() < 1.0


class _RoundingCamera:
    """A camera with 1/3-stop shutter steps writing a DNG of a known mosaic."""

    exposure_s = 1.0

    def set_exposure(self, exposure_s):
        self.exposure_s = 2.0 ** (round(3 * np.log2(exposure_s)) / 3)

    def capture(self, stem):
        from tunespec.devices.dng import write_dng

        mosaic = np.full((24, 32), 2048 + 6476, np.uint16)  # half of full scale
        mosaic[0, 0] = 15000  # a saturated red site
        return write_dng(f"{stem}.dng", mosaic, black_level=2048, white_level=15000)


def test_device_frames_are_scaled_to_the_requested_exposure(tmp_path):
    bench = gonio_devices.DeviceGonioBench(None, None, _RoundingCamera(), tmp_path)
    frame = bench.capture(0.3, key=7)
    used = 2.0 ** (round(3 * np.log2(0.3)) / 3)  # 0.315 s
    assert frame.shape == (3, 12, 16) and (tmp_path / "frame_00000007.dng").exists()
    half = 6476 / (15000 - 2048)
    # a cell with a saturated site: full scale in every plane, whatever the scaling
    assert np.all(frame[:, 0, 0] == 1.0)
    rest = frame.reshape(3, -1)[:, 1:]
    assert rest == pytest.approx(np.full_like(rest, half * 0.3 / used), rel=1e-6)


def test_gonio_run_checks_its_inputs_before_writing_anything(tmp_path, capsys):
    out = tmp_path / "s"
    base = ["gonio-run", "--out", str(out), "--layout", str(LAYOUT)]
    assert main(base) == 2  # a new session: plan and sensitivities needed
    assert main([*base, "--plan", str(_plan(tmp_path)),
                 "--sensitivities", str(tmp_path / "none.csv")]) == 2  # fmt: skip
    assert main([*base, "--iso", "7"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3
    assert "needs --plan and --sensitivities" in err[0] and "none.csv" in err[1]
    assert "--iso" in err[2]
    assert not out.exists() or not (out / "plan.json").exists()


def test_a_processing_failure_names_the_geometry_and_its_folder(tmp_path):
    """A target not found at one geometry: the message says which (issue 27: the
    full-resolution run stopped on "could not follow one of the target's sides")."""
    from tunespec.app.pipeline.gonio_process import process_gonio

    layout = TargetLayout.load(LAYOUT)
    plan = GonioPlan.load(_plan(tmp_path))
    out = tmp_path / "s"
    out.mkdir()
    plan.save(out / "plan.json")
    rng = np.random.default_rng(0)
    for i, step in enumerate(plan.steps):
        gdir = out / plan.folder(i)
        gdir.mkdir()
        g = step.geometry.as_dict()
        (gdir / "position.json").write_text(json.dumps(g))
        for n, k in frame_names(step, ["L0"]):  # featureless frames: no target
            frame = rng.uniform(0.0, 0.01, (3, 48, 64)).astype(np.float32)
            np.save(gdir / f"{n}_e{k}.npy", frame)
    S = read_spectra_csv(_sensitivities(tmp_path), allow_negative=True)
    with pytest.raises(InputError) as err:
        process_gonio(out, S.resample(DEFAULT_GRID), layout, S.resample(DEFAULT_GRID))
    assert str(err.value).startswith(
        f"geometry 1 (theta_i 0, theta_r 10), {plan.folder(0)}: "
    )


def test_gonio_run_resume_uses_the_sessions_own_layout(tmp_path, capsys):
    """--resume without --layout reads the session's layout.json; a different
    --layout is refused (checked before any device is opened)."""
    out = tmp_path / "s"
    out.mkdir()
    GonioPlan.load(_plan(tmp_path)).save(out / "plan.json")
    TargetLayout.load(LAYOUT).save(out / "layout.json")
    other = tmp_path / "other.json"
    other.write_text(
        json.dumps({**TargetLayout.load(LAYOUT).to_dict(), "width_mm": 99.0})
    )
    base = ["gonio-run", "--out", str(out), "--resume"]
    assert main(base) == 2  # past the layout: the calibration is what is missing
    assert main([*base, "--layout", str(other)]) == 2
    assert main([*base, "--layout", str(LAYOUT)]) == 2  # the same layout: accepted
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3
    assert "no calibration.csv yet" in err[0] and "--layout" not in err[0]
    assert "uses its own layout.json" in err[1] and "other.json" in err[1]
    assert "no calibration.csv yet" in err[2]


def test_a_session_keeps_the_sensor_bend_its_calibration_undid(tmp_path):
    """gonio-run linearises every frame as the chart's were: the calibration's
    ``linearity_gamma`` is kept with the session (``excess_variance.json``) and
    reaches a resumed session, which is given no side file."""
    from tunespec.core.calibration import excess_from_meta
    from tunespec.core.excess import ExcessVariance

    S = read_spectra_csv(_sensitivities(tmp_path))
    side = {
        "excess_variance": ExcessVariance(0.001, 0.0, linearity_gamma=0.02).as_dict()
    }
    first, corr = gonio_devices._session_calibration(tmp_path, S, None, side)
    assert corr is None
    assert excess_from_meta(first.meta).linearity_gamma == 0.02
    resumed, _ = gonio_devices._session_calibration(tmp_path, S, None, {})
    assert excess_from_meta(resumed.meta).linearity_gamma == 0.02
    (tmp_path / "excess_variance.json").write_text('{"linearity_gamma": "0.02"}')
    again, _ = gonio_devices._session_calibration(tmp_path, S, None, {})
    bad = r"excess_variance\.json: excess_variance\.linearity_gamma = '0\.02': expected"
    with pytest.raises(InputError, match=bad):
        excess_from_meta(again.meta)
