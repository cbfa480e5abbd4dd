"""Edit a :class:`~tunespec.core.layout.TargetLayout` over a captured frame.

The frame is shown with four draggable corner handles (TL, TR, BR, BL) and the patch
grid with its ROIs drawn through the layout's homography. Rows, columns, margins,
patch and ROI fractions are editable; corners can be found automatically (the core's
corner finder runs in a :class:`~tunespec.app.gui.workers.Worker`) and then corrected by
dragging. Layouts load from and save to JSON through ``TargetLayout.load/save``.

All geometry (homography, ROI quads) comes from ``core.layout``; this module only
draws it and turns mouse drags into new corners.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6.QtCore import QPointF, Qt, Signal, Slot
from PySide6.QtGui import QKeySequence, QUndoCommand, QUndoStack
from PySide6.QtWidgets import (
    QCheckBox,
    QDoubleSpinBox,
    QFileDialog,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QSpinBox,
    QToolButton,
    QVBoxLayout,
    QWidget,
)

from tunespec.app.gui.plots.frame_plot import FramePlot, FramePreview, build_preview
from tunespec.app.gui.workers import Worker
from tunespec.core.errors import TuneSpecError
from tunespec.core.io.cht import read_cht
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import read_bytes

__all__ = ["CORNER_NAMES", "FoundCorners", "TargetLayoutEditor", "find_target_corners"]

log = logging.getLogger(__name__)

CORNER_NAMES = ("TL", "TR", "BR", "BL")
_GRID_PEN = pg.mkPen((0, 220, 255), width=1)
_ROI_PEN = pg.mkPen((255, 220, 0), width=2)
_OUTLINE_PEN = pg.mkPen((0, 255, 0), width=2)
_SELECTED_PEN = pg.mkPen((255, 60, 60), width=3)

#: ``finder(frame, layout, *, session_root, progress, should_stop)`` returning (4, 2)
#: corners (TL, TR, BR, BL in mosaic pixels) or a :class:`FoundCorners`.
CornerFinder = Callable[..., Any]


@dataclass(frozen=True)
class FoundCorners:
    """What the automatic corner finder found.

    Parameters
    ----------
    corners_px : (4, 2)
        TL, TR, BR, BL in mosaic pixels.
    preview
        The frame the corners were found in, for the editor to show (None: the
        frame shown already).
    message
        What the operator reads in the editor's status line.
    """

    corners_px: NDArray[np.float64]
    preview: FramePreview | None = None
    message: str = ""


def find_target_corners(
    frame: Any,
    target_layout: TargetLayout,
    *,
    session_root: str | Path | None = None,
    progress: Any = None,
    should_stop: Any = None,
) -> FoundCorners:
    """The corners processing would find, in mosaic pixels (pool thread).

    With a session that holds a white-background and a target frame under one LED,
    this is processing's own detection
    (:func:`tunespec.core.processing.find_session_corners`: the same frames, the same
    detector), and the target frame it used is returned for display. Without one
    (a frame taken outside a measurement), the shown frame's green plane alone is
    searched, which finds a target only against an evenly lit background.
    """
    from tunespec.core.errors import InputError
    from tunespec.core.io.session import MANIFEST_NAME

    root = Path(session_root) if session_root else None
    if root is not None and (root / MANIFEST_NAME).is_file():
        from tunespec.app.pipeline.jobs import find_session_corners

        try:
            found, target = find_session_corners(root, target_layout)
        except InputError as exc:
            if frame is None or "white-background and a target" not in str(exc):
                raise
        else:
            return FoundCorners(
                found.corners_px,
                build_preview(target),
                f"Corners found as processing finds them ({found.target_id} "
                f"against {found.white_id}, fit residual {found.residual_px:.2f} "
                "px); drag a handle to correct.",
            )
    if frame is None:
        raise InputError("take the white-background and target frames first")
    from tunespec.core.homography import locate_target
    from tunespec.core.io.raw import plane_to_full_px

    grid = _find_patch_grid(frame, target_layout)
    if grid is not None:
        return FoundCorners(
            plane_to_full_px(grid),
            None,
            "Patch grid found in the shown frame; check the ROIs, drag a handle "
            "to correct.",
        )
    try:
        corners_plane, _fit = locate_target(frame.planes[1], target_layout)
    except InputError as exc:
        raise InputError(
            f"{exc} (in the shown frame alone; with the white-background frame "
            "taken, the finder compares the two as processing does)"
        ) from None
    return FoundCorners(
        plane_to_full_px(corners_plane),
        None,
        "Corners found in the shown frame; drag a handle to correct.",
    )


def _find_patch_grid(
    frame: Any, target_layout: TargetLayout
) -> NDArray[np.float64] | None:
    """The layout's outer corners (plane px) from the patch-grid finder of
    ``tunespec extract`` (any background, any rotation), or None."""
    from tunespec.app.pipeline.extract import layout_reference, reference_xyz
    from tunespec.core.chart_finder import find_patch_grid
    from tunespec.core.errors import InputError

    ref = reference_xyz(target_layout, layout_reference(target_layout))
    try:
        fit = find_patch_grid(
            np.moveaxis(np.asarray(frame.planes), 0, -1),
            target_layout,
            reference_xyz=ref,
        )
    except InputError:
        return None
    return fit.corners_px


def _polylines(quads: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Closed quads (n, 4, 2) as x, y arrays with NaN breaks for one curve item."""
    closed = np.concatenate(
        [quads, quads[:, :1], np.full((len(quads), 1, 2), np.nan)], 1
    )
    flat = closed.reshape(-1, 2)
    return flat[:, 0], flat[:, 1]


class _LayoutEdit(QUndoCommand):
    """One edit of the layout (a corner drag, a spin box, found corners...).

    Pushed after the edit is shown, so the first ``redo`` (Qt calls it on push)
    re-applies the same layout. Successive changes of one spin box merge into one
    step (``merge_key``), so an arrow key held down is undone at once.
    """

    def __init__(
        self,
        editor: TargetLayoutEditor,
        before: TargetLayout,
        after: TargetLayout,
        text: str,
        merge_key: int = -1,
    ) -> None:
        super().__init__(text)
        self._editor, self.before, self.after = editor, before, after
        self._merge_key = merge_key

    def id(self) -> int:
        return self._merge_key

    def mergeWith(self, other: QUndoCommand) -> bool:
        if not isinstance(other, _LayoutEdit) or other.id() != self.id():
            return False
        self.after = other.after
        return True

    def redo(self) -> None:
        self._editor._apply_layout(self.after)

    def undo(self) -> None:
        self._editor._apply_layout(self.before)


#: ``merge_key`` of the spin boxes' edits (a drag or a button never merges: -1).
_MERGE_KEYS = {"rows": 1, "cols": 2, "patch": 3, "roi": 4, "margin": 10}


class TargetLayoutEditor(QWidget):
    """The target-layout editor.

    Parameters
    ----------
    target_layout
        The layout to start with.
    corner_finder
        Automatic corner finder, ``finder(frame, layout, progress=, should_stop=)``
        returning (4, 2) mosaic-pixel corners (default :func:`find_target_corners`);
        None disables the button.
    """

    #: The layout changed (corners, grid or fractions): the new ``TargetLayout``.
    layout_changed = Signal(object)
    #: A patch was clicked: its name.
    patch_selected = Signal(str)
    #: A layout file was loaded: its path.
    layout_loaded = Signal(str)

    def __init__(
        self,
        target_layout: TargetLayout,
        *,
        corner_finder: CornerFinder | None = find_target_corners,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self._layout = target_layout
        self._corner_finder = corner_finder
        self._finder_worker: Worker | None = None
        self._finder_target = ""
        self._session_root: Path | None = None
        self._updating = False
        self._drag_before: TargetLayout | None = None
        #: Undo/redo of the edits made here (corners, grid, margins, fractions).
        #: A layout set from outside (another target, the corners a step used)
        #: starts a new history.
        self.undo_stack = QUndoStack(self)
        self.selected_patch: str | None = None
        self.last_dir = ""

        self._build_plot()
        self._build_fields()
        self._build_undo()
        self._build_side_panel()
        self._connect_fields()
        self.set_corner_finder(corner_finder)
        self.set_target_layout(target_layout)

    def _build_plot(self) -> None:
        """The frame with the grid, ROIs, outline and the four corner handles."""
        self.frame_plot = FramePlot()
        vb = self.frame_plot.view_box
        self.grid_item = pg.PlotCurveItem(pen=_GRID_PEN, connect="finite")
        self.roi_item = pg.PlotCurveItem(pen=_ROI_PEN, connect="finite")
        self.outline_item = pg.PlotCurveItem(pen=_OUTLINE_PEN, connect="finite")
        self.selected_item = pg.PlotCurveItem(pen=_SELECTED_PEN, connect="finite")
        for z, item in enumerate(
            (self.grid_item, self.roi_item, self.outline_item, self.selected_item), 2
        ):
            item.setZValue(z)
            vb.addItem(item)
        self.handles: list[pg.TargetItem] = []
        for name in CORNER_NAMES:
            handle = pg.TargetItem(
                pos=(0, 0),
                size=16,
                symbol="s",
                pen=pg.mkPen((255, 255, 255), width=2),
                brush=(0, 200, 0, 120),
                hoverBrush=(255, 255, 0, 180),
                movable=True,
                label=name,
                labelOpts={"color": (255, 255, 255), "offset": (10, 10)},
            )
            handle.setZValue(10)
            handle.sigPositionChanged.connect(self._on_handle_position_changed)
            handle.sigPositionChangeFinished.connect(self._on_handle_drag_finished)
            vb.addItem(handle)
            self.handles.append(handle)
        self.name_items: list[pg.TextItem] = []
        vb.scene().sigMouseClicked.connect(self._on_scene_mouse_clicked)

    def _build_fields(self) -> None:
        self.name_label = QLabel()
        self.rows_spin = QSpinBox(minimum=1, maximum=100)
        self.cols_spin = QSpinBox(minimum=1, maximum=26)
        self.margin_spins = [
            QDoubleSpinBox(
                minimum=0.0, maximum=1000.0, decimals=2, singleStep=0.5, suffix=" mm"
            )
            for _ in range(4)
        ]
        self.patch_fraction_spin = QDoubleSpinBox(
            minimum=0.05, maximum=1.0, decimals=3, singleStep=0.01
        )
        self.roi_fraction_spin = QDoubleSpinBox(
            minimum=1.0, maximum=100.0, decimals=1, singleStep=1.0, suffix=" % of area"
        )
        self.names_check = QCheckBox("Show patch names")
        self.load_button = QPushButton("Load…")
        self.save_button = QPushButton("Save…")
        self.open_image_button = QPushButton("Open image…")
        self.open_image_button.setToolTip(
            "Show a camera raw file (CR2, DNG, ...) to place the layout on"
        )
        self.find_button = QPushButton("Find corners")
        self.find_button.setToolTip(
            "Find the target's corners automatically, then drag to correct"
        )
        self.reset_button = QPushButton("Reset corners")
        self.status_label = QLabel()
        self.status_label.setWordWrap(True)
        self.corners_label = QLabel()
        self.corners_label.setWordWrap(True)

    def _build_undo(self) -> None:
        self.undo_action = self.undo_stack.createUndoAction(self, "Undo")
        self.undo_action.setShortcut(QKeySequence.StandardKey.Undo)
        self.redo_action = self.undo_stack.createRedoAction(self, "Redo")
        # the platform's Redo, and both common ones whatever the platform says
        redo_keys = QKeySequence.keyBindings(QKeySequence.StandardKey.Redo)
        for text in ("Ctrl+Shift+Z", "Ctrl+Y"):
            if all(k.toString() != text for k in redo_keys):
                redo_keys.append(QKeySequence(text))
        self.redo_action.setShortcuts(redo_keys)
        for action in (self.undo_action, self.redo_action):
            # only while the editor has the focus: a spin box elsewhere keeps its own
            action.setShortcutContext(Qt.ShortcutContext.WidgetWithChildrenShortcut)
            self.addAction(action)
        self.undo_button = QToolButton()
        self.undo_button.setDefaultAction(self.undo_action)
        self.redo_button = QToolButton()
        self.redo_button.setDefaultAction(self.redo_action)

    def _build_side_panel(self) -> None:
        form = QFormLayout()
        form.addRow("Target", self.name_label)
        form.addRow("Rows", self.rows_spin)
        form.addRow("Columns", self.cols_spin)
        for label, spin in zip(
            ("Left", "Top", "Right", "Bottom"), self.margin_spins, strict=True
        ):
            form.addRow(f"{label} margin", spin)
        form.addRow("Patch / cell", self.patch_fraction_spin)
        form.addRow("ROI", self.roi_fraction_spin)
        form.addRow(self.names_check)
        box = QGroupBox("Layout")
        box.setLayout(form)
        buttons = QHBoxLayout()
        buttons.addWidget(self.load_button)
        buttons.addWidget(self.save_button)
        corners = QHBoxLayout()
        corners.addWidget(self.open_image_button)
        corners.addWidget(self.find_button)
        corners.addWidget(self.reset_button)
        history = QHBoxLayout()
        history.addWidget(self.undo_button)
        history.addWidget(self.redo_button)
        history.addStretch(1)
        side = QVBoxLayout()
        side.addWidget(box)
        side.addLayout(buttons)
        side.addLayout(corners)
        side.addLayout(history)
        side.addWidget(self.corners_label)
        side.addWidget(self.status_label)
        side.addStretch(1)
        side_widget = QWidget()
        side_widget.setLayout(side)
        side_widget.setMaximumWidth(300)
        main = QHBoxLayout(self)
        main.setContentsMargins(2, 2, 2, 2)
        main.addWidget(self.frame_plot, 1)
        main.addWidget(side_widget)

    def _connect_fields(self) -> None:
        edits = [
            (self.rows_spin, _MERGE_KEYS["rows"], "Change rows"),
            (self.cols_spin, _MERGE_KEYS["cols"], "Change columns"),
            (self.patch_fraction_spin, _MERGE_KEYS["patch"], "Change patch size"),
            (self.roi_fraction_spin, _MERGE_KEYS["roi"], "Change ROI size"),
        ]
        for i, (spin, side) in enumerate(
            zip(self.margin_spins, ("left", "top", "right", "bottom"), strict=True)
        ):
            edits.append((spin, _MERGE_KEYS["margin"] + i, f"Change {side} margin"))
        for spin, merge, text in edits:
            spin.valueChanged.connect(
                lambda _v, m=merge, t=text: self._on_geometry_edited(t, m)
            )
        self.names_check.toggled.connect(self._on_names_check_toggled)
        self.load_button.clicked.connect(self._on_load_button_clicked)
        self.save_button.clicked.connect(self._on_save_button_clicked)
        self.find_button.clicked.connect(self._on_find_button_clicked)
        self.open_image_button.clicked.connect(self._on_open_image_button_clicked)
        self.reset_button.clicked.connect(self._on_reset_button_clicked)

    # -- public API -------------------------------------------------------------------
    @property
    def target_layout(self) -> TargetLayout:
        """The layout as edited now."""
        return self._layout

    def set_target_layout(
        self,
        target_layout: TargetLayout,
        *,
        emit: bool = False,
        undo_text: str | None = None,
    ) -> None:
        """Show and edit ``target_layout`` (corners are kept if it has none).

        A layout from outside (another target, the corners a step used) starts a new
        undo history; with ``undo_text`` (a file loaded here) it is a step of it.
        """
        before = self._layout
        if (
            target_layout.corners_px is None
            and self._layout.corners_px is not None
            and self.frame_plot.image_size is not None
        ):
            target_layout = target_layout.with_corners(self._layout.corners_px)
        if undo_text is None:
            self.undo_stack.clear()
        if target_layout.name != before.name:
            self.status_label.setText("")  # it spoke of the other target
        self._layout = target_layout
        self._sync_spins()
        self.names_check.setChecked(target_layout.n_patches <= 48)
        if target_layout.corners_px is None and self.frame_plot.image_size is not None:
            self._layout = target_layout.with_corners(self.default_corners())
        self._commit(before, emit, undo_text)

    def _commit(self, before: TargetLayout, emit: bool, undo_text: str | None) -> None:
        """Show the layout just set; announce it (``emit``) and make it a step of
        the undo history (``undo_text``)."""
        self._sync_handles()
        self._redraw()
        if emit:
            self.layout_changed.emit(self._layout)
        if undo_text is not None:
            self._edited(before, undo_text)

    def _sync_spins(self) -> None:
        lay = self._layout
        self._updating = True
        try:
            self.name_label.setText(lay.name)
            self.rows_spin.setValue(lay.rows)
            self.cols_spin.setValue(lay.cols)
            for spin, m in zip(self.margin_spins, lay.margin_mm, strict=True):
                spin.setValue(m)
            self.patch_fraction_spin.setValue(lay.patch_fraction)
            self.roi_fraction_spin.setValue(100.0 * lay.roi_fraction)
        finally:
            self._updating = False

    def _apply_layout(self, target_layout: TargetLayout) -> None:
        """Show ``target_layout`` as the edited one (undo/redo) and announce it."""
        self._layout = target_layout
        self._sync_spins()
        self._sync_handles()
        self._redraw()
        self.layout_changed.emit(self._layout)

    def _edited(self, before: TargetLayout, text: str, merge_key: int = -1) -> None:
        """Record the edit from ``before`` to the layout now shown (undoable)."""
        if before != self._layout:
            self.undo_stack.push(
                _LayoutEdit(self, before, self._layout, text, merge_key)
            )

    def set_session_root(self, root: str | Path | None) -> None:
        """The capture session of the target being edited (None: none yet).

        "Find corners" then compares its white-background and target frames, as
        processing does.
        """
        self._session_root = Path(root) if root else None

    @property
    def session_root(self) -> Path | None:
        """The session "Find corners" reads, or None."""
        return self._session_root

    def show_status(self, text: str) -> None:
        """Show ``text`` in the editor's status line."""
        self.status_label.setText(text)

    def set_corner_finder(self, finder: CornerFinder | None) -> None:
        """Use ``finder`` for "Find corners" (None disables it)."""
        self._corner_finder = finder
        self.find_button.setEnabled(finder is not None)

    def set_corners(
        self, corners_px: Any, *, emit: bool = True, undo_text: str | None = None
    ) -> None:
        """Move the corners to ``corners_px`` (4, 2) TL, TR, BR, BL mosaic pixels.

        With ``undo_text`` the move is a step of the undo history.
        """
        before = self._layout
        self._layout = self._layout.with_corners(np.asarray(corners_px, dtype=float))
        self._commit(before, emit, undo_text)

    def show_preview(self, preview: FramePreview) -> None:
        """Show a frame; a layout without corners gets default ones inside it."""
        self.frame_plot.show_preview(preview)
        if self._layout.corners_px is None:
            # placeholders to drag from, not corners anybody chose: not emitted
            self.set_corners(self.default_corners(), emit=False)

    def default_corners(self) -> NDArray[np.float64]:
        """A rectangle inset 10 % into the frame, with the target's aspect ratio."""
        size = self.frame_plot.image_size or (640, 480)
        w, h = size
        aspect = self._layout.width_mm / self._layout.height_mm
        bw, bh = 0.8 * w, 0.8 * h
        if bw / bh > aspect:
            bw = bh * aspect
        else:
            bh = bw / aspect
        x0, y0 = (w - bw) / 2, (h - bh) / 2
        return np.array([[x0, y0], [x0 + bw, y0], [x0 + bw, y0 + bh], [x0, y0 + bh]])

    def handle_positions(self) -> NDArray[np.float64]:
        """Where the four handles are, (4, 2) mosaic pixels."""
        return np.array([[h.pos().x(), h.pos().y()] for h in self.handles])

    def select_patch(self, name: str | None) -> None:
        """Outline patch ``name`` (None clears)."""
        self.selected_patch = name
        self._redraw_selection()

    # -- drawing ------------------------------------------------------------------
    def _sync_handles(self) -> None:
        corners = self._layout.corners_px
        self._updating = True
        try:
            for handle, c in zip(self.handles, corners or [(0, 0)] * 4, strict=True):
                handle.setVisible(corners is not None)
                handle.setPos(QPointF(float(c[0]), float(c[1])))
        finally:
            self._updating = False
        self._show_corners_text()

    def _show_corners_text(self) -> None:
        c = self._layout.corners_px
        self.corners_label.setText(
            "Corners: not set"
            if c is None
            else "Corners (px): "
            + ", ".join(
                f"{n} ({x:.0f}, {y:.0f})"
                for n, (x, y) in zip(CORNER_NAMES, c, strict=True)
            )
        )

    def _clear_names(self) -> None:
        for item in self.name_items:
            self.frame_plot.view_box.removeItem(item)
        self.name_items.clear()

    def _redraw(self) -> None:
        lay = self._layout
        try:
            if lay.corners_px is None:
                raise TuneSpecError("no corners")
            H = lay.homography()
            from tunespec.core.layout import apply_homography

            patches = apply_homography(H, lay.patch_quads_mm(1.0))
            rois = lay.roi_quads_px()
            outline = apply_homography(H, lay.outer_corners_mm()[None])
        except TuneSpecError:
            for item in (
                self.grid_item,
                self.roi_item,
                self.outline_item,
                self.selected_item,
            ):
                item.setData([], [])
            self._clear_names()
            self._quads_px = None
            return
        self._quads_px = patches
        self.grid_item.setData(*_polylines(patches))
        self.roi_item.setData(*_polylines(rois))
        self.outline_item.setData(*_polylines(outline))
        names = list(lay.patch_names) if self.names_check.isChecked() else []
        if [t.textItem.toPlainText() for t in self.name_items] != names:
            # made again only when the names change: a chart's 140 labels cost the
            # GUI thread tens of ms to make (gui_timing --why), moving them far less
            self._clear_names()
            for name in names:
                text = pg.TextItem(name, color=(255, 255, 255), anchor=(0.5, 1.3))
                text.setZValue(6)
                self.frame_plot.view_box.addItem(text)
                self.name_items.append(text)
        for text, (x, y) in zip(self.name_items, patches.mean(axis=1), strict=False):
            text.setPos(x, y)
        self._redraw_selection()

    def _redraw_selection(self) -> None:
        quads = getattr(self, "_quads_px", None)
        name = self.selected_patch
        if quads is None or name not in self._layout.patch_names:
            self.selected_item.setData([], [])
            return
        i = self._layout.patch_names.index(name)
        self.selected_item.setData(*_polylines(quads[i : i + 1]))

    def patch_at(self, x: float, y: float) -> str | None:
        """The patch whose quad contains mosaic pixel (x, y), or None."""
        quads = getattr(self, "_quads_px", None)
        if quads is None:
            return None
        # inside a convex quad: the point is on the same side of all four edges
        edges = np.roll(quads, -1, axis=1) - quads
        rel = np.array([x, y])[None, None, :] - quads
        cross = edges[..., 0] * rel[..., 1] - edges[..., 1] * rel[..., 0]
        inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
        hits = np.flatnonzero(inside)
        return self._layout.patch_names[hits[0]] if hits.size else None

    # -- slots --------------------------------------------------------------------
    @Slot(object)
    def _on_handle_position_changed(self, _handle: Any) -> None:
        if self._updating:
            return
        if self._drag_before is None:
            self._drag_before = self._layout  # the drag's first move
        self._layout = self._layout.with_corners(self.handle_positions())
        self._show_corners_text()
        self._redraw()
        self.layout_changed.emit(self._layout)

    @Slot(object)
    def _on_handle_drag_finished(self, handle: Any) -> None:
        before, self._drag_before = self._drag_before, None
        if before is not None:
            name = CORNER_NAMES[self.handles.index(handle)]
            self._edited(before, f"Move corner {name}")
        log.info("target corners set by hand: %s", self._layout.corners_px)

    def _on_geometry_edited(
        self, text: str = "Edit layout", merge_key: int = -1
    ) -> None:
        if self._updating:
            return
        lay = self._layout
        rows, cols = self.rows_spin.value(), self.cols_spin.value()
        # the names stay while the main grid keeps its shape; a new shape takes the
        # default names (a layout with extra grids then asks for names in the file)
        names = lay.patch_names if (rows, cols) == (lay.rows, lay.cols) else ()
        try:
            new = replace(
                lay,
                rows=rows,
                cols=cols,
                margin_mm=tuple(s.value() for s in self.margin_spins),
                patch_fraction=self.patch_fraction_spin.value(),
                roi_fraction=self.roi_fraction_spin.value() / 100.0,
                patch_names=names,
            )
        except TuneSpecError as exc:
            self.status_label.setText(f"Not applied: {exc}")
            return
        self.status_label.setText("")
        before, self._layout = self._layout, new
        self._redraw()
        self.layout_changed.emit(new)
        self._edited(before, text, merge_key)

    @Slot(bool)
    def _on_names_check_toggled(self, _on: bool) -> None:
        self._redraw()

    @Slot(object)
    def _on_scene_mouse_clicked(self, event: Any) -> None:
        vb = self.frame_plot.view_box
        if not vb.sceneBoundingRect().contains(event.scenePos()):
            return
        p = vb.mapSceneToView(event.scenePos())
        name = self.patch_at(p.x(), p.y())
        if name is not None:
            self.select_patch(name)
            self.patch_selected.emit(name)

    @Slot()
    def _on_load_button_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self,
            "Load target layout",
            self.last_dir,
            "Target layouts (*.json);;ArgyllCMS chart templates (*.cht);;All files (*)",
        )
        if path:
            self.load(path)

    @Slot()
    def _on_open_image_button_clicked(self) -> None:
        path, _ = QFileDialog.getOpenFileName(
            self,
            "Open a camera raw file",
            self.last_dir,
            "Camera raw files (*.dng *.cr2 *.cr3 *.nef *.arw *.orf *.raf *.rw2 "
            "*.pef *.srw *.DNG *.CR2);;All files (*)",
        )
        if path:
            self.open_image(path)

    def open_image(self, path: str | Path) -> bool:
        """Show a camera raw file (anything LibRaw reads) to place the layout on;
        its corners are in the file's mosaic pixels, as ``tunespec extract`` and
        processing read them. Errors are shown, not raised."""
        from tunespec.core.io.raw import load_raw

        try:
            preview = build_preview(load_raw(path))
        except TuneSpecError as exc:
            self.status_label.setText(f"Cannot open: {exc}")
            log.error("cannot open image: %s", exc)
            return False
        self.last_dir = str(Path(path).parent)
        self.show_preview(preview)
        self.status_label.setText(
            f"Showing {Path(path).name}; Find corners, or drag the handles."
        )
        return True

    @Slot()
    def _on_save_button_clicked(self) -> None:
        path, _ = QFileDialog.getSaveFileName(
            self, "Save target layout", self.last_dir, "Target layouts (*.json)"
        )
        if path:
            self.save(path)

    def load(self, path: str | Path) -> None:
        """Load a layout JSON file or an ArgyllCMS ``.cht`` template (errors are
        shown, not raised). A template keeps its own units (the homography does not
        mind); saving writes it as a TuneSpec layout."""
        try:
            lay = _read_layout(Path(path))
        except TuneSpecError as exc:
            self.status_label.setText(f"Cannot load: {exc}")
            log.error("cannot load layout: %s", exc)
            return
        self.last_dir = str(Path(path).parent)
        self.set_target_layout(lay, emit=True, undo_text=f"Load {Path(path).name}")
        self.status_label.setText(f"Loaded {Path(path).name}")
        self.layout_loaded.emit(str(path))

    def save(self, path: str | Path) -> None:
        """Save the layout as JSON (errors are shown, not raised)."""
        try:
            self._layout.save(path)
        except OSError as exc:
            self.status_label.setText(f"Cannot save: {exc}")
            log.error("cannot save layout: %s", exc)
            return
        self.last_dir = str(Path(path).parent)
        self.status_label.setText(f"Saved {Path(path).name}")
        log.info("layout saved to %s", path)

    @Slot()
    def _on_reset_button_clicked(self) -> None:
        self.set_corners(self.default_corners(), undo_text="Reset corners")

    @Slot()
    def _on_find_button_clicked(self) -> None:
        self.find_corners()

    def _has_session(self) -> bool:
        from tunespec.core.io.session import MANIFEST_NAME

        root = self._session_root
        return root is not None and (root / MANIFEST_NAME).is_file()

    def find_corners(self) -> Worker | None:
        """Run the automatic corner finder on the shown frame (in a worker)."""
        preview = self.frame_plot.preview
        frame = None if preview is None else preview.frame
        if self._corner_finder is None or (frame is None and not self._has_session()):
            self.status_label.setText("Take a frame of the target first.")
            return None
        if self._finder_worker is not None:
            return self._finder_worker
        self.status_label.setText("Finding corners…")
        self.find_button.setEnabled(False)
        self._finder_target = self._layout.name
        worker = Worker(
            self._corner_finder,
            frame,
            self._layout,
            session_root=self._session_root,
        )
        worker.signals.returned.connect(self._on_finder_returned)
        worker.signals.errored.connect(self._on_finder_errored)
        worker.signals.finished.connect(self._on_finder_finished)
        self._finder_worker = worker
        return worker.start()

    @Slot(object)
    def _on_finder_returned(self, corners: Any) -> None:
        if self._layout.name != self._finder_target:
            # the editor moved on to the other target while the finder ran
            self.status_label.setText(
                f"Corners found for {self._finder_target} not used: the editor now "
                f"shows {self._layout.name}."
            )
            return
        found = (
            corners
            if isinstance(corners, FoundCorners)
            else FoundCorners(
                np.asarray(corners, dtype=float),
                None,
                "Corners found; drag a handle to correct.",
            )
        )
        if found.preview is not None:
            self.frame_plot.show_preview(found.preview)
        self.set_corners(
            np.asarray(found.corners_px, dtype=float).reshape(4, 2),
            undo_text="Find corners",
        )
        self.status_label.setText(found.message)
        log.info("target corners found automatically")

    @Slot(object)
    def _on_finder_errored(self, exc: Exception) -> None:
        self.status_label.setText(f"Corners not found: {exc}. Place them by hand.")
        log.warning("automatic corner finding failed: %s", exc)

    @Slot()
    def _on_finder_finished(self) -> None:
        self._finder_worker = None
        self.find_button.setEnabled(self._corner_finder is not None)


def _read_layout(path: Path) -> TargetLayout:
    """A ``tunespec-layout`` JSON file, or an ArgyllCMS ``.cht`` (told by content:
    a JSON document starts with ``{``)."""
    head = read_bytes(path).removeprefix(b"\xef\xbb\xbf").lstrip()
    if head.startswith(b"{"):
        return TargetLayout.load(path)
    return read_cht(path).to_layout()
