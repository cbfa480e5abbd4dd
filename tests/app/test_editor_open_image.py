"""The layout editor opens a camera raw file and finds a real chart's patch grid."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.test_extract import hand_corners_mosaic_px
from tunespec.app.gui.editors.target_layout_editor import TargetLayoutEditor
from tunespec.core.layout import TargetLayout

DNG = Path(__file__).parents[1] / "data" / "tinydng_colorchart.dng"


def test_open_the_real_dng_and_find_its_patch_grid(qtbot, tmp_path):
    layout = TargetLayout.load("colorchecker_24")
    ed = TargetLayoutEditor(layout)
    qtbot.addWidget(ed)
    assert ed.open_image(DNG)
    assert "tinydng_colorchart.dng" in ed.status_label.text()
    assert ed.find_corners() is not None
    qtbot.waitUntil(lambda: ed.find_button.isEnabled(), timeout=30_000)
    assert "Patch grid found" in ed.status_label.text()
    corners = np.asarray(ed.target_layout.corners_px)
    # mosaic pixels, as extract and processing read a layout's corners
    assert np.abs(corners - hand_corners_mosaic_px(layout)).max() < 12
    ed.save(tmp_path / "placed.json")
    assert TargetLayout.load(tmp_path / "placed.json").corners_px is not None


def test_a_file_that_is_not_raw_is_one_status_line(qtbot, tmp_path):
    ed = TargetLayoutEditor(TargetLayout.load("colorchecker_24"))
    qtbot.addWidget(ed)
    bad = tmp_path / "x.dng"
    bad.write_bytes(b"not a raw file")
    assert not ed.open_image(bad)
    assert ed.status_label.text().startswith("Cannot open:")
