from __future__ import annotations

import json

import numpy as np
import pytest

from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.responses_csv import read_responses_csv, write_responses_csv
from tunespec.core.layout import TargetLayout, apply_homography
from tunespec.core.responses import Responses


def test_responses_round_trip(tmp_path) -> None:
    rng = np.random.default_rng(1)
    r = Responses(
        ("A1", "B1"),
        ("L1", "L2", "L3"),
        rng.random((2, 3, 3)),
        rng.random((2, 3, 3)) * 0.01,
        np.full((2, 3), 400.0),
        np.zeros((2, 3)),
        rng.random((3, 3)),
    )
    write_responses_csv(r, tmp_path / "r.csv")
    b = read_responses_csv(tmp_path / "r.csv")
    assert b.patches == r.patches and b.illuminants == r.illuminants
    np.testing.assert_array_equal(b.rgb, r.rgb)
    np.testing.assert_array_equal(b.rgb_std, r.rgb_std)
    np.testing.assert_array_equal(b.white_rgb, r.white_rgb)
    # a subset keeps its lights' white levels
    np.testing.assert_array_equal(r.subset(illuminants=["L3", "L1"]).white_rgb,
                                  r.white_rgb[[2, 0]])  # fmt: skip


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("patch,illuminant,R,G\nA,L,1,2\n", "missing column"),
        ("patch,illuminant,R,G,B\nA,L,1,2,x\n", "not a number"),
        ("patch,illuminant,R,G,B\nA,L,1,2,3\nA,L,1,2,3\n", "duplicate row"),
        ("patch,illuminant,R,G,B\nA,L,1,2,3\nB,M,1,2,3\n", "pair"),
        ("patch,illuminant,R,G,B,R_std\nA,L,1,2,3,1\n", "R_std,G_std,B_std"),
        ("patch,illuminant,R,G,B,white_R\nA,L,1,2,3,1\n", "white_R,white_G,white_B"),
        (
            "patch,illuminant,R,G,B,white_R,white_G,white_B\nA,L,1,2,3,4,5,6\n"
            "B,L,1,2,3,4,5,6.1\n",
            "under 'L' differ from line 2's",
        ),
    ],
)
def test_responses_errors(tmp_path, text, fragment) -> None:
    p = tmp_path / "r.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=fragment):
        read_responses_csv(p)


def test_layout_roundtrip_and_homography(tmp_path) -> None:
    sg = TargetLayout.load(resource_path("layouts", "colorchecker_sg.json"))
    assert sg.n_patches == 140 and sg.patch_names[:2] == ("A1", "B1")
    corners = [[210.0, 140.0], [1630.0, 180.0], [1600.0, 1250.0], [240.0, 1200.0]]
    sg2 = sg.with_corners(corners)
    sg2.save(tmp_path / "l.json")
    back = TargetLayout.load(tmp_path / "l.json")
    assert back == sg2
    H = back.homography()
    np.testing.assert_allclose(
        apply_homography(H, sg.outer_corners_mm()), corners, atol=1e-6
    )
    quads = back.roi_quads_px()
    assert quads.shape == (140, 4, 2)
    # ROI area is roi_fraction of the patch area (in mm, before projection)
    q = sg.patch_quads_mm(sg.roi_fraction)[0]
    p = sg.patch_quads_mm()[0]
    assert np.ptp(q[:, 0]) * np.ptp(q[:, 1]) == pytest.approx(
        0.2 * np.ptp(p[:, 0]) * np.ptp(p[:, 1])
    )


def test_layout_errors(tmp_path) -> None:
    p = tmp_path / "x.json"
    p.write_text(
        '{"format": "tunespec-layout", "name": "x", "rows": 2, "cols": 2, '
        '"width_mm": 10, "height_mm": 10, "patch_names": ["a"]}'
    )
    with pytest.raises(InputError, match="1 patch names for 2x2"):
        TargetLayout.load(p)
    p.write_text("{bad")
    with pytest.raises(InputError, match="not valid JSON") as err:
        TargetLayout.load(p)
    assert err.value.line == 1


def test_responses_duplicate_columns_and_blank_lines(tmp_path) -> None:
    p = tmp_path / "r.csv"
    p.write_text("patch,illuminant,R,G,B,R\nA,L,1,2,3,4\n")
    with pytest.raises(InputError, match="duplicate column") as err:
        read_responses_csv(p)
    assert err.value.line == 1
    # Blank lines are skipped (before the header too); errors keep the file's lines.
    p.write_text("\n\npatch,illuminant,R,G,B\nA,L,1,2,3\n\nB,L,1,2,x\n")
    with pytest.raises(InputError, match="not a number") as err:
        read_responses_csv(p)
    assert err.value.line == 6
    p.write_text("\npatch,illuminant,R,G,B\nA,L,0.1,0.2,0.3\n")
    r = read_responses_csv(p)
    assert r.patches == ("A",)
    np.testing.assert_array_equal(r.rgb, [[[0.1, 0.2, 0.3]]])


def test_responses_subset_and_names() -> None:
    r = Responses(("A", "B", "C"), ("L1", "L2"), np.arange(18.0).reshape(3, 2, 3))
    sub = r.subset(["C", "A"], ["L2"])
    assert sub.patches == ("C", "A") and sub.illuminants == ("L2",)
    np.testing.assert_array_equal(sub.rgb[:, 0], [[15.0, 16.0, 17.0], [3.0, 4.0, 5.0]])
    assert r.subset([]).rgb.shape == (0, 2, 3)  # an empty list keeps nothing
    assert r.subset().patches == r.patches
    with pytest.raises(InputError, match=r"1 patch name\(s\) not in the responses: Z"):
        r.subset(["A", "Z"])
    with pytest.raises(InputError, match="illuminant name"):
        r.subset(illuminants=["L9"])
    with pytest.raises(InputError, match="duplicate patch names: A"):
        Responses(("A", "A"), ("L1",), np.zeros((2, 1, 3)))


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        ({"margin_mm": [1, 2, 3]}, "margin_mm must be"),
        ({"corners_px": [[1, 2], [3]]}, "bad layout"),
        ({"rows": "x"}, "bad layout"),
    ],
)
def test_layout_malformed_fields_are_input_errors(tmp_path, change, fragment) -> None:
    doc = TargetLayout.load(resource_path("layouts", "colorchecker_sg.json")).to_dict()
    p = tmp_path / "x.json"
    p.write_text(json.dumps({**doc, **change}))
    with pytest.raises(InputError, match=fragment) as err:
        TargetLayout.load(p)
    assert err.value.path == str(p)
