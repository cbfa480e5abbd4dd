"""SimCamera, SimScene and the DNG writer: numbers against the forward model (Eq. 1)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rawpy

from tests.devices.camera_fixtures import StubLight
from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
from tunespec.core.forward_model import render_rgb
from tunespec.core.io.raw import full_to_plane_px, load_raw, plane_to_full_px, quad_mask
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout, apply_homography
from tunespec.core.spectra import Spectra
from tunespec.devices.clock import VirtualClock
from tunespec.devices.dng import CANON_5D_MARK_III_COLOR_MATRIX, write_dng
from tunespec.devices.protocols import DeviceCommandError, TargetStage
from tunespec.devices.sim.camera import (
    DEFAULT_ELECTRONS_PER_UNIT,
    NOMINAL_PEAK_RADIANCE_W_SR_M2_NM,
    SimCamera,
    camera_constant_for,
)
from tunespec.devices.sim.led_physics import PEAK_RADIANCE_W_SR_M2_NM
from tunespec.devices.sim.light import SimLightSource
from tunespec.devices.sim.scene import SimScene

#: A simulated ROI mean must be within this many predicted standard errors of Eq. 1.
N_SIGMA = 4.5
RESOLUTION = (1536, 1024)


def _camera(light=None, scene=None, **kw) -> SimCamera:
    scene = scene or SimScene.colorchecker_sg()
    return SimCamera(light, scene, resolution=kw.pop("resolution", RESOLUTION), **kw)


def _site_shading(cam: SimCamera, mask: np.ndarray, x0: int, y0: int) -> np.ndarray:
    """Mean shading of R, G, B photosites over the plane pixels of ``mask``."""
    rows, cols = np.nonzero(mask)
    u, v = cols + x0, rows + y0
    per_site = {
        (dy, dx): cam.shading(np.stack([2 * u + dx, 2 * v + dy], axis=-1)).mean()
        for dy in (0, 1)
        for dx in (0, 1)
    }
    return np.array(
        [per_site[0, 0], 0.5 * (per_site[0, 1] + per_site[1, 0]), per_site[1, 1]]
    )


def _expected_planes(cam: SimCamera, spd: Spectra) -> tuple:
    """Eq. 1 per patch ROI, with the same pixels as ``frame.roi_stats``, and its sigma."""
    truth = cam.truth()
    layout: TargetLayout = truth["layout"]
    quads = full_to_plane_px(layout.roi_quads_px())
    refl = truth["reflectances"].select(layout.patch_names)
    sens = truth["sensitivity"]
    spd = spd.resample(cam.render_grid)
    rgb = render_rgb(refl.values, spd.values, sens.values, sens.step_nm)[:, 0, :]
    t = cam.exposure_s
    gain = cam.gain_dn_per_e
    scale = cam.white_level - cam.black_level
    expected = np.empty((len(quads), 3))
    sigma = np.empty((len(quads), 3))
    for i, q in enumerate(quads):
        x0, y0 = int(np.floor(q[:, 0].min())), int(np.floor(q[:, 1].min()))
        w = int(np.ceil(q[:, 0].max())) + 1 - x0
        h = int(np.ceil(q[:, 1].max())) + 1 - y0
        mask = quad_mask(q, x0, y0, w, h)
        n = mask.sum()
        electrons = (
            t * cam.electrons_per_unit * rgb[i] * _site_shading(cam, mask, x0, y0)
        )
        electrons += t * cam.dark_current_e_per_s
        expected[i] = electrons * gain / scale
        # per photosite: shot + read noise, plus quantisation; G averages two sites
        var_dn = gain**2 * (electrons + cam.read_noise_e**2) + 1.0 / 12.0
        var_dn[1] /= 2.0
        sigma[i] = np.sqrt(var_dn / n) / scale
    return expected, sigma


# -- the forward model, end to end -----------------------------------------------
@pytest.mark.parametrize(
    ("channel", "exposure_s"), [("WHITE_WARM", 6.0), ("LED450", 6.0)]
)
def test_patch_means_follow_eq1(
    tmp_path: Path, channel: str, exposure_s: float
) -> None:
    light = StubLight(channel)
    cam = _camera(light, exposure_s=exposure_s)
    frame = load_raw(cam.capture(tmp_path / "target"))
    truth = cam.truth()
    stats = frame.roi_stats(full_to_plane_px(truth["layout"].roi_quads_px()))
    expected, sigma = _expected_planes(cam, light.emitted_spd())
    assert stats.n_saturated.sum() == 0
    assert stats.n_pixels.min() > 100
    z = (stats.mean - expected) / sigma
    assert np.abs(z).max() < N_SIGMA, np.abs(z).max()
    # and the spread is the predicted one (a biased model would inflate it)
    assert 0.7 < np.mean(z**2) < 1.3


def test_with_the_simulated_light_source(tmp_path: Path) -> None:
    """SimLightSource drives the camera: same clock, SPD integrated over the exposure."""
    light = SimLightSource(seed=2)  # just switched on: warming up, drifting
    names = [c.name for c in light.channels()]
    light.set_levels(np.array([n == "LED525" for n in names], dtype=float))
    cam = _camera(light, exposure_s=6.0)
    assert cam._clock is light.clock
    t0_s = light.clock.now_s()
    frame = load_raw(cam.capture(tmp_path / "led525"))
    assert light.clock.now_s() == pytest.approx(t0_s + 6.0)
    stats = frame.roi_stats(full_to_plane_px(cam.truth()["layout"].roi_quads_px()))
    expected, sigma = _expected_planes(cam, light.emitted_spd_over(t0_s, t0_s + 6.0))
    z = (stats.mean - expected) / sigma
    assert np.abs(z).max() < N_SIGMA
    # the nominal light scale and the camera's default constant agree
    assert NOMINAL_PEAK_RADIANCE_W_SR_M2_NM == PEAK_RADIANCE_W_SR_M2_NM
    assert 0.1 < stats.mean[:, 1].max() < 0.9


def test_pixel_noise_is_shot_plus_read_noise(tmp_path: Path) -> None:
    """Photon transfer: the difference of two equal frames has sqrt(2) x pixel noise."""
    light = StubLight("WHITE_COOL")
    scene = SimScene.colorchecker_sg(presented="white")
    cam = _camera(light, scene, exposure_s=3.0)
    a = load_raw(cam.capture(tmp_path / "a")).planes_in(200, 300, 300, 400)
    b = load_raw(cam.capture(tmp_path / "b")).planes_in(200, 300, 300, 400)
    noise = (a - b).astype(np.float64).std(axis=(1, 2)) / np.sqrt(2)
    signal = 0.5 * (a + b).astype(np.float64).mean(axis=(1, 2))
    scale = cam.white_level - cam.black_level
    electrons = signal * scale / cam.gain_dn_per_e
    var_dn = cam.gain_dn_per_e**2 * (electrons + cam.read_noise_e**2) + 1 / 12
    predicted = np.sqrt(var_dn * np.array([1.0, 0.5, 1.0])) / scale
    # 10^4 pixel pairs: the std is known to ~1 %
    np.testing.assert_allclose(noise, predicted, rtol=0.04)


def test_brightest_patch_fills_half_to_ninety_percent() -> None:
    """The calibration constant: nominal LED set at level 1, 6 s, ISO 100."""
    leds = load_led_set()
    leds = leds.with_values(leds.values * NOMINAL_PEAK_RADIANCE_W_SR_M2_NM)
    sg = load_colorchecker_sg()
    sens = load_camera()
    rgb = render_rgb(sg.values, leds.values, sens.values, sens.step_nm)
    cam = _camera(exposure_s=6.0)
    electrons = 6.0 * DEFAULT_ELECTRONS_PER_UNIT * rgb.max()
    fill_centre = electrons / cam.full_well_e
    assert 0.5 < fill_centre < 0.9
    # where N10 (the brightest) actually sits in the default scene
    layout = cam.truth()["layout"]
    n10 = layout.patch_names.index("N10")
    centre = apply_homography(layout.homography(), layout.patch_centers_mm()[n10])
    assert 0.5 < fill_centre * cam.shading(centre) < 0.9
    # camera_constant_for inverts it
    k = camera_constant_for(leds.select(["WHITE_WARM"]), sens, float(sg.values.max()))
    assert k == pytest.approx(0.75 * 67000 / (6.0 * rgb[:, 21].max()), rel=0.05)


# -- dark frames, saturation ---------------------------------------------------------
@pytest.mark.parametrize("exposure_s", [6.0, 120.0])
def test_dark_frame_is_black_level_plus_dark_current(
    tmp_path: Path, exposure_s
) -> None:
    cam = _camera(StubLight(None), exposure_s=exposure_s)
    frame = load_raw(cam.capture(tmp_path / "dark"))
    dn = frame.mosaic.astype(np.float64)
    dark_e = cam.dark_current_e_per_s * exposure_s
    expected_dn = cam.black_level + dark_e * cam.gain_dn_per_e
    sigma_px = np.sqrt(cam.gain_dn_per_e**2 * (dark_e + cam.read_noise_e**2) + 1 / 12)
    assert abs(dn.mean() - expected_dn) < N_SIGMA * sigma_px / np.sqrt(dn.size)
    assert dn.std() == pytest.approx(sigma_px, rel=0.02)
    assert frame.black_level == cam.black_level
    np.testing.assert_allclose(
        frame.planes.mean(axis=(1, 2)),
        dark_e * cam.gain_dn_per_e / (cam.white_level - cam.black_level),
        atol=N_SIGMA * sigma_px / np.sqrt(dn.size / 4) / 12952,
    )


def test_dark_current_grows_with_exposure() -> None:
    cam = _camera(None)
    means = []
    for t in (10.0, 1000.0):
        cam.set_exposure(t)
        means.append(cam.render(None).mean() - cam.black_level)
    ratio_expected = 1000.0 / 10.0
    assert means[1] / means[0] == pytest.approx(ratio_expected, rel=0.1)


def test_overexposure_clips_at_the_white_level(tmp_path: Path) -> None:
    cam = _camera(StubLight("WHITE_WARM"), exposure_s=30.0)
    frame = load_raw(cam.capture(tmp_path / "hot"))
    assert frame.mosaic.max() == cam.white_level
    sat = frame.saturated
    assert 0.05 < sat.mean() < 1.0
    # clipped cells read full scale in their saturated channel
    assert frame.planes[1][sat].max() == pytest.approx(1.0)
    assert np.all(frame.planes <= 1.0 + 1e-6)


def test_iso_scales_the_gain() -> None:
    cam = _camera(StubLight("LED525"), exposure_s=2.0)
    spd = load_led_set()["LED525"] * NOMINAL_PEAK_RADIANCE_W_SR_M2_NM
    cam.set_iso(100)
    low = cam.render(spd).astype(float).mean() - cam.black_level
    cam.set_iso(400)
    high = cam.render(spd).astype(float).mean() - cam.black_level
    assert high / low == pytest.approx(4.0, rel=0.02)


# -- scene geometry ---------------------------------------------------------------------
def test_scene_is_a_target_stage_and_corners_are_a_perspective_quad() -> None:
    scene = SimScene.colorchecker_sg()
    assert isinstance(scene, TargetStage)
    c = scene.corners_px(*RESOLUTION)
    top = np.linalg.norm(c[1] - c[0])
    bottom = np.linalg.norm(c[2] - c[3])
    assert bottom / top == pytest.approx((1 + 0.02) / (1 - 0.02), rel=1e-9)
    # not a parallelogram: a homography, not an affine map, is needed
    assert not np.allclose(c[1] - c[0], c[2] - c[3], atol=1.0)
    with pytest.raises(ValueError, match="'white' or 'target'"):
        scene.present("chart")  # type: ignore[arg-type]


def test_patch_centres_are_labelled_with_their_patch() -> None:
    scene = SimScene.colorchecker_sg()
    w, h = RESOLUTION
    layout = scene.layout_px(w, h)
    centres = apply_homography(layout.homography(), layout.patch_centers_mm())
    xs, ys = np.round(centres[:, 0]), np.round(centres[:, 1])
    labels = np.array(
        [
            scene.labels(np.array([x]), np.array([y]), w, h)[0, 0]
            for x, y in zip(xs, ys, strict=True)
        ]
    )
    np.testing.assert_array_equal(labels, np.arange(140) + 2)
    # gaps between patches and the frame are frame (1), far outside is background
    gap = apply_homography(layout.homography(), [[layout.margin_mm[0] + 0.2, 50.0]])[0]
    assert scene.labels(np.array([gap[0]]), np.array([gap[1]]), w, h)[0, 0] == 1
    assert scene.labels(np.array([5.0]), np.array([5.0]), w, h)[0, 0] == 0
    scene.present("white")
    assert not scene.labels(np.arange(0, w, 7.0), np.arange(0, h, 7.0), w, h).any()


def test_falloff_is_about_ten_percent_at_the_chart_margin() -> None:
    scene = SimScene.colorchecker_sg()
    w, h = RESOLUTION
    c = scene.corners_px(w, h)
    centre = np.array(
        [scene.falloff_centre_frac[0] * w - 0.5, scene.falloff_centre_frac[1] * h - 0.5]
    )
    assert scene.irradiance(centre[0], centre[1], w, h) == pytest.approx(1.0)
    drop = 1 - scene.irradiance(c[:, 0], c[:, 1], w, h)
    assert 0.06 < drop.max() < 0.14


def test_white_frame_is_the_board_times_shading(tmp_path: Path) -> None:
    light = StubLight("WHITE_COOL")
    scene = SimScene.colorchecker_sg()
    cam = _camera(light, scene, exposure_s=4.0)
    scene.present("white")
    frame = load_raw(cam.capture(tmp_path / "white"))
    # a 50 x 50 plane window anywhere: mean = Eq. 1 for the board x mean shading
    board = scene.materials.select(["background"]).values
    sens = cam.sensitivity
    rgb = render_rgb(board, light.emitted_spd().values, sens.values, sens.step_nm)[0, 0]
    for x0, y0 in ((20, 20), (350, 250), (700, 450)):
        mask = np.ones((50, 50), dtype=bool)
        e = cam.exposure_s * (
            cam.electrons_per_unit * rgb * _site_shading(cam, mask, x0, y0)
            + cam.dark_current_e_per_s
        )
        expected = e * cam.gain_dn_per_e / (cam.white_level - cam.black_level)
        got = frame.planes_in(y0, y0 + 50, x0, x0 + 50).mean(axis=(1, 2))
        np.testing.assert_allclose(got, expected, rtol=2e-3)


def test_neugebauer_sample_target(tmp_path: Path) -> None:
    scene = SimScene.neugebauer_cmy()
    cam = _camera(StubLight("WHITE_WARM"), scene, exposure_s=6.0)
    frame = load_raw(cam.capture(tmp_path / "cmy"))
    layout = cam.truth()["layout"]
    stats = frame.roi_stats(full_to_plane_px(layout.roi_quads_px()))
    assert layout.n_patches == 8 and stats.n_pixels.min() > 50
    names = list(layout.patch_names)
    g = stats.mean[:, 1]
    assert g[names.index("C0M0Y0")] == g.max()  # bare substrate is the brightest
    assert g[names.index("C1M1Y1")] == g.min()


# -- camera settings, clock, truth ----------------------------------------------------------
def test_capture_advances_the_virtual_clock_and_integrates_drift(
    tmp_path: Path,
) -> None:
    clock = VirtualClock()
    light = StubLight("LED525", clock=clock, drift_per_s=0.01)
    drifting = _camera(light, clock=clock, exposure_s=10.0, seed=1)
    a = load_raw(drifting.capture(tmp_path / "drift")).planes.mean()
    assert clock.now_s() == pytest.approx(10.0)
    # the frame sees the mean output over the exposure: factor 1.05 for 0 ... 10 s
    stable = _camera(StubLight("LED525", level=1.05), exposure_s=10.0, seed=1)
    b = load_raw(stable.capture(tmp_path / "stable")).planes.mean()
    assert a == pytest.approx(b, rel=1e-3)


def test_settings_are_validated() -> None:
    cam = _camera()
    cam.set_exposure(1 / 8000)
    cam.set_iso(6400)
    assert (cam.exposure_s, cam.iso) == (1 / 8000, 6400)
    for bad in (0.0, -1.0, float("nan"), 1e6):
        with pytest.raises(DeviceCommandError, match="exposure"):
            cam.set_exposure(bad)
    for bad_iso in (0, 25, 100.5, 10**6):
        with pytest.raises(DeviceCommandError, match="ISO"):
            cam.set_iso(bad_iso)
    with pytest.raises(ValueError, match="even"):
        _camera(resolution=(101, 64))


def test_truth_is_written_beside_the_session(tmp_path: Path) -> None:
    cam = _camera(exposure_s=6.0)
    paths = cam.write_truth(tmp_path / "truth")
    assert [p.name for p in paths] == [
        "truth_sensitivity.csv",
        "truth_sensitivity_absolute.csv",
        "truth_reflectances.csv",
        "truth_layout.json",
        "truth.json",
    ]
    sens = read_spectra_csv(paths[0])
    np.testing.assert_array_equal(sens.values, cam.sensitivity.values)
    absolute = read_spectra_csv(paths[1])
    k = cam.electrons_per_unit * cam.gain_dn_per_e / (cam.white_level - cam.black_level)
    np.testing.assert_allclose(absolute.values, cam.sensitivity.values * k, rtol=1e-12)
    refl = read_spectra_csv(paths[2])
    assert refl.names[:3] == ("background", "frame", "A1") and len(refl) == 142
    layout = TargetLayout.load(paths[3])
    doc = json.loads(paths[4].read_text())
    np.testing.assert_allclose(layout.corners_px, doc["corners_px"])
    np.testing.assert_allclose(
        plane_to_full_px(doc["corners_plane_px"]), doc["corners_px"]
    )
    assert (
        doc["camera"]["read_noise_e"] == 30.0
        and doc["camera"]["full_well_e"] == 67000.0
    )


# -- the DNG writer ----------------------------------------------------------------------------
@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_dng_round_trip_is_exact(tmp_path: Path, pattern: str) -> None:
    rng = np.random.default_rng(3)
    mosaic = rng.integers(0, 16384, (64, 96)).astype(np.uint16)
    path = write_dng(
        tmp_path / "x.dng",
        mosaic,
        cfa_pattern=pattern,
        black_level=[2046, 2047, 2048, 2049],
        white_level=15000,
        exposure_s=1 / 125,
        iso=800,
        make="TuneSpec",
        model="SimCamera",
    )
    with rawpy.imread(str(path)) as raw:
        np.testing.assert_array_equal(raw.raw_image_visible, mosaic)
        assert raw.white_level == 15000
        letters = "".join(raw.color_desc.decode()[i] for i in raw.raw_pattern.ravel())
        assert letters == pattern
        black = np.asarray(raw.black_level_per_channel)[raw.raw_pattern]
        np.testing.assert_array_equal(black.ravel(), [2046, 2047, 2048, 2049])
        assert raw.other.shutter_speed == pytest.approx(1 / 125)
        assert raw.other.iso_speed == 800
    frame = load_raw(path)
    assert frame.cfa_pattern == pattern and (frame.make, frame.model) == (
        "TuneSpec",
        "SimCamera",
    )
    assert frame.iso == 800 and frame.exposure_s == pytest.approx(0.008)
    assert [p.name for p in tmp_path.iterdir()] == ["x.dng"]  # no temporary left


def test_dng_tags_read_back_with_tifffile(tmp_path: Path) -> None:
    """The tags rawpy does not show, read by an independent TIFF reader."""
    from datetime import datetime

    tifffile = pytest.importorskip("tifffile")
    mosaic = np.arange(24 * 30, dtype=np.uint16).reshape(24, 30)
    path = write_dng(
        tmp_path / "x.dng",
        mosaic,
        cfa_pattern="GBRG",
        exposure_s=0.3,
        iso=1600,
        make="Canon",
        model="EOS 5D Mark III",
        timestamp=datetime(2024, 5, 6, 7, 8, 9),
        description="simulated",
    )
    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        np.testing.assert_array_equal(page.asarray(), mosaic)
        tags = {t.code: t.value for t in page.tags.values()}
    assert tags[262] == 32803  # PhotometricInterpretation: CFA
    assert bytes(tags[50706]) == bytes([1, 4, 0, 0])  # DNGVersion
    assert tags[50708] == "Canon EOS 5D Mark III"  # UniqueCameraModel
    assert tuple(tags[33421]) == (2, 2) and bytes(tags[33422]) == bytes([1, 2, 0, 1])
    assert tags[50717] == 15000 and tags[50714] == 2048
    cm = np.asarray(tags[50721]).reshape(9, 2)
    np.testing.assert_array_equal(cm[:, 0], CANON_5D_MARK_III_COLOR_MATRIX)
    assert set(cm[:, 1]) == {10000}
    assert tuple(tags[50728]) == (1, 1, 1, 1, 1, 1) and tags[50778] == 21
    assert (tags[270], tags[306]) == ("simulated", "2024:05:06 07:08:09")
    exif = tags[34665]
    assert exif["ISOSpeedRatings"] == 1600 and exif["SensitivityType"] == 3
    assert tuple(exif["ExposureTime"]) == (3, 10)
    assert exif["DateTimeOriginal"] == "2024:05:06 07:08:09"


def test_dng_writer_rejects_bad_input(tmp_path: Path) -> None:
    good = np.zeros((32, 32), dtype=np.uint16)
    with pytest.raises(ValueError, match="uint16"):
        write_dng(tmp_path / "a.dng", good.astype(np.int32))
    with pytest.raises(ValueError, match="too small"):
        write_dng(tmp_path / "a.dng", good[:10])
    with pytest.raises(ValueError, match="CFA pattern"):
        write_dng(tmp_path / "a.dng", good, cfa_pattern="RGBW")
    with pytest.raises(ValueError, match="black_level"):
        write_dng(tmp_path / "a.dng", good, black_level=20000)
    assert list(tmp_path.iterdir()) == []


def test_dng_write_is_atomic_over_an_existing_file(tmp_path: Path) -> None:
    target = tmp_path / "f.dng"
    target.write_bytes(b"old")
    write_dng(
        target, np.full((32, 32), 7, dtype=np.uint16), black_level=0, white_level=100
    )
    with rawpy.imread(str(target)) as raw:
        assert raw.raw_image_visible.max() == 7


def test_irradiance_field_belongs_to_the_bench_not_the_target() -> None:
    """A calibration on the SG carries over to a small sample: same fall-off."""
    from tunespec.devices.sim.scene import FALLOFF_RADIUS_MM, SimScene

    sg, cmy = SimScene.colorchecker_sg(), SimScene.neugebauer_cmy()
    assert sg.falloff_radius_mm == cmy.falloff_radius_mm == FALLOFF_RADIUS_MM
    xy = np.array([[768.0, 512.0], [300.0, 200.0]])
    np.testing.assert_allclose(
        sg.irradiance(xy[:, 0], xy[:, 1], 1536, 1024),
        cmy.irradiance(xy[:, 0], xy[:, 1], 1536, 1024),
    )
