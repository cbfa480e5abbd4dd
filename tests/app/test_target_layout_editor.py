"""TargetLayoutEditor: handles, grid overlay, editing and JSON round trip."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
import pytest

from tests.app.helpers import mouse_drag
from tunespec.app.gui.editors.target_layout_editor import TargetLayoutEditor
from tunespec.app.gui.plots.frame_plot import build_preview
from tunespec.core.datasets import resource_path
from tunespec.core.layout import TargetLayout


class _Frame:
    """A frame-like object: grey background with a dark rectangle (the target)."""

    def __init__(self, h: int = 240, w: int = 320) -> None:
        planes = np.full((3, h, w), 0.8, np.float32)
        planes[:, 60:181, 40:281] = 0.2
        self.planes = planes
        self.saturated = np.zeros((h, w), bool)
        self.saturated[0:4, 0:4] = True


@pytest.fixture
def editor(qtbot):
    layout = TargetLayout.load(resource_path("layouts", "neugebauer_cmy.json"))
    ed = TargetLayoutEditor(layout)
    qtbot.addWidget(ed)
    ed.resize(900, 600)
    ed.show_preview(build_preview(_Frame()))
    ed.show()
    qtbot.waitExposed(ed)
    return ed


def test_default_corners_are_set_inside_the_frame(editor):
    corners = np.asarray(editor.target_layout.corners_px)
    assert corners.shape == (4, 2)
    # the view is in mosaic pixels: twice the planes' 320 x 240
    assert np.all((corners[:, 0] > 0) & (corners[:, 0] < 640))
    assert np.all((corners[:, 1] > 0) & (corners[:, 1] < 480))
    np.testing.assert_allclose(editor.handle_positions(), corners)


def test_dragging_a_handle_moves_that_corner(editor, qtbot, monkeypatch):
    monkeypatch.setitem(pg.CONFIG_OPTIONS, "mouseRateLimit", -1)
    before = np.asarray(editor.target_layout.corners_px)
    vb = editor.frame_plot.view_box
    view = editor.frame_plot.graphics
    target_xy = before[2] + np.array([-20.0, 15.0])  # move BR
    start = view.mapFromScene(vb.mapViewToScene(pg.Point(*before[2])))
    end = view.mapFromScene(vb.mapViewToScene(pg.Point(*target_xy)))
    with qtbot.waitSignal(editor.layout_changed, timeout=2000):
        mouse_drag(view.viewport(), start, end)
    after = np.asarray(editor.target_layout.corners_px)
    # the drag is quantised to screen pixels: allow two of them in image pixels
    np.testing.assert_allclose(after[2], target_xy, atol=2 * max(vb.viewPixelSize()))
    np.testing.assert_allclose(after[[0, 1, 3]], before[[0, 1, 3]])
    np.testing.assert_allclose(editor.handle_positions(), after)
    # the ROIs follow the new corners through the layout's homography
    np.testing.assert_allclose(
        editor.roi_item.getData()[0][:4], editor.target_layout.roi_quads_px()[0, :, 0]
    )


def test_editing_rows_cols_and_roi_fraction(editor, qtbot):
    with qtbot.waitSignal(editor.layout_changed):
        editor.roi_fraction_spin.setValue(10.0)
    assert editor.target_layout.roi_fraction == pytest.approx(0.10)
    with qtbot.waitSignal(editor.layout_changed):
        editor.rows_spin.setValue(3)
    lay = editor.target_layout
    assert (lay.rows, lay.cols, lay.n_patches) == (3, 4, 12)
    assert lay.patch_names[0] == "A1"  # names fall back to the SG scheme
    with qtbot.waitSignal(editor.layout_changed):
        editor.margin_spins[0].setValue(10.0)
    assert editor.target_layout.margin_mm[0] == 10.0


def test_impossible_margins_are_refused_plainly(editor):
    before = editor.target_layout
    editor.margin_spins[0].setValue(99.0)
    assert editor.target_layout is before
    assert "margins" in editor.status_label.text()


def test_save_and_load_round_trip(editor, tmp_path):
    editor.set_corners([[10, 20], [300, 25], [290, 220], [15, 210]])
    path = tmp_path / "layout.json"
    editor.save(path)
    loaded = TargetLayout.load(path)
    assert loaded == editor.target_layout
    editor.set_corners([[0, 0], [100, 0], [100, 100], [0, 100]])
    editor.load(path)
    np.testing.assert_allclose(editor.handle_positions(), np.asarray(loaded.corners_px))


def test_clicking_a_patch_selects_it(editor, qtbot):
    quads = editor.target_layout.roi_quads_px()
    centre = quads[5].mean(axis=0)
    assert editor.patch_at(*centre) == editor.target_layout.patch_names[5]


def test_core_corner_finder_finds_the_dark_rectangle(editor, qtbot):
    assert editor.find_corners() is not None
    qtbot.waitUntil(lambda: editor.find_button.isEnabled(), timeout=10_000)
    # the rectangle spans planes x 40..280, y 60..180 -> mosaic 2u + 0.5 at the edges
    corners = np.asarray(editor.target_layout.corners_px)
    expected = np.array([[79.5, 119.5], [561.5, 119.5], [561.5, 361.5], [79.5, 361.5]])
    np.testing.assert_allclose(corners, expected, atol=3.0)


def test_automatic_corner_finder_runs_in_a_worker(editor, qtbot):
    found = np.array([[40.0, 60.0], [280.0, 60.0], [280.0, 180.0], [40.0, 180.0]])

    def finder(frame, layout, *, session_root, progress, should_stop):
        return found

    editor.set_corner_finder(finder)
    assert editor.find_corners() is not None
    qtbot.waitUntil(lambda: editor.find_button.isEnabled(), timeout=5000)
    np.testing.assert_allclose(editor.target_layout.corners_px, found)


def _drag_corner(editor, index, delta):
    vb = editor.frame_plot.view_box
    view = editor.frame_plot.graphics
    corners = np.asarray(editor.target_layout.corners_px)
    start = view.mapFromScene(vb.mapViewToScene(pg.Point(*corners[index])))
    end = view.mapFromScene(vb.mapViewToScene(pg.Point(*(corners[index] + delta))))
    mouse_drag(view.viewport(), start, end)


def test_undo_restores_a_dragged_corner(editor, qtbot, monkeypatch):
    monkeypatch.setitem(pg.CONFIG_OPTIONS, "mouseRateLimit", -1)
    before = np.asarray(editor.target_layout.corners_px)
    with qtbot.waitSignal(editor.layout_changed, timeout=2000):
        _drag_corner(editor, 2, np.array([-30.0, 20.0]))
    moved = np.asarray(editor.target_layout.corners_px)
    assert np.abs(moved[2] - before[2]).max() > 10
    # one drag (many mouse moves) is one step of the history
    assert editor.undo_stack.count() == 1
    assert editor.undo_action.text() == "Undo Move corner BR"
    with qtbot.waitSignal(editor.layout_changed):
        editor.undo_action.trigger()
    np.testing.assert_array_equal(editor.target_layout.corners_px, before)
    np.testing.assert_allclose(editor.handle_positions(), before)
    editor.redo_action.trigger()
    np.testing.assert_array_equal(editor.target_layout.corners_px, moved)
    np.testing.assert_allclose(editor.handle_positions(), moved)


def test_undo_redo_of_margins_grid_and_found_corners(editor, qtbot):
    original = editor.target_layout
    editor.margin_spins[0].setValue(5.0)
    editor.margin_spins[0].setValue(6.0)  # the same spin box: one step
    editor.rows_spin.setValue(3)
    assert editor.undo_stack.count() == 2
    editor.set_corners([[10, 20], [300, 25], [290, 220], [15, 210]], undo_text="x")
    editor.undo_stack.undo()
    np.testing.assert_array_equal(editor.target_layout.corners_px, original.corners_px)
    editor.undo_stack.undo()
    assert editor.target_layout.rows == original.rows == editor.rows_spin.value()
    editor.undo_stack.undo()
    assert editor.target_layout == original
    assert editor.margin_spins[0].value() == original.margin_mm[0]
    editor.undo_stack.redo()
    assert editor.target_layout.margin_mm[0] == 6.0


def test_undo_and_redo_keys(editor, qtbot):
    from PySide6.QtCore import Qt

    editor.activateWindow()
    editor.rows_spin.setFocus()
    original = editor.target_layout
    editor.cols_spin.setValue(5)
    editor.frame_plot.graphics.setFocus()
    qtbot.keyClick(
        editor.frame_plot.graphics, Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier
    )
    assert editor.target_layout == original
    qtbot.keyClick(
        editor.frame_plot.graphics,
        Qt.Key.Key_Z,
        Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier,
    )
    assert editor.target_layout.cols == 5


def test_a_layout_from_outside_starts_a_new_history(editor):
    editor.rows_spin.setValue(3)
    assert editor.undo_stack.canUndo()
    other = TargetLayout.load(resource_path("layouts", "colorchecker_sg.json"))
    editor.set_target_layout(other)
    assert not editor.undo_stack.canUndo()


@pytest.mark.parametrize("chart", ["it8.cht", "ColorCheckerPassport.cht"])
def test_open_cht_save_as_layout_reopen_same_patches(editor, tmp_path, chart):
    """An ArgyllCMS template of several grids opens, saves as a TuneSpec layout
    (version 2, extra grids) and reopens with the same patches where they were."""
    from pathlib import Path

    from tunespec.core.io.cht import read_cht

    cht = Path("/usr/share/color/argyll/ref") / chart
    if not cht.is_file():
        pytest.skip("ArgyllCMS reference files not installed")
    editor.load(cht)
    opened = editor.target_layout
    template = read_cht(cht).to_layout()
    assert opened.patch_names == template.patch_names
    np.testing.assert_allclose(opened.patch_quads_mm(), template.patch_quads_mm())
    # the overlay shows every patch, the extra grids' too
    assert editor.patch_at(*editor._quads_px[-1].mean(axis=0)) == opened.patch_names[-1]
    editor.save(tmp_path / "chart.json")
    editor.load(tmp_path / "chart.json")
    back = editor.target_layout
    assert back.patch_names == opened.patch_names and back.extra_grids
    np.testing.assert_allclose(back.patch_quads_mm(), opened.patch_quads_mm())
    np.testing.assert_allclose(back.roi_quads_px(), opened.roi_quads_px())
    # an edit of the main grid keeps the extra grids and the names
    editor.patch_fraction_spin.setValue(0.9)
    assert editor.target_layout.extra_grids == back.extra_grids
    assert editor.target_layout.patch_names == back.patch_names


def test_a_bad_file_is_one_status_line(editor, tmp_path):
    p = tmp_path / "bad.cht"
    p.write_text("BOXES 1\n  Y 1 3 A\n")
    before = editor.target_layout
    editor.load(p)
    assert editor.target_layout == before
    text = editor.status_label.text()
    assert text.startswith("Cannot load:") and str(p) in text and "\n" not in text
