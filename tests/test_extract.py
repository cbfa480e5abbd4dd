"""``tunespec extract``: the chart finder and the extraction check on a real frame.

The frame is ``tests/data/tinydng_colorchart.dng`` (Canon 550D, a ColorChecker
Passport open, dim and slightly blurred; MIT, see ``tests/data/SOURCE.md``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.tolerances import RTOL_AUTO_VS_HAND, RTOL_TURNED_CHROMATICITY
from tunespec.app.cli import main
from tunespec.app.pipeline.extract import extract_chart, read_linear_image
from tunespec.core.errors import InputError
from tunespec.core.io.raw import plane_to_full_px
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout, apply_homography

DNG = Path(__file__).parent / "data" / "tinydng_colorchart.dng"

#: Patch centres set by hand (plane pixels of the DNG's half-resolution planes): the
#: midpoints of each patch's four edges, read off an 8x enlargement of the frame.
#: Only patches bright enough to see their edges; the outline follows from them.
HAND_CENTRES_PLANE_PX = {
    "A2": (412.0, 312.5),
    "A6": (626.0, 306.6),
    "B6": (626.7, 357.2),
    "C6": (628.2, 408.8),
    "D1": (351.3, 465.4),
    "D3": (462.3, 463.4),
    "D4": (518.0, 462.4),
}


@pytest.fixture(scope="module")
def layout() -> TargetLayout:
    return TargetLayout.load("colorchecker_24")


@pytest.fixture(scope="module")
def reference():
    from tunespec.core.datasets import resource_path

    return read_spectra_csv(resource_path("charts", "colorchecker_24.csv"))


@pytest.fixture(scope="module")
def image():
    return read_linear_image(DNG)


def hand_corners_mosaic_px(layout: TargetLayout) -> np.ndarray:
    """The layout's outer corners (mosaic px) from the hand-set patch centres."""
    import cv2

    names = list(HAND_CENTRES_PLANE_PX)
    mm = layout.patch_centers_mm()[[layout.patch_names.index(n) for n in names]]
    H, _ = cv2.findHomography(mm, np.array(list(HAND_CENTRES_PLANE_PX.values())), 0)
    return plane_to_full_px(apply_homography(H, layout.outer_corners_mm()))


@pytest.fixture(scope="module")
def by_hand(image, layout, reference):
    return extract_chart(
        image, layout, corners_px=hand_corners_mosaic_px(layout), reflectances=reference
    )


@pytest.fixture(scope="module")
def automatic(image, layout, reference):
    return extract_chart(image, layout, reflectances=reference)


def test_real_dng_found_automatically(automatic, by_hand, layout):
    assert automatic.method == "grid"
    assert automatic.check.ok, automatic.check.summary()
    g = automatic.responses.rgb[:, 0, 1]
    neutral = g[[layout.patch_names.index(f"D{k}") for k in range(1, 7)]]
    assert np.all(np.diff(neutral) < 0), neutral  # white D1 ... black D6
    assert 15 < neutral[0] / neutral[-1] < 40
    auto, hand = automatic.responses.rgb[:, 0], by_hand.responses.rgb[:, 0]
    rel = np.abs(auto / hand - 1)
    assert rel.max() < RTOL_AUTO_VS_HAND, dict(
        zip(layout.patch_names, rel.max(1), strict=True)
    )
    # the corners written out are the file's (mosaic) pixels, as in a session
    auto_c = np.asarray(automatic.layout.corners_px)
    assert np.abs(auto_c - hand_corners_mosaic_px(layout)).max() < 12
    assert automatic.check.metrics["y_correlation"] > 0.98
    assert automatic.check.metrics["colour_residual"] < 0.06


def _uint16(linear: np.ndarray) -> np.ndarray:
    """0..1 -> 16-bit; the raw planes' noise below black (negative) clips at 0."""
    return np.round(np.clip(linear, 0.0, 1.0) * 65535).astype(np.uint16)


def _turned_tilted_tiff(image, path: Path) -> None:
    """The frame's planes turned 90 degrees and warped in perspective, 16-bit."""
    import cv2
    import tifffile

    rgb = np.rot90(np.moveaxis(image.planes, 0, -1), k=1).astype(np.float32)
    h, w = rgb.shape[:2]
    src = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    dst = np.float32([[0.06 * w, 0.02 * h], [0.97 * w, 0.0], [w, h], [0.0, 0.93 * h]])
    M = cv2.getPerspectiveTransform(src, dst)
    warped = cv2.warpPerspective(rgb, M, (w, h), flags=cv2.INTER_LINEAR)
    scale = 0.8 / float(warped.max())
    tifffile.imwrite(path, _uint16(warped * scale))


def test_turned_and_tilted_tiff_same_chromaticities(
    image, layout, reference, automatic, tmp_path
):
    tif = tmp_path / "turned.tif"
    _turned_tilted_tiff(image, tif)
    ex = extract_chart(tif, layout, reflectances=reference)
    assert ex.check.ok, ex.check.summary()

    def chroma(rgb):
        return rgb / rgb.sum(axis=1, keepdims=True)

    a = chroma(ex.responses.rgb[:, 0])
    b = chroma(automatic.responses.rgb[:, 0])
    assert np.abs(a / b - 1).max() < RTOL_TURNED_CHROMATICITY


def test_clipped_crop_found_or_refused(image, layout, reference, by_hand, tmp_path):
    """The classic panel cropped through its right column: right or refused."""
    import tifffile

    rgb = np.moveaxis(image.planes, 0, -1)
    crop = rgb[265:505, 300:640]  # the right edge cuts through column 6
    tif = tmp_path / "crop.tif"
    tifffile.imwrite(tif, _uint16(crop / crop.max() * 0.8))
    try:
        ex = extract_chart(tif, layout, reflectances=reference)
    except InputError as exc:
        assert "refused" in str(exc) or "not found" in str(exc)
        return
    # found: every patch wholly inside agrees with the hand-set extraction
    inside = ex.stats.n_pixels >= ex.stats.n_expected
    scale = by_hand.responses.rgb[:, 0, 1].max() / ex.responses.rgb[:, 0, 1].max()
    rel = np.abs(ex.responses.rgb[inside, 0] * scale / by_hand.responses.rgb[inside, 0])
    assert np.abs(rel - 1).max() < 0.05


def test_cli_extract_and_refusal(tmp_path, capsys):
    out, png = tmp_path / "patches.csv", tmp_path / "preview.png"
    rc = main(
        ["extract", str(DNG), "--layout", "colorchecker_24", "-o", str(out),
         "--preview", str(png)]
    )  # fmt: skip
    assert rc == 0
    assert png.stat().st_size > 1000
    from tunespec.core.io.responses_csv import read_responses_csv

    r = read_responses_csv(out)
    assert r.patches[0] == "A1" and r.illuminants == ("tinydng_colorchart",)
    assert r.n_pixels is not None and r.n_pixels.min() > 500
    # corners a third of a patch off: refused with one line, preview written
    bad = hand_corners_mosaic_px(TargetLayout.load("colorchecker_24"))
    bad[:, 0] += 40.0
    corners = ",".join(f"{v:.1f}" for v in bad.ravel())
    png.unlink()
    rc = main(
        ["extract", str(DNG), "--layout", "colorchecker_24", "-o", str(out),
         "--preview", str(png), "--corners", corners]
    )  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "refused" in err and "\n" not in err
    assert png.is_file()
    rc = main(
        ["extract", str(DNG), "--layout", "colorchecker_24", "-o", str(out),
         "--corners", corners, "--force"]
    )  # fmt: skip
    assert rc == 0
    assert "FORCED" in out.read_text().splitlines()[1]


def _bench_frame(tmp_path, layout_name, background, rotation_deg):
    """One simulated bench frame (broadband light, ~60 % of full scale) as a DNG,
    the scene's true outer corners (mosaic px) and the chart's reflectances."""
    from tunespec.devices.dng import write_dng
    from tunespec.devices.registry import layout_reflectances
    from tunespec.devices.sim.camera import SimCamera
    from tunespec.devices.sim.scene import SimScene

    layout = TargetLayout.load(layout_name)
    refl = layout_reflectances(layout)
    scene = SimScene(
        layout,
        refl,
        background=background,
        rotation_deg=rotation_deg,
        keystone=0.08,
        field_width_mm=700.0 if layout.n_patches == 24 else 504.0,
    )
    cam = SimCamera(None, scene, seed=1)
    flat = np.ones(cam.render_grid.n)
    probe = cam.render(flat * 1e-3).astype(float) - cam.black_level
    gain = 0.6 * (cam.white_level - cam.black_level) / np.percentile(probe, 99.5)
    mosaic = cam.render(flat * 1e-3 * gain)
    path = tmp_path / f"{layout_name}.dng"
    write_dng(
        path, mosaic, cfa_pattern="RGGB", black_level=cam.black_level,
        white_level=cam.white_level, exposure_s=1.0, iso=100,
        make="TuneSpec", model="SimCamera",
    )  # fmt: skip
    return path, scene.corners_px(*cam.resolution), layout, refl


@pytest.mark.parametrize(
    ("layout_name", "background", "rotation_deg"),
    [("colorchecker_24", 0.05, -80.0), ("colorchecker_24", 0.5, 95.0)],
)
def test_bench_frame_on_another_background(
    tmp_path, layout_name, background, rotation_deg
):
    """A dark or grey board, the chart turned about 90 degrees and in perspective:
    the patch grid is found (the bench's outline finder needs a white board)."""
    from tunespec.core.layout import homography_from_corners

    path, truth, layout, refl = _bench_frame(
        tmp_path, layout_name, background, rotation_deg
    )
    ex = extract_chart(path, layout, reflectances=refl)
    assert ex.method == "grid" and ex.check.ok, ex.check.summary()
    mm = layout.patch_centers_mm()
    found = apply_homography(
        homography_from_corners(layout.outer_corners_mm(), ex.layout.corners_px), mm
    )
    true = apply_homography(
        homography_from_corners(layout.outer_corners_mm(), truth), mm
    )
    pitch = np.linalg.norm(true[1] - true[0])
    # measured 2.1 % (dark board) and 1.3 % (grey) of the pitch at worst
    assert np.hypot(*(found - true).T).max() < 0.03 * pitch


def test_bench_sg_on_grey_board(tmp_path):
    """The SG on a grey board, turned 30 degrees: found (the grid finder's partial
    lattice is placed wrongly here and refused by the check; the outline finder
    then finds it to a pixel)."""
    path, truth, layout, refl = _bench_frame(tmp_path, "colorchecker_sg", 0.2, 30.0)
    ex = extract_chart(path, layout, reflectances=refl)
    assert ex.check.ok, ex.check.summary()
    assert np.abs(np.asarray(ex.layout.corners_px) - truth).max() < 1.5


def test_partial_view_keeps_the_patches_in_the_image(
    image, layout, reference, tmp_path
):
    """Columns 1-4 of the classic panel only: placed by the reference colours, the
    patches outside are left out (and said), the others agree with the full view."""
    import tifffile

    rgb = np.moveaxis(image.planes, 0, -1)
    crop = rgb[265:505, 300:546]  # cut in the gap between columns 4 and 5
    tif = tmp_path / "part.tif"
    scale = 0.8 / crop.max()
    tifffile.imwrite(tif, _uint16(crop * scale))
    ex = extract_chart(tif, layout, reflectances=reference)
    assert ex.check.ok, ex.check.summary()
    want = [f"{r}{c}" for r in "ABCD" for c in range(1, 5)]
    assert list(ex.responses.patches) == want
    assert any("left out" in n and "A5" in n for n in ex.check.notes)
    full = extract_chart(image, layout, reflectances=reference).responses
    idx = [layout.patch_names.index(p) for p in want]
    ratio = ex.responses.rgb[:, 0] / (full.rgb[idx, 0] * scale)
    # the same up to the TIFF's quantisation (measured 0.25 % at worst)
    assert np.abs(ratio - 1).max() < 0.01


@pytest.mark.parametrize("shift_mosaic_px", [-44.0, -22.0, 44.0])
def test_right_edge_off_is_refused(image, layout, reference, by_hand, shift_mosaic_px):
    """The outline the bench's finder once gave on a crop of this frame: the right
    edge about 22 plane (44 mosaic) pixels off, patch means off by up to 128 %.
    Such an outline (and one off by half as much) is refused, naming the ROIs."""
    corners = hand_corners_mosaic_px(layout)
    corners[1:3, 0] += shift_mosaic_px  # TR and BR
    with pytest.raises(InputError, match=r"refused.*not uniform"):
        extract_chart(image, layout, corners_px=corners, reflectances=reference)
    kept = extract_chart(
        image, layout, corners_px=corners, reflectances=reference, force=True
    )
    # what the check protects from: patch means far off the right ones
    dev = np.abs(kept.responses.rgb[:, 0] / by_hand.responses.rgb[:, 0] - 1).max()
    assert dev > 0.15 and kept.forced
