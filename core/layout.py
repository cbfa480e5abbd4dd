"""Target layouts: where the patches are on a chart, and their ROIs in an image.

A layout describes a rectangular target in its own millimetre coordinates: the outer
rectangle ``(0, 0)-(width_mm, height_mm)`` (the four corners a homography maps into
the image), a grid of ``rows x cols`` equal cells inside the margins, and per cell a
patch of ``patch_fraction`` of the cell's side. The ROI of a patch is its central
``roi_fraction`` of the patch *area* (the paper's "central 20 % patch-pixels").

Patch names come from a naming scheme (``"sg"``: letter = column, digit = row, as on
the ColorChecker SG, A1 ... N10) or an explicit list in row-major order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError, read_json
from tunespec.core.limits import dumps_json, valid_name, valid_number

__all__ = ["TargetLayout", "apply_homography", "homography_from_corners"]

LAYOUT_VERSION = 1
#: Limits of a layout file: patches per side and in all, sizes in mm, corners in px.
MAX_SIDE = 1000
MAX_PATCHES = 10_000
MAX_MM = 1e5
MAX_PX = 1e6


@dataclass(frozen=True)
class TargetLayout:
    """A chart's geometry and patch names.

    Parameters
    ----------
    name
        Human name, e.g. ``"ColorChecker SG"``.
    rows, cols
        Patch grid size.
    width_mm, height_mm
        Outer rectangle of the target (its corners are the homography's anchors).
    margin_mm
        (left, top, right, bottom) from the outer edge to the patch grid.
    patch_fraction
        Side of a patch as a fraction of its cell (the rest is the gap between patches).
    roi_fraction
        ROI area as a fraction of the patch area (paper: 0.2).
    patch_names
        Row-major names, ``rows * cols`` of them; empty means the ``"sg"`` scheme.
    corners_px
        The target's outer corners in the image (TL, TR, BR, BL), ``(4, 2)`` x/y pixels,
        or ``None`` if not yet known.
    """

    name: str
    rows: int
    cols: int
    width_mm: float
    height_mm: float
    margin_mm: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    patch_fraction: float = 1.0
    roi_fraction: float = 0.2
    patch_names: tuple[str, ...] = ()
    corners_px: tuple[tuple[float, float], ...] | None = None
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.rows < 1 or self.cols < 1:
            raise InputError(f"layout {self.name!r}: rows and cols must be >= 1")
        if not (0 < self.patch_fraction <= 1 and 0 < self.roi_fraction <= 1):
            raise InputError(
                f"layout {self.name!r}: patch_fraction and roi_fraction must be in (0, 1]"
            )
        numbers = (self.width_mm, self.height_mm, *self.margin_mm)
        if not all(
            isinstance(v, int | float)
            and not isinstance(v, bool)
            and math.isfinite(v)
            and v >= 0
            for v in numbers
        ):
            raise InputError(
                f"layout {self.name!r}: sizes and margins must be finite numbers >= 0"
            )
        if len(self.margin_mm) != 4:
            raise InputError(
                f"layout {self.name!r}: margin_mm must be (left, top, right, bottom)"
            )
        l, t, r, b = self.margin_mm
        if self.width_mm - l - r <= 0 or self.height_mm - t - b <= 0:
            raise InputError(f"layout {self.name!r}: margins leave no room for patches")
        names = tuple(self.patch_names) or _sg_names(self.rows, self.cols)
        if len(names) != self.rows * self.cols:
            raise InputError(
                f"layout {self.name!r}: {len(names)} patch names for "
                f"{self.rows}x{self.cols} patches"
            )
        if len(set(names)) != len(names):
            raise InputError(f"layout {self.name!r}: duplicate patch names")
        object.__setattr__(self, "patch_names", names)
        object.__setattr__(self, "margin_mm", tuple(float(m) for m in self.margin_mm))
        if self.corners_px is not None:
            c = np.asarray(self.corners_px, dtype=np.float64)
            if c.shape != (4, 2) or not np.all(np.isfinite(c)):
                raise InputError(
                    f"layout {self.name!r}: corners_px must be 4 (x, y) pairs"
                )
            object.__setattr__(self, "corners_px", tuple(map(tuple, c.tolist())))

    # -- geometry in target millimetres ------------------------------------------
    @property
    def n_patches(self) -> int:
        return self.rows * self.cols

    def cell_size_mm(self) -> tuple[float, float]:
        """(width, height) of one grid cell."""
        l, t, r, b = self.margin_mm
        return (
            (self.width_mm - l - r) / self.cols,
            (self.height_mm - t - b) / self.rows,
        )

    def patch_centers_mm(self) -> NDArray[np.float64]:
        """Patch centres, (n_patches, 2) x/y mm, row-major like ``patch_names``."""
        l, t, _, _ = self.margin_mm
        cw, ch = self.cell_size_mm()
        rr, cc = np.mgrid[0 : self.rows, 0 : self.cols]
        x = l + (cc.ravel() + 0.5) * cw
        y = t + (rr.ravel() + 0.5) * ch
        return np.stack([x, y], axis=1)

    def patch_quads_mm(self, area_fraction: float = 1.0) -> NDArray[np.float64]:
        """Patch squares scaled to ``area_fraction`` of the patch, (n, 4, 2) mm.

        ``area_fraction=1`` is the whole patch; ``self.roi_fraction`` the ROI.
        """
        cw, ch = self.cell_size_mm()
        s = self.patch_fraction * math.sqrt(area_fraction)
        hw, hh = 0.5 * cw * s, 0.5 * ch * s
        offs = np.array([[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh]])
        return self.patch_centers_mm()[:, None, :] + offs[None]

    def outer_corners_mm(self) -> NDArray[np.float64]:
        """TL, TR, BR, BL of the outer rectangle, (4, 2) mm."""
        w, h = self.width_mm, self.height_mm
        return np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])

    # -- image coordinates ------------------------------------------------------
    def homography(self) -> NDArray[np.float64]:
        """3x3 homography mapping target mm to image pixels (needs ``corners_px``)."""
        if self.corners_px is None:
            raise InputError(f"layout {self.name!r}: the target's corners are not set")
        return homography_from_corners(self.outer_corners_mm(), self.corners_px)

    def roi_quads_px(self) -> NDArray[np.float64]:
        """ROI quadrilaterals in image pixels, (n_patches, 4, 2) x/y."""
        return apply_homography(
            self.homography(), self.patch_quads_mm(self.roi_fraction)
        )

    def with_corners(self, corners_px: ArrayLike | None) -> TargetLayout:
        """A copy with new image corners (TL, TR, BR, BL)."""
        c = (
            None
            if corners_px is None
            else tuple(map(tuple, np.asarray(corners_px, dtype=float).tolist()))
        )
        return replace(self, corners_px=c)

    # -- JSON -------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["format"] = "tunespec-layout"
        d["version"] = LAYOUT_VERSION
        d["margin_mm"] = list(self.margin_mm)
        d["patch_names"] = list(self.patch_names)
        d["corners_px"] = (
            None if self.corners_px is None else [list(c) for c in self.corners_px]
        )
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any], *, source: str | None = None) -> TargetLayout:
        """A layout from its JSON form, every field checked (:mod:`~.limits`).

        Raises
        ------
        InputError
            Naming the file and the key: another format, a newer or malformed
            ``version``, a field of the wrong type or out of its range.
        """
        if not isinstance(d, Mapping):
            raise InputError("bad layout: expected an object", path=source)
        if d.get("format") != "tunespec-layout":
            raise InputError(
                "not a TuneSpec layout (format != 'tunespec-layout')", path=source
            )
        version = valid_number(
            d.get("version", 0), "version", path=source, lo=0, hi=1e6, integer=True
        )
        if version > LAYOUT_VERSION:
            raise InputError(
                f"layout version {version} is newer than this "
                f"TuneSpec understands ({LAYOUT_VERSION})",
                path=source,
            )
        try:
            kw = _checked_fields(d, source)
        except InputError as exc:
            raise InputError(f"bad layout: {exc.message}", path=source) from None
        try:
            return cls(**kw)
        except InputError as exc:
            raise InputError(exc.message, path=source) from None
        except (TypeError, ValueError) as exc:
            raise InputError(f"bad layout: {exc}", path=source) from None

    def save(self, path: str | PathLike[str]) -> None:
        Path(path).write_text(dumps_json(self.to_dict()), encoding="utf-8")

    @classmethod
    def load(cls, path: str | PathLike[str]) -> TargetLayout:
        path = Path(path)
        d = read_json(path)
        if not isinstance(d, dict):
            raise InputError("expected a JSON object", path=path)
        return cls.from_dict(d, source=str(path))


def _checked_fields(d: Mapping[str, Any], source: str | None) -> dict[str, Any]:
    """The dataclass fields of a layout document, each of the right type and range."""
    kw: dict[str, Any] = {}
    kw["name"] = valid_name(d.get("name"), "name", path=source)
    for key in ("rows", "cols"):
        kw[key] = valid_number(
            d.get(key), key, path=source, lo=1, hi=MAX_SIDE, integer=True
        )
    if kw["rows"] * kw["cols"] > MAX_PATCHES:
        raise InputError(
            f"rows x cols: {kw['rows'] * kw['cols']} patches, at most {MAX_PATCHES}",
            path=source,
        )
    for key in ("width_mm", "height_mm"):
        kw[key] = float(
            valid_number(d.get(key), key, path=source, lo=0, hi=MAX_MM, lo_open=True)
        )
    margin = d.get("margin_mm", [0, 0, 0, 0])
    if not isinstance(margin, list | tuple) or len(margin) != 4:
        raise InputError(
            "margin_mm must be 4 numbers (left, top, right, bottom)", path=source
        )
    kw["margin_mm"] = tuple(
        float(valid_number(m, "margin_mm", path=source, lo=0, hi=MAX_MM))
        for m in margin
    )
    for key in ("patch_fraction", "roi_fraction"):
        if key in d:
            kw[key] = float(
                valid_number(d[key], key, path=source, lo=0, hi=1, lo_open=True)
            )
    names = d.get("patch_names", [])
    if not isinstance(names, list | tuple):
        raise InputError("patch_names: expected a list of texts", path=source)
    kw["patch_names"] = tuple(valid_name(n, "patch_names", path=source) for n in names)
    corners = d.get("corners_px")
    if corners is not None:
        if (
            not isinstance(corners, list | tuple)
            or len(corners) != 4
            or any(not isinstance(c, list | tuple) or len(c) != 2 for c in corners)
        ):
            raise InputError("corners_px: expected 4 (x, y) pairs or null", path=source)
        kw["corners_px"] = tuple(
            tuple(
                float(valid_number(v, "corners_px", path=source, lo=-MAX_PX, hi=MAX_PX))
                for v in c
            )
            for c in corners
        )
    meta = d.get("meta", {})
    if not isinstance(meta, Mapping) or not all(
        isinstance(v, str) for v in meta.values()
    ):
        raise InputError("meta: expected an object of texts", path=source)
    kw["meta"] = dict(meta)
    return kw


def _sg_names(rows: int, cols: int) -> tuple[str, ...]:
    """ColorChecker SG naming: letter = column (A...), digit = row (1...), row-major."""
    if cols > 26:
        raise InputError("the 'sg' naming scheme supports at most 26 columns")
    return tuple(f"{chr(65 + c)}{r + 1}" for r in range(rows) for c in range(cols))


def homography_from_corners(src: ArrayLike, dst: ArrayLike) -> NDArray[np.float64]:
    """The 3x3 homography taking 4 ``src`` points to 4 ``dst`` points (OpenCV).

    References
    ----------
    R. Hartley and A. Zisserman, Multiple View Geometry in Computer Vision, 2nd ed.,
    Cambridge University Press (2004), Sec. 4.1 (the direct linear transform), as
    OpenCV's ``getPerspectiveTransform``.

    Examples
    --------
    >>> import numpy as np
    >>> H = homography_from_corners([[0, 0], [1, 0], [1, 1], [0, 1]],
    ...                             [[0, 0], [2, 0], [2, 2], [0, 2]])
    >>> np.round(apply_homography(H, [[0.5, 0.5]]), 6)
    array([[1., 1.]])
    """
    import cv2

    s = np.asarray(src, dtype=np.float32).reshape(4, 2)
    d = np.asarray(dst, dtype=np.float32).reshape(4, 2)
    H = cv2.getPerspectiveTransform(s, d)
    if not np.all(np.isfinite(H)) or abs(np.linalg.det(H)) < 1e-12:
        raise InputError("degenerate corners: three or more are collinear")
    return np.asarray(H, dtype=np.float64)


def apply_homography(H: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """Map points (..., 2) through the homography ``H`` (3, 3).

    References
    ----------
    R. Hartley and A. Zisserman, Multiple View Geometry in Computer Vision, 2nd ed.
    (2004), Sec. 2.3 (projective transformation of homogeneous points, x' = H x).
    """
    H = np.asarray(H, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    flat = p.reshape(-1, 2)
    q = np.c_[flat, np.ones(len(flat))] @ H.T
    return (q[:, :2] / q[:, 2:3]).reshape(p.shape)
