"""Layouts of several grids (issue 16 item 3): the file format's extra grids, the
shipped IT8.7/2 and ColorChecker Passport, ArgyllCMS's templates of them, and an IT8
bench capture read through both."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.cht import read_cht
from tunespec.core.layout import PatchGrid, TargetLayout

ARGYLL_REF = Path("/usr/share/color/argyll/ref")
requires_ref = pytest.mark.skipif(
    not (ARGYLL_REF / "it8.cht").is_file(),
    reason="ArgyllCMS reference files not installed (apt-get install argyll-ref)",
)
#: ArgyllCMS it8.cht units per millimetre: its 25.625-unit fields are 1/4 in.
IT8_UNITS_PER_MM = 25.625 / 6.35


def _two_grids(**kw) -> TargetLayout:
    args = {
        "name": "two",
        "rows": 2,
        "cols": 3,
        "width_mm": 100.0,
        "height_mm": 80.0,
        "margin_mm": (10.0, 10.0, 30.0, 40.0),
        "patch_fraction": 0.8,
        "patch_names": ("A1", "B1", "C1", "A2", "B2", "C2", "G1", "G2"),
        "extra_grids": (PatchGrid(1, 2, 10.0, 50.0, 20.0, 25.0, 30.0, 0.0),),
    }
    return TargetLayout(**{**args, **kw})


def test_extra_grid_geometry() -> None:
    lay = _two_grids()
    assert lay.n_patches == 8
    quads = lay.patch_quads_mm()
    # main grid: 20 x 15 mm cells, 16 x 12 mm patches; extra: 20 x 25 mm patches at
    # (10, 50) and (40, 50)
    np.testing.assert_allclose(quads[0, 0], [12.0, 11.5])
    np.testing.assert_allclose(quads[6], [[10, 50], [30, 50], [30, 75], [10, 75]])
    np.testing.assert_allclose(quads[7, 2], [60.0, 75.0])
    roi = lay.patch_quads_mm(0.25)[7]  # half the side, same centre
    np.testing.assert_allclose(roi[0], [45.0, 56.25])


def test_extra_grids_round_trip_as_version_2(tmp_path) -> None:
    lay = _two_grids()
    lay.save(tmp_path / "two.json")
    d = json.loads((tmp_path / "two.json").read_text())
    assert d["version"] == 2 and d["extra_grids"][0]["pitch_x_mm"] == 30.0
    back = TargetLayout.load(tmp_path / "two.json")
    assert back == lay
    # a one-grid layout is still written as version 1, without the new key
    one = TargetLayout.load(resource_path("layouts", "colorchecker_sg.json"))
    one.save(tmp_path / "one.json")
    d1 = json.loads((tmp_path / "one.json").read_text())
    assert d1["version"] == 1 and "extra_grids" not in d1


@pytest.mark.parametrize(
    ("kw", "fragment"),
    [
        ({"extra_grids": (PatchGrid(1, 2, 80.0, 50.0, 20, 25, 30, 0),)}, "beyond"),
        ({"extra_grids": (PatchGrid(1, 2, 10.0, 20.0, 20, 25, 30, 0),)}, "overlaps"),
        ({"patch_names": ("A1", "B1")}, "2 patch names for 2x3 patches \\+ 2"),
    ],
)
def test_bad_extra_grids_are_one_line(kw, fragment) -> None:
    with pytest.raises(InputError, match=fragment):
        _two_grids(**kw)


@pytest.mark.parametrize(
    ("grids", "fragment"),
    [
        ({"rows": 1}, "extra_grids\\[0\\].cols"),
        ({"rows": 1, "cols": 2, "x_mm": 0, "y_mm": 0, "patch_w_mm": 5}, "patch_h_mm"),
        (
            {"rows": 1, "cols": 2, "x_mm": 0, "y_mm": 0, "patch_w_mm": 5,
             "patch_h_mm": 5, "pitch_x_mm": 2},
            "overlap",
        ),
        ({"rows": 1, "cols": 1, "size": 3}, "unknown key 'size'"),
        ({"rows": 1000, "cols": 1000}, "more than 10000 patches"),
    ],
)  # fmt: skip
def test_bad_extra_grid_in_a_file_names_file_and_key(tmp_path, grids, fragment):
    d = _two_grids(extra_grids=(), patch_names=()).to_dict()
    d["extra_grids"] = [grids]
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(d))
    with pytest.raises(InputError, match=fragment) as err:
        TargetLayout.load(p)
    assert str(p) in str(err.value) and "\n" not in str(err.value)


def test_shipped_it8_geometry() -> None:
    lay = TargetLayout.load(resource_path("layouts", "it8_7_2.json"))
    assert lay.n_patches == 22 * 12 + 24
    assert lay.patch_names[:2] == ("A01", "A02") and lay.patch_names[-1] == "GS23"
    sizes = lay.patch_sizes_mm()
    np.testing.assert_allclose(sizes[0], [6.35, 6.35])
    np.testing.assert_allclose(sizes[-1], [6.35, 12.7])
    q = lay.patch_quads_mm()
    # A01 one field in from the top-left; GS23 ends at the bottom-right corner
    np.testing.assert_allclose(q[0, 0], [6.35, 6.35])
    np.testing.assert_allclose(q[-1, 2], [152.4, 101.6])


def test_scene_paints_the_extra_grid() -> None:
    from tunespec.core.layout import apply_homography
    from tunespec.core.spectra import DEFAULT_GRID
    from tunespec.devices.sim.scene import SimScene

    scene = SimScene.it8_7_2(DEFAULT_GRID)
    lay = scene.layout_px(2000, 1500)
    centres = apply_homography(lay.homography(), lay.patch_centers_mm())
    labels = np.array([scene.labels([x], [y], 2000, 1500)[0, 0] for x, y in centres])
    np.testing.assert_array_equal(labels, 2 + np.arange(lay.n_patches))
    white, black = (scene.materials[n][20] for n in ("GS00", "GS23"))
    assert white > 0.8 and black < 0.005


@requires_ref
def test_argyll_it8_and_passport_templates_match_the_shipped_layouts() -> None:
    ours = TargetLayout.load(resource_path("layouts", "it8_7_2.json"))
    theirs = read_cht(ARGYLL_REF / "it8.cht").to_layout()
    assert theirs.patch_names == ours.patch_names
    # it8.cht's outline is its D box (1, 1)-(616, 410) grown to the grey scale at
    # x = 0: 616 x 409 units, the colour fields 1 unit right of the ideal layout
    assert (theirs.width_mm, theirs.height_mm) == (616.0, 409.0)
    q = theirs.patch_quads_mm() / IT8_UNITS_PER_MM
    np.testing.assert_allclose(q, ours.patch_quads_mm(), atol=1.01 / IT8_UNITS_PER_MM)
    assert theirs.roi_fraction == pytest.approx(ours.roi_fraction)
    passport = TargetLayout.load(resource_path("layouts", "colorchecker_passport.json"))
    cht = read_cht(ARGYLL_REF / "ColorCheckerPassport.cht").to_layout()
    assert cht.patch_names == passport.patch_names
    np.testing.assert_allclose(cht.patch_quads_mm(), passport.patch_quads_mm())
    assert (passport.rows, passport.cols, len(passport.extra_grids)) == (6, 4, 4)


@pytest.mark.slow
@requires_ref
def test_it8_capture_reads_the_same_through_argyll_template(tmp_path) -> None:
    """A bench capture of the IT8.7/2, its corners found under each layout: the
    shipped layout and Argyll's it8.cht give the same patch values within the ROI
    means' noise (their ROIs differ by it8.cht's 1-unit offset, ~1 pixel)."""
    from tunespec.app.pipeline.steps import capture_target, process
    from tunespec.core.spectra import DEFAULT_GRID
    from tunespec.devices.registry import open_bench
    from tunespec.devices.sim.scene import it8_bench_reflectances

    layout = TargetLayout.load(resource_path("layouts", "it8_7_2.json"))
    refl = it8_bench_reflectances(layout.patch_names, DEFAULT_GRID)
    with open_bench("sim", None, layout=layout, reflectances=refl, seed=3) as bench:
        session, _ = capture_target(bench, tmp_path / "it8", layout)
    ours = process(session).responses
    theirs = process(session, layout=read_cht(ARGYLL_REF / "it8.cht").to_layout())
    b = theirs.responses
    assert set(b.patches) == set(ours.patches)
    idx = [b.patches.index(n) for n in ours.patches]
    se = np.sqrt(
        ours.rgb_std**2 / ours.n_pixels[..., None]
        + b.rgb_std[idx] ** 2 / b.n_pixels[idx][..., None]
    )
    z = np.abs(b.rgb[idx] - ours.rgb) / se
    assert z.max() < 4.0
    # neighbouring patches differ by far more: a shifted or misnamed ROI would fail
    assert np.median(np.abs(np.diff(ours.rgb, axis=0)) / se[1:]) > 20


@pytest.mark.slow
def test_passport_capture_is_found_and_read(tmp_path) -> None:
    """Both Passport panels on the bench: the detected outline is the true one (to a
    pixel) and every patch of both panels is read."""
    from tunespec.app.pipeline.steps import capture_target, process
    from tunespec.core.spectra import DEFAULT_GRID
    from tunespec.devices.registry import open_bench
    from tunespec.devices.sim.scene import it8_bench_reflectances

    layout = TargetLayout.load(resource_path("layouts", "colorchecker_passport.json"))
    refl = it8_bench_reflectances(layout.patch_names, DEFAULT_GRID, seed=5)
    with open_bench("sim", None, layout=layout, reflectances=refl, seed=3) as bench:
        session, _ = capture_target(bench, tmp_path / "passport", layout)
        truth = bench.camera.scene.corners_px(*bench.camera.resolution)
    processed = process(session)
    np.testing.assert_allclose(processed.layout.corners_px, truth, atol=1.0)
    assert processed.responses.patches == layout.patch_names
    # every patch read where it is: its response over all LEDs ranks as its
    # mean reflectance does (a shifted or misnamed ROI would scramble the order)
    response = processed.responses.rgb.sum(axis=(1, 2))
    brightness = refl.select(layout.patch_names).values.mean(axis=1)
    rank = np.argsort(np.argsort(response)), np.argsort(np.argsort(brightness))
    assert np.corrcoef(*rank)[0, 1] > 0.95


@pytest.mark.parametrize(
    ("line", "fragment"),
    [
        ("Y 1 3 A B 0 10 10 10 20 20", "zero patch size or pitch"),
        ("Y 1 3 A B 10 10 10 10 0 20", "zero patch size or pitch"),
    ],
)
def test_degenerate_template_grid_is_one_line(tmp_path, line, fragment) -> None:
    p = tmp_path / "d.cht"
    p.write_text(f"BOXES 2\n  D ALL ALL _ _ 100 70 0 0 0 0\n  {line}\n")
    with pytest.raises(InputError, match=fragment) as err:
        read_cht(p).to_layout()
    assert str(p) in str(err.value)
