"""A raw frame on screen: a display preview of the planes and a saturation overlay.

:func:`build_preview` is plain numpy and may run on any thread (the device controller
calls it next to the camera, so the GUI thread only uploads a small image).
Coordinates in the view are *mosaic* pixels (full sensor resolution, pixel centres at
integers, ``tunespec.core.io.raw`` convention), the coordinates a
:class:`~tunespec.core.layout.TargetLayout` keeps its corners in; a plane pixel ``u``
covers mosaic pixels ``2u`` and ``2u + 1``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pyqtgraph as pg
from numpy.typing import NDArray
from PySide6.QtCore import QRectF
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget

__all__ = ["FramePlot", "FramePreview", "build_preview"]

#: Longest side of the displayed image; larger frames are shown decimated.
PREVIEW_MAX_SIDE = 1600
#: Colour of saturated pixels in the overlay (RGBA).
SATURATION_RGBA = (255, 0, 255, 220)


@dataclass(frozen=True)
class FramePreview:
    """What the screen shows of one frame.

    Parameters
    ----------
    rgb : (h, w, 3) uint8
        Display image (decimated by ``step``), gamma-encoded for viewing only.
    overlay : (h, w, 4) uint8
        Saturated pixels in :data:`SATURATION_RGBA`, transparent elsewhere.
    width_px, height_px
        Size of the planes (half the mosaic).
    saturated_fraction
        Fraction of plane pixels saturated in any channel.
    peak
        Highest plane value (full scale = 1).
    frame
        The frame it was built from (``RawFrame``), or None.
    """

    rgb: NDArray[np.uint8]
    overlay: NDArray[np.uint8]
    width_px: int
    height_px: int
    saturated_fraction: float
    peak: float
    frame: Any = None


def build_preview(frame: Any, max_side: int = PREVIEW_MAX_SIDE) -> FramePreview:
    """Make the display preview of ``frame`` (``.planes`` (3, h, w), ``.saturated``).

    Display only: the brightness is scaled so the 99.5th percentile sits near white,
    then gamma-encoded; nothing here feeds a measurement.
    """
    planes = np.asarray(frame.planes, dtype=np.float32)
    _, h, w = planes.shape
    step = max(1, int(np.ceil(max(h, w) / max_side)))
    small = planes[:, ::step, ::step]
    sat = getattr(frame, "saturated", None)
    if sat is None:
        sat_full = np.zeros((h, w), bool)
    else:
        sat_full = np.asarray(sat, dtype=bool)
        if sat_full.ndim == 3:
            sat_full = sat_full.any(axis=0)
    scale = float(np.percentile(small, 99.5)) if small.size else 0.0
    scale = scale if scale > 0 else 1.0
    rgb = np.clip(np.moveaxis(small, 0, -1) / scale, 0.0, 1.0) ** (1 / 2.2)
    overlay = np.zeros((*rgb.shape[:2], 4), np.uint8)
    overlay[sat_full[::step, ::step]] = SATURATION_RGBA
    return FramePreview(
        rgb=(rgb * 255 + 0.5).astype(np.uint8),
        overlay=overlay,
        width_px=w,
        height_px=h,
        saturated_fraction=float(sat_full.mean()) if sat_full.size else 0.0,
        peak=float(planes.max()) if planes.size else 0.0,
        frame=frame,
    )


class FramePlot(QWidget):
    """Shows a :class:`FramePreview` in plane-pixel coordinates (y down, aspect locked).

    Other widgets may add items to :attr:`view_box` (the layout editor draws its
    corner handles and patch grid there).
    """

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.graphics = pg.GraphicsView(background="k")
        self.view_box = pg.ViewBox(lockAspect=True, invertY=True, enableMenu=False)
        self.graphics.setCentralItem(self.view_box)
        self.image_item = pg.ImageItem(axisOrder="row-major")
        self.overlay_item = pg.ImageItem(axisOrder="row-major")
        self.overlay_item.setZValue(1)
        self.view_box.addItem(self.image_item)
        self.view_box.addItem(self.overlay_item)
        self.info_label = QLabel("No frame yet.")
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.graphics, 1)
        layout.addWidget(self.info_label)
        self.preview: FramePreview | None = None

    @property
    def image_size(self) -> tuple[int, int] | None:
        """(width, height) of the frame's mosaic, or None without a frame."""
        p = self.preview
        return None if p is None else (2 * p.width_px, 2 * p.height_px)

    def show_preview(self, preview: FramePreview) -> None:
        """Display ``preview`` (keeps the zoom if the size did not change)."""
        new_size = self.preview is None or (
            (self.preview.width_px, self.preview.height_px)
            != (preview.width_px, preview.height_px)
        )
        self.preview = preview
        # plane pixel u spans mosaic pixels 2u - 0.5 ... 2u + 1.5 (centres at integers)
        rect = QRectF(-0.5, -0.5, 2 * preview.width_px, 2 * preview.height_px)
        self.image_item.setImage(preview.rgb, autoLevels=False, levels=None)
        self.image_item.setRect(rect)
        self.overlay_item.setImage(preview.overlay, autoLevels=False, levels=None)
        self.overlay_item.setRect(rect)
        if new_size:
            self.view_box.autoRange(padding=0.02)
        self.info_label.setText(
            f"{2 * preview.width_px} x {2 * preview.height_px} px, peak "
            f"{preview.peak:.1%} of full scale, "
            f"{preview.saturated_fraction:.2%} saturated (magenta)"
        )
