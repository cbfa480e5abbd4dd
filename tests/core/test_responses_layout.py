from __future__ import annotations

import numpy as np
import pytest

from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.layout import TargetLayout, apply_homography
from tunespec.core.responses import Responses, read_responses_csv, write_responses_csv


def test_responses_round_trip(tmp_path) -> None:
    rng = np.random.default_rng(1)
    r = Responses(
        ("A1", "B1"),
        ("L1", "L2", "L3"),
        rng.random((2, 3, 3)),
        rng.random((2, 3, 3)) * 0.01,
        np.full((2, 3), 400.0),
        np.zeros((2, 3)),
    )
    write_responses_csv(r, tmp_path / "r.csv")
    b = read_responses_csv(tmp_path / "r.csv")
    assert b.patches == r.patches and b.illuminants == r.illuminants
    np.testing.assert_array_equal(b.rgb, r.rgb)
    np.testing.assert_array_equal(b.rgb_std, r.rgb_std)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("patch,illuminant,R,G\nA,L,1,2\n", "missing column"),
        ("patch,illuminant,R,G,B\nA,L,1,2,x\n", "not a number"),
        ("patch,illuminant,R,G,B\nA,L,1,2,3\nA,L,1,2,3\n", "duplicate row"),
        ("patch,illuminant,R,G,B\nA,L,1,2,3\nB,M,1,2,3\n", "pair"),
        ("patch,illuminant,R,G,B,R_std\nA,L,1,2,3,1\n", "R_std,G_std,B_std"),
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
