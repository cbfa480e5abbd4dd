"""Multi-geometry sessions: BRDF bench, plan, kill/resume, processing and fusion."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.helpers import without_progress
from tunespec.app.cli import main
from tunespec.app.pipeline.gonio import GonioPlan, default_plan, frame_names
from tunespec.app.pipeline.gonio_bench import open_gonio_bench, run_gonio_demo
from tunespec.core.colorimetry import (
    astm_e308_weights_d50,
    xyz_d50,
    xyz_to_lab_d50,
)
from tunespec.core.errors import InputError
from tunespec.core.fusion import fuse_patch, fused_covariance
from tunespec.core.homography import locate_target
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import apply_homography
from tunespec.core.spectra import DEFAULT_GRID
from tunespec.devices.goniometer import Geometry
from tunespec.devices.protocols import DeviceConnectionError
from tunespec.devices.sim.gonio import (
    brdf_reflectance_factor,
    ggx_specular,
    view_homography,
)


def test_ggx_lobe_is_normalised_and_peaks_at_the_mirror_direction():
    # the GGX distribution integrates to 1 over the projected hemisphere of h
    a = 0.2
    th = np.linspace(0, np.pi / 2, 20001)
    c = np.cos(th)
    d = a**2 / (np.pi * (c**2 * (a**2 - 1) + 1) ** 2)
    assert np.trapezoid(d * c * np.sin(th), th) * 2 * np.pi == pytest.approx(
        1, abs=1e-4
    )
    lobe = [ggx_specular(Geometry(45, 0, t, 180), [0.2])[0] for t in range(0, 80, 5)]
    # the reflectance factor's 1 / (cos i cos r) moves the peak a little off-mirror
    assert 45 <= 5 * int(np.argmax(lobe)) <= 55
    assert lobe[9] > 10 * lobe[0]
    # reciprocity: swapping light and camera changes nothing
    g, swapped = Geometry(30, 0, 60, 150), Geometry(60, 150, 30, 0)
    assert ggx_specular(g, [0.3]) == pytest.approx(ggx_specular(swapped, [0.3]))
    # far from the lobe: the body colour times the Fresnel transmission
    rho = np.full((1, 5), 0.5)
    R = brdf_reflectance_factor(rho, [0.1], Geometry(45, 0, 0, 0))
    assert pytest.approx(rho, rel=0.01) == R


@pytest.mark.slow
def test_projective_view_and_corners_refound():
    g0 = Geometry(45, 0, 0, 0)
    H = view_homography(g0, (320, 200), 2.0)
    c = apply_homography(H, np.array([[-50.0, -25.0], [50.0, 25.0]]))
    np.testing.assert_allclose(c, [[60.0, 50.0], [260.0, 150.0]], atol=1e-9)
    g60 = Geometry(45, 0, 60, 180)
    c60 = apply_homography(
        view_homography(g60, (320, 200), 2.0), np.array([[-50.0, 0], [50.0, 0]])
    )
    assert (c60[1, 0] - c60[0, 0]) / 200.0 == pytest.approx(
        np.cos(np.radians(60)), rel=0.02
    )
    bench = open_gonio_bench(seed=3)
    bench.gonio.home()
    bench.light.set_levels(np.full(22, 0.2))
    for g in (
        g0,
        Geometry(45, 0, 35, 180),
        Geometry(45, 0, 70, 180),
        Geometry(45, 0, 30, 90),
    ):
        bench.gonio.move_to(g.as_dict())
        frame = bench.capture(0.05)
        corners, _ = locate_target(frame[1], bench.layout)
        assert np.abs(corners - bench.corners_px(g)).max() < 0.5  # pixels


def test_plan_round_trip_and_one_line_errors(tmp_path):
    plan = default_plan(14)
    assert len(plan.steps) == 14 and sum(s.spectral for s in plan.steps) == 3
    plan.save(tmp_path / "p.json")
    assert GonioPlan.load(tmp_path / "p.json") == plan
    doc = plan.to_dict()
    doc["geometries"][2]["theta_r"] = 95
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"bad.json: geometries\[2\]: theta_r = 95"):
        GonioPlan.load(tmp_path / "bad.json")
    doc["geometries"][2]["theta_r"] = 10
    doc["geometries"][3]["hdr"] = "yes"
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"geometries\[3\]: spectral and hdr"):
        GonioPlan.load(tmp_path / "bad.json")
    names = frame_names(plan.steps[6], ["A", "B"])  # spectral and HDR
    assert (
        names[:4] == [("dark", 0), ("mix", 0), ("mix", 1), ("mix", 2)]
        and len(names) == 10
    )


def test_fusion_reproduces_the_measured_xyz_and_recovers_a_glossy_spectrum():
    wl = DEFAULT_GRID.wavelength_nm
    rho = 0.2 + 0.6 * np.exp(-0.5 * ((wl - 600) / 40) ** 2)
    spectral = np.array([rho + 0.02, rho + 0.4, rho + 1.5])  # three geometries
    truth = rho + 0.7  # another geometry: same body, other surface reflection
    M = np.random.default_rng(0).uniform(0, 1, (3, wl.size)) * 1e-3
    xyz = xyz_d50(truth, wl)
    f = fuse_patch(M @ truth, xyz, spectral, M, wl)
    assert xyz_d50(f.reflectance, wl) == pytest.approx(xyz, abs=1e-8)
    assert np.abs(f.reflectance - truth).max() < 1e-6
    # a measured XYZ off by 1 %: reproduced exactly, the spectrum stays close
    f2 = fuse_patch(M @ truth, xyz * 1.01, spectral, M, wl)
    assert xyz_d50(f2.reflectance, wl) == pytest.approx(xyz * 1.01, abs=1e-8)
    assert np.sqrt(np.mean((f2.reflectance - truth) ** 2)) < 0.02


def test_fused_spectrum_covariance_carries_the_xyz_covariance():
    """cov(R) = G cov(XYZ) G^T + P cov(R0) P^T: its colour is the single shot's
    (W^T cov W = cov(XYZ)) and, with a certain XYZ, the prior's part is invisible
    to the colour matching functions; checked against Monte Carlo fusions."""
    wl = DEFAULT_GRID.wavelength_nm
    rho = 0.2 + 0.6 * np.exp(-0.5 * ((wl - 600) / 40) ** 2)
    spectral = np.array([rho + 0.02, rho + 0.4])
    W = astm_e308_weights_d50(wl)
    kx = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.02], [0.0, 0.02, 0.25]])
    k0 = np.full(wl.size, 1e-4)
    K = fused_covariance(spectral, wl, kx, k0)
    np.testing.assert_allclose(W.T @ K @ W, kx, rtol=1e-6, atol=1e-9)
    K0 = fused_covariance(spectral, wl, np.zeros((3, 3)), k0)
    np.testing.assert_allclose(W.T @ K0 @ W, 0.0, atol=1e-9)
    # the prior's part, projected along the colour matching functions: of its size
    assert 0.5e-4 < np.diagonal(K0).min() <= np.diagonal(K0).max() < 2e-4
    # Monte Carlo: fuse noisy XYZ with the same prior (a linear map of the XYZ)
    truth = rho + 0.3
    M = np.random.default_rng(0).uniform(0, 1, (3, wl.size)) * 1e-3
    xyz = xyz_d50(truth, wl)
    rng = np.random.default_rng(1)
    draws = rng.multivariate_normal(xyz, kx, 400)
    fused = np.array([fuse_patch(M @ truth, x, spectral, M, wl).reflectance
                      for x in draws])  # fmt: skip
    Kx_only = fused_covariance(spectral, wl, kx, np.zeros(wl.size))
    np.testing.assert_allclose(
        fused.std(axis=0), np.sqrt(np.diagonal(Kx_only)), rtol=0.15
    )
    with pytest.raises(InputError):
        fused_covariance(spectral, wl, np.eye(2), k0)


@pytest.mark.slow
def test_fourteen_geometry_session_end_to_end(tmp_path):
    import xarray as xr

    s = run_gonio_demo(tmp_path, n_geometries=14, seed=0)
    assert s["n_geometries"] == 14 and s["n_spectral"] == 3
    # measured (seed 0): full captures RMS 0.061, fused 0.069 (1.12x); fused D50
    # colorimetry mean 0.384 dE00 (full captures 0.21)
    assert s["rms_ratio_fused_to_full"] <= 1.5
    assert s["de00_fused_mean"] <= 0.5
    assert s["de00_full_captures_mean"] <= 0.3
    with xr.open_dataset(tmp_path / "gonio.nc", engine="scipy") as ds:
        assert ds.reflectance.shape == (8, 14, 71)
        assert list(ds.theta_r.values[:3]) == [0.0, 10.0, 20.0]
        fused = ds.spectral.values == 0
        lab = xyz_to_lab_d50(ds.XYZ.values[:, fused])
        assert ds.Lab.values[:, fused] == pytest.approx(lab, abs=1e-3)  # XYZ reproduced
        assert ds.reflectance.values.min() >= 0.0
        # a standard uncertainty at every geometry (issue 28: NaN at 11 of 14)
        u = ds.u_reflectance.values
        assert np.isfinite(u).all() and (u > 0).all()
        assert np.isfinite(ds.u_Lab.values).all() and (ds.u_Lab.values > 0).all()
        # fused spectra are as uncertain in colour as the single shot's XYZ: u(L*)
        # is dL*/dY u(Y) (L* = 116 (Y/100)^(1/3) - 16, Y/100 > 0.008856 here)
        Y, u_Y = ds.XYZ.values[:, fused, 1], ds.u_XYZ.values[:, fused, 1]
        assert Y.min() > 0.9
        dL_dY = 116.0 / 300.0 * (Y / 100.0) ** (-2.0 / 3.0)
        np.testing.assert_allclose(ds.u_Lab.values[:, fused, 0], dL_dY * u_Y, rtol=1e-4)
        assert ds.u_reflectance.attrs["units"] == "1"
        assert ds.wavelength.attrs["units"] == "nm"
        assert ds.theta_r.attrs["units"] == "degree"
        assert "tunespec" in ds.attrs["history"] and ds.attrs["Conventions"]
    plan = GonioPlan.load(tmp_path / "plan.json")
    refl = read_spectra_csv(tmp_path / plan.folder(5) / "reflectance.csv")
    assert len(refl) == 8 and (tmp_path / "angles.png").stat().st_size > 10_000


@pytest.mark.slow
def test_killed_session_resumes_at_the_geometry_without_losing_a_frame(tmp_path):
    plan = default_plan(6)
    plan.save(tmp_path / "plan.json")
    with pytest.raises(DeviceConnectionError):
        run_gonio_demo(tmp_path, seed=1, fail_after_moves=4)  # dies moving to g03
    before = {
        p: (p.stat().st_mtime_ns, p.read_bytes()) for p in tmp_path.rglob("*.npy")
    }
    assert before and not any("g03" in str(p) for p in before)
    n_total = sum(len(frame_names(s, [f"x{i}" for i in range(22)])) for s in plan.steps)
    assert len(before) < n_total
    s = run_gonio_demo(tmp_path, seed=1, scheduler="threads")  # processed on Dask
    after = list(tmp_path.rglob("*.npy"))
    assert len(after) == n_total  # every frame, once
    for p, (mtime, data) in before.items():  # nothing taken before was taken again
        assert p.stat().st_mtime_ns == mtime and p.read_bytes() == data
    assert s["n_geometries"] == 6
    # processing one geometry after another gives the same numbers
    assert run_gonio_demo(tmp_path, seed=1) == s


@pytest.mark.slow
def test_cli_kill_and_resume(tmp_path, capsys):
    out = tmp_path / "g"
    args = ["gonio-demo", "--out", str(out), "--geometries", "4", "--seed", "2"]
    assert main([*args, "--fail-after-moves", "3"]) == 3
    err = without_progress(capsys.readouterr().err)
    assert "continue with --resume" in err and len(err.splitlines()) == 1
    assert main(args) == 2  # the folder holds a session: --resume is required
    assert main([*args, "--resume"]) == 0
    assert "4 geometries (2 spectral)" in capsys.readouterr().out


@pytest.mark.slow
def test_brackets_on_a_tone_curve_are_warned_of_by_geometry(tmp_path, capsys):
    """A geometry whose HDR brackets do not scale with their exposures (frames on
    c^1.1, as a JPEG's would be) is named on the console, in summary.json and in
    gonio.nc; the simulated bench's own frames give no warning."""
    from tunespec.app.pipeline.gonio_view import load_gonio_result

    out = tmp_path / "g"
    args = ["gonio-demo", "--out", str(out), "--geometries", "5", "--seed", "3"]
    assert main(args) == 0
    assert "warning" not in without_progress(capsys.readouterr().err)
    assert load_gonio_result(out)["warnings"] == []
    gdir = out / default_plan(5).folder(3)  # theta_r 30: the first HDR geometry
    dark = np.load(gdir / "dark_e0.npy")
    for path in gdir.glob("mix_e*.npy"):
        frame = np.load(path)
        np.save(path, (np.maximum(frame - dark, 0) ** 1.1 + dark).astype(frame.dtype))
    assert main([*args, "--resume"]) == 0
    err = without_progress(capsys.readouterr().err).splitlines()
    said = [line for line in err if line.startswith("warning: ")]
    assert len(said) == 1, err
    assert said[0].startswith(
        f"warning: geometry 4 (theta_i 45, theta_r 30), {gdir.name}: its exposure "
        "brackets bend as response^(1 + gamma) with gamma +0.10"
    )
    summary = json.loads((out / "summary.json").read_text())
    assert summary["warnings"] == load_gonio_result(out)["warnings"] == [said[0][9:]]


@pytest.mark.slow
def test_a_plan_without_brackets_says_its_frames_were_not_checked(tmp_path, capsys):
    """Without an HDR geometry nothing checks the frames' linearity: the session
    says so once, on the console and in summary.json, and still exits 0."""
    from tunespec.core.plausibility import NO_BRACKETS_WARNING

    plan = tmp_path / "plan.json"
    assert main(["gonio-plan", "-o", str(plan), "--theta-r", "0,10,20",
                 "--spectral", "0,20", "--hdr-from", "90"]) == 0  # fmt: skip
    out = tmp_path / "g"
    assert main(["gonio-demo", "--out", str(out), "--plan", str(plan)]) == 0
    err = without_progress(capsys.readouterr().err).splitlines()
    assert [line for line in err if line.startswith("warning: ")] == [
        f"warning: {NO_BRACKETS_WARNING}"
    ]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["warnings"] == [NO_BRACKETS_WARNING]


def test_cli_writes_a_plan_and_refuses_bad_angles(tmp_path, capsys):
    out = tmp_path / "p.json"
    rc = main(["gonio-plan", "-o", str(out), "--theta-r", "0,15,30,45,60",
               "--spectral", "0,45", "--off-plane", "30:90", "--hdr-from", "30"])  # fmt: skip
    assert rc == 0
    plan = GonioPlan.load(out)
    assert [s.geometry.theta_r for s in plan.steps] == [0, 15, 30, 45, 60, 30]
    assert [s.spectral for s in plan.steps] == [True, False, False, True, False, False]
    assert [s.hdr for s in plan.steps] == [False, False, True, True, True, True]
    assert (
        main(["gonio-plan", "-o", str(out), "--theta-r", "0,95", "--spectral", "0"])
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "theta_r = 95 deg outside" in err[0]


def test_fusion_reaches_an_xyz_the_basis_cannot_reach_without_going_negative():
    wl = DEFAULT_GRID.wavelength_nm
    green = 0.05 + 0.8 * np.exp(-0.5 * ((wl - 530) / 25) ** 2)
    red = 0.03 + 0.9 / (1 + np.exp(-(wl - 610) / 10))
    M = np.random.default_rng(1).uniform(0, 1, (3, wl.size)) * 1e-3
    # spectral captures of a green, and a single shot that measured a red
    f = fuse_patch(M @ red, xyz_d50(red, wl), np.array([green, green + 0.3]), M, wl)
    assert f.reflectance.min() >= 0.0
    assert xyz_d50(f.reflectance, wl) == pytest.approx(xyz_d50(red, wl), abs=1e-4)
