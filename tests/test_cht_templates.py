"""Argyll ``.cht`` features of the templates that did not parse (issue 25).

Minimal templates with the feature of each: CMP Digital Target-4/-7 (label range
``2A``..``2D``), SpyderChecker (patch size / pitch 42/49 in x, 42/50 in y),
QPcard 201 (the grid's cells reach past the ``D ALL`` box), it8Wolf (an extra grid
whose patches are a hair wider than their pitch). Each keeps its patch centres
exactly where the template puts them.
"""

from __future__ import annotations

import glob

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.io.cht import load_layout, read_cht
from tunespec.core.layout import TargetLayout


def _write(tmp_path, body: str):
    p = tmp_path / "t.cht"
    p.write_text("\nBOXES 9\n" + body + "\nBOX_SHRINK 2\n")
    return p


def _centres(layout: TargetLayout) -> dict[str, np.ndarray]:
    return dict(zip(layout.patch_names, layout.patch_centers_mm(), strict=True))


def test_alphanumeric_label_range(tmp_path) -> None:
    p = _write(
        tmp_path,
        "  D ALL ALL _ _ 700 300 0 0 0 0\n"
        "  X A E   1 2 100 100 0 0 100 100\n"
        "  X 2A 2B 1 2 100 100 500 0 100 100",
    )
    t = read_cht(p)
    assert t.patch_names[-4:] == ("2A1", "2B1", "2A2", "2B2")
    c = _centres(t.to_layout())
    np.testing.assert_allclose(c["2B2"], [650.0, 150.0])
    np.testing.assert_allclose(c["C1"], [250.0, 50.0])


def test_pitch_differing_in_x_and_y_keeps_centres(tmp_path) -> None:
    p = _write(
        tmp_path,
        "  D ALL ALL _ _ 475 315 0 0 0 0\n"
        "  X A D 1 6 42 42 11 10 49 50\n"
        "  X E H 1 6 42 42 274 10 49 50",
    )
    lay = read_cht(p).to_layout()
    c = _centres(lay)
    np.testing.assert_allclose(c["A1"], [32.0, 31.0], atol=1e-9)
    np.testing.assert_allclose(c["D6"], [11 + 3 * 49 + 21, 10 + 5 * 50 + 21], atol=1e-9)
    np.testing.assert_allclose(c["H6"], [274 + 3 * 49 + 21, 10 + 5 * 50 + 21])
    assert "approximation" in lay.meta
    # beyond 5 % it is refused, naming the file
    bad = _write(tmp_path, "  X A D 1 6 42 42 11 10 49 60")
    with pytest.raises(InputError, match="differs in x") as err:
        read_cht(bad).to_layout()
    assert str(bad) in str(err.value)


def test_cells_past_the_chart_box_grow_the_outline(tmp_path) -> None:
    p = _write(
        tmp_path,
        "  D ALL ALL _ _ 1654.0 478.0 0.0 0.0 0 0\n"
        "  Y 1 10 A C 118.0 119.0 239.0 66.0 141.5 142.0",
    )
    lay = read_cht(p).to_layout()
    c = _centres(lay)
    np.testing.assert_allclose(c["A1"], [239 + 59, 66 + 59.5])
    np.testing.assert_allclose(c["C10"], [239 + 9 * 141.5 + 59, 66 + 2 * 142 + 59.5])
    assert lay.height_mm >= 478.0


def test_extra_grid_a_hair_wider_than_its_pitch(tmp_path) -> None:
    p = _write(
        tmp_path,
        "  D ALL ALL _ _ 615 409 1 1 0 0\n"
        "  Y 01 22 A L 25.625 25.625 26.625 26.625 25.625 25.625\n"
        "  X GS00 GS23 _ _ 25.625 51.25 3.3 360 25.57 0",
    )
    lay = read_cht(p).to_layout()
    assert lay.n_patches == 22 * 12 + 24
    assert lay.extra_grids[0].patch_w_mm == pytest.approx(25.57)
    # a real overlap is one line naming the file and the grid
    bad = _write(
        tmp_path,
        "  D ALL ALL _ _ 615 409 1 1 0 0\n"
        "  Y 01 22 A L 25.625 25.625 26.625 26.625 25.625 25.625\n"
        "  X GS00 GS23 _ _ 30 51.25 3.3 360 25.57 0",
    )
    with pytest.raises(InputError, match=r"GS00\.\.GS23.*overlap") as err:
        read_cht(bad).to_layout()
    assert str(bad) in str(err.value) and "\n" not in str(err.value)


def test_cht_is_a_layout_wherever_a_layout_is(tmp_path) -> None:
    p = _write(
        tmp_path,
        "  D ALL ALL _ _ 330 228 0 0 0 0\n  Y 1 6 A D 46 46 12 11.5 52.5 52.5",
    )
    lay = load_layout(p)
    assert (lay.rows, lay.cols) == (4, 6) and lay.patch_names[0] == "A1"


ARGYLL_TEMPLATES = sorted(glob.glob("/usr/share/color/argyll/ref/*.cht"))


@pytest.mark.skipif(not ARGYLL_TEMPLATES, reason="argyll-ref not installed")
def test_every_installed_argyll_template_parses() -> None:
    failed = {}
    for path in ARGYLL_TEMPLATES:
        try:
            read_cht(path).to_layout()
        except InputError as exc:
            failed[path] = str(exc)
    assert not failed
