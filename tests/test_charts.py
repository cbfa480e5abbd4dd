"""Charts as data: ArgyllCMS .cht templates read as layouts, the shipped ColorChecker 24,
and calibrating on it on the simulated bench."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.cht import read_cht
from tunespec.core.io.spectral import read_spectral
from tunespec.core.layout import TargetLayout
from tunespec.core.spectra import CALIBRATION_GRID, DEFAULT_GRID

ARGYLL_REF = Path("/usr/share/color/argyll/ref")
requires_ref = pytest.mark.skipif(
    not (ARGYLL_REF / "ColorChecker.cht").is_file(),
    reason="ArgyllCMS reference files not installed (apt-get install argyll-ref)",
)

#: A template in ArgyllCMS's documented format: 2 rows x 3 columns, y-part first.
SMALL_CHT = """
BOXES 7
  F _ _ 1.0 1.0  99.0 1.0  99.0 69.0  1.0 69.0
  D ALL ALL _ _ 100 70  0 0  0 0
  Y 01 03 A B  20.0 20.0  10.0 15.0  30.0 30.0

BOX_SHRINK 2.0

EXPECTED XYZ 6
  A01 1 2 3
"""


def test_offset_chart_box_is_the_outline(tmp_path) -> None:
    p = tmp_path / "d.cht"
    p.write_text(
        "BOXES 2\n  D ALL ALL _ _ 100 70 5 5 0 0\n  Y 1 3 A B 10 10 10 10 20 20\n"
    )
    lay = read_cht(p).to_layout()
    assert (lay.width_mm, lay.height_mm) == (100.0, 70.0)
    # patch A1 at (10, 10) in template units is 5 mm in from the box at (5, 5)
    np.testing.assert_allclose(lay.patch_quads_mm()[0, 0], [5.0, 5.0])


def test_small_template_as_layout(tmp_path) -> None:
    p = tmp_path / "t.cht"
    p.write_text(SMALL_CHT)
    t = read_cht(p)
    assert t.patch_names == ("A01", "A02", "A03", "B01", "B02", "B03")
    assert t.expected["A01"] == (1.0, 2.0, 3.0) and t.fiducials.shape == (4, 2)
    lay = t.to_layout("small", width_mm=200.0)
    assert (lay.rows, lay.cols, lay.width_mm, lay.height_mm) == (2, 3, 200.0, 140.0)
    # patch B02: the box (40, 45)-(60, 65) in template units, x2 in mm
    b02 = lay.patch_quads_mm()[lay.patch_names.index("B02")]
    np.testing.assert_allclose(b02[0], [80.0, 90.0])
    np.testing.assert_allclose(b02[2], [120.0, 130.0])
    assert lay.roi_fraction == pytest.approx(16 * 16 / (20 * 20))


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("BOXES 1\n  D ALL ALL _ _ 100 70 0 0 0 0\n", "X/Y patch lines"),
        ("BOXES 1\n  D ALL ALL _ _ 100 70 0 0 0 0\n  Y 1 3 A\n", "expected 10"),
        ("BOXES 1\n  D ALL ALL _ _ 100 70 0 0 0 0\n  Y 3 1 A B 1 1 1 1 1 1\n", "label"),
    ],
)
def test_bad_templates_are_one_line(tmp_path, text, fragment) -> None:
    p = tmp_path / "bad.cht"
    p.write_text(text)
    with pytest.raises(InputError, match=fragment) as err:
        read_cht(p)
    assert str(p) in str(err.value)


@requires_ref
def test_argyll_templates() -> None:
    cc = read_cht(ARGYLL_REF / "ColorChecker.cht").to_layout(width_mm=279.4)
    ours = TargetLayout.load(resource_path("layouts", "colorchecker_24.json"))
    assert cc.patch_names == ours.patch_names
    np.testing.assert_allclose(cc.patch_quads_mm(), ours.patch_quads_mm(), atol=1e-9)
    sg = read_cht(ARGYLL_REF / "ColorCheckerSG.cht").to_layout()
    assert sg.n_patches == 140 and sg.patch_names[:2] == ("A1", "B1")
    passport = read_cht(ARGYLL_REF / "ColorCheckerPassport.cht")
    assert len(passport.patch_names) == 50 and len(passport.expected) == 50
    lay = passport.to_layout()
    assert lay.n_patches == 50 and len(lay.extra_grids) == 4


def test_shipped_colorchecker24_matches_its_reflectances() -> None:
    layout = TargetLayout.load(resource_path("layouts", "colorchecker_24.json"))
    refl = read_spectral(
        resource_path("charts", "colorchecker_24.csv"), kind="reflectance"
    )
    assert refl.names == layout.patch_names
    # D1 is the white (N 9.5), D6 the black (N 2): ~0.9 and ~0.03
    assert refl["D1"][20] > 0.85 and refl["D6"][20] < 0.05


@pytest.mark.slow
@requires_ref
def test_cht_drives_extraction_and_cc24_calibrates(tmp_path) -> None:
    """A bench capture of the CC24 read through Argyll's template gives the same patch
    values as through the shipped layout, and calibrates the camera."""
    from tunespec.app.pipeline.steps import calibrate, capture_target, process
    from tunespec.devices.registry import open_bench

    layout = TargetLayout.load(resource_path("layouts", "colorchecker_24.json"))
    refl = read_spectral(
        resource_path("charts", "colorchecker_24.csv"), kind="reflectance"
    )
    refl = refl.resample(DEFAULT_GRID)
    with open_bench("sim", None, layout=layout, reflectances=refl, seed=3) as bench:
        session, _ = capture_target(bench, tmp_path / "cc24", layout)
        truth = bench.truth
    ours = process(session)
    cht = read_cht(ARGYLL_REF / "ColorChecker.cht").to_layout(width_mm=279.4)
    theirs = process(session, layout=cht.with_corners(ours.layout.corners_px))
    assert theirs.responses.patches == ours.responses.patches
    np.testing.assert_allclose(theirs.responses.rgb, ours.responses.rgb, rtol=1e-12)
    cal = calibrate(ours, refl)
    assert cal.table1.mean[3] < 0.001
    true = truth["absolute_sensitivity"].resample(CALIBRATION_GRID).values
    est = cal.sensitivity.values
    scale = float(np.sum(est * true) / np.sum(true * true))  # flat-field shading
    assert np.sqrt(np.mean((est - scale * true) ** 2)) / (scale * true.max()) < 0.08
