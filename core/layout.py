"""Target layouts: where the patches are on a chart, and their ROIs in an image.

A layout describes a rectangular target in its own millimetre coordinates: the outer
rectangle ``(0, 0)-(width_mm, height_mm)`` (the four corners a homography maps into
the image), a grid of ``rows x cols`` equal cells inside the margins, and per cell a
patch of ``patch_fraction`` of the cell's side. The ROI of a patch is its central
``roi_fraction`` of the patch *area* (the paper's "central 20 % patch-pixels").

Patch names come from a naming scheme (``"sg"``: letter = column, digit = row, as on
the ColorChecker SG, A1 ... N10) or an explicit list in row-major order.

Charts of several panels or patch sizes (the ColorChecker Passport's two panels, the
IT8.7/2's 22 x 12 colour fields over a row of 24 taller grey steps) add
``extra_grids``: further :class:`PatchGrid` s, each ``rows x cols`` patches of its own
size and pitch placed anywhere in the chart (a free box is a 1 x 1 grid). Their
patches follow the main grid's in ``patch_names`` and every per-patch array.

File format (``tunespec-layout``, JSON): ``name``, ``rows``, ``cols``, ``width_mm``,
``height_mm``, ``margin_mm`` [left, top, right, bottom], ``patch_fraction``,
``roi_fraction``, ``patch_names`` (all patches: the main grid row-major, then each
extra grid row-major), ``corners_px`` (null or 4 [x, y]), ``meta`` (texts) and, from
version 2, ``extra_grids``: a list of ``{"rows", "cols", "x_mm", "y_mm",
"patch_w_mm", "patch_h_mm", "pitch_x_mm", "pitch_y_mm"}`` (top-left patch's top-left
corner, patch size, centre-to-centre pitch). A layout without extra grids is written
as version 1, so older TuneSpec reads it; version 1 files read unchanged.
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

from tunespec.core.atomic import atomic_write_text
from tunespec.core.errors import InputError
from tunespec.core.limits import dumps_json, read_json, valid_name, valid_number

__all__ = [
    "PatchGrid",
    "TargetLayout",
    "apply_homography",
    "homography_from_corners",
    "shipped_layout_names",
]

LAYOUT_VERSION = 2
#: Limits of a layout file: patches per side and in all, sizes in mm, corners in px.
MAX_SIDE = 1000
MAX_PATCHES = 10_000
MAX_MM = 1e5
MAX_PX = 1e6


@dataclass(frozen=True)
class PatchGrid:
    """A further regular grid of equal patches in chart millimetres.

    ``(x_mm, y_mm)`` is the top-left corner of the top-left patch; patch ``(r, c)``
    spans ``x_mm + c * pitch_x_mm`` ... ``+ patch_w_mm`` (and the same along y).
    Row-major like the main grid. A pitch is ignored (0 allowed) along a side of one
    patch; otherwise it is at least the patch size (patches do not overlap).
    """

    rows: int
    cols: int
    x_mm: float
    y_mm: float
    patch_w_mm: float
    patch_h_mm: float
    pitch_x_mm: float = 0.0
    pitch_y_mm: float = 0.0

    def __post_init__(self) -> None:
        numbers = (self.x_mm, self.y_mm, self.patch_w_mm, self.patch_h_mm)
        if not all(_finite(v) and v >= 0 for v in numbers) or min(numbers[2:]) <= 0:
            raise InputError("extra grid: position >= 0 and patch size > 0 expected")
        if not (_finite(self.pitch_x_mm) and _finite(self.pitch_y_mm)):
            raise InputError("extra grid: pitch must be a finite number")
        if (self.cols > 1 and self.pitch_x_mm < self.patch_w_mm - 1e-9) or (
            self.rows > 1 and self.pitch_y_mm < self.patch_h_mm - 1e-9
        ):
            raise InputError("extra grid: pitch smaller than the patch (overlap)")
        if self.rows < 1 or self.cols < 1:
            raise InputError("extra grid: rows and cols must be >= 1")

    @property
    def n_patches(self) -> int:
        return self.rows * self.cols

    def centers_mm(self) -> NDArray[np.float64]:
        """Patch centres, (n, 2) x/y mm, row-major."""
        rr, cc = np.mgrid[0 : self.rows, 0 : self.cols]
        x = self.x_mm + cc.ravel() * self.pitch_x_mm + 0.5 * self.patch_w_mm
        y = self.y_mm + rr.ravel() * self.pitch_y_mm + 0.5 * self.patch_h_mm
        return np.stack([x, y], axis=1)

    def bounds_mm(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) around all the grid's patches."""
        return (
            self.x_mm,
            self.y_mm,
            self.x_mm + (self.cols - 1) * self.pitch_x_mm + self.patch_w_mm,
            self.y_mm + (self.rows - 1) * self.pitch_y_mm + self.patch_h_mm,
        )


def _finite(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


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
    extra_grids
        Further patch grids (other panels, other patch sizes); their patches follow
        the main grid's in ``patch_names``.
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
    extra_grids: tuple[PatchGrid, ...] = ()

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
        grids = tuple(self.extra_grids)
        if not all(isinstance(g, PatchGrid) for g in grids):
            raise InputError(f"layout {self.name!r}: extra_grids must be PatchGrids")
        object.__setattr__(self, "extra_grids", grids)
        n = self.rows * self.cols + sum(g.n_patches for g in grids)
        names = tuple(self.patch_names) or _sg_names(self.rows, self.cols)
        if len(names) != n:
            extra = f" + {n - self.rows * self.cols} in extra grids" if grids else ""
            raise InputError(
                f"layout {self.name!r}: {len(names)} patch names for "
                f"{self.rows}x{self.cols} patches{extra}"
            )
        self._check_grids_fit()
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

    def _check_grids_fit(self) -> None:
        """Every extra grid inside the chart, none overlapping another's patches."""
        boxes = [self._main_bounds_mm(), *(g.bounds_mm() for g in self.extra_grids)]
        for k, (x0, y0, x1, y1) in enumerate(boxes[1:], start=1):
            if x1 > self.width_mm + 1e-6 or y1 > self.height_mm + 1e-6:
                raise InputError(
                    f"layout {self.name!r}: extra grid {k} reaches beyond the "
                    f"{self.width_mm:g} x {self.height_mm:g} mm chart"
                )
            for j, (a0, b0, a1, b1) in enumerate(boxes[:k]):
                if (
                    x0 < a1 - 1e-6
                    and a0 < x1 - 1e-6
                    and y0 < b1 - 1e-6
                    and b0 < y1 - 1e-6
                ):
                    where = "the main grid" if j == 0 else f"extra grid {j}"
                    raise InputError(
                        f"layout {self.name!r}: extra grid {k} overlaps {where}"
                    )

    def _main_bounds_mm(self) -> tuple[float, float, float, float]:
        l, t, r, b = self.margin_mm
        cw, ch = self.cell_size_mm()
        gx, gy = (
            0.5 * cw * (1 - self.patch_fraction),
            0.5 * ch * (1 - self.patch_fraction),
        )
        return (l + gx, t + gy, self.width_mm - r - gx, self.height_mm - b - gy)

    # -- geometry in target millimetres ------------------------------------------
    @property
    def n_patches(self) -> int:
        return self.rows * self.cols + sum(g.n_patches for g in self.extra_grids)

    def cell_size_mm(self) -> tuple[float, float]:
        """(width, height) of one grid cell."""
        l, t, r, b = self.margin_mm
        return (
            (self.width_mm - l - r) / self.cols,
            (self.height_mm - t - b) / self.rows,
        )

    def patch_centers_mm(self) -> NDArray[np.float64]:
        """Patch centres, (n_patches, 2) x/y mm, in the order of ``patch_names``."""
        l, t, _, _ = self.margin_mm
        cw, ch = self.cell_size_mm()
        rr, cc = np.mgrid[0 : self.rows, 0 : self.cols]
        x = l + (cc.ravel() + 0.5) * cw
        y = t + (rr.ravel() + 0.5) * ch
        return np.concatenate(
            [np.stack([x, y], axis=1), *(g.centers_mm() for g in self.extra_grids)]
        )

    def patch_sizes_mm(self) -> NDArray[np.float64]:
        """(width, height) of each patch, (n_patches, 2) mm."""
        cw, ch = self.cell_size_mm()
        main = np.tile(
            [cw * self.patch_fraction, ch * self.patch_fraction],
            (self.rows * self.cols, 1),
        )
        extra = [
            np.tile([g.patch_w_mm, g.patch_h_mm], (g.n_patches, 1))
            for g in self.extra_grids
        ]
        return np.concatenate([main, *extra])

    def patch_quads_mm(self, area_fraction: float = 1.0) -> NDArray[np.float64]:
        """Patch rectangles scaled to ``area_fraction`` of the patch, (n, 4, 2) mm.

        ``area_fraction=1`` is the whole patch; ``self.roi_fraction`` the ROI.
        """
        half = 0.5 * math.sqrt(area_fraction) * self.patch_sizes_mm()
        signs = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
        return self.patch_centers_mm()[:, None, :] + signs[None] * half[:, None, :]

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
        # version 1 when the file has nothing newer: older TuneSpec reads it
        d["version"] = LAYOUT_VERSION if self.extra_grids else 1
        if not self.extra_grids:
            del d["extra_grids"]
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
        atomic_write_text(path, dumps_json(self.to_dict()))

    @classmethod
    def load(cls, path: str | PathLike[str]) -> TargetLayout:
        """A layout from a TuneSpec JSON file or the stem of a shipped layout
        (``"colorchecker_24"``).

        A name with no folder and no suffix that is not a file here is looked up in
        the shipped ``resources/layouts``. An ArgyllCMS ``.cht`` template is read by
        :func:`tunespec.core.io.cht.load_layout`, which takes all three (and which
        every ``--layout`` option uses).
        """
        path = _shipped_layout(path)
        if path.suffix.lower() == ".cht":
            # the data class imports no reader (core.io.cht imports it)
            raise InputError(
                "an ArgyllCMS .cht template, not a tunespec-layout JSON file "
                "(tunespec.core.io.cht.load_layout reads both)",
                path=path,
            )
        d = read_json(path)
        if not isinstance(d, dict):
            raise InputError("expected a JSON object", path=path)
        return cls.from_dict(d, source=str(path))


def shipped_layout_names() -> list[str]:
    """Stems of the shipped layouts (``--layout colorchecker_24``)."""
    from importlib import resources

    folder = resources.files("tunespec.resources").joinpath("layouts")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".json"))


def _shipped_layout(path: str | PathLike[str]) -> Path:
    """``path`` itself, or the shipped layout a bare stem names."""
    p = Path(path)
    text = str(path)
    if p.exists() or p.suffix or "/" in text or "\\" in text:
        return p
    if text in shipped_layout_names():
        from importlib import resources

        ref = resources.files("tunespec.resources").joinpath("layouts", f"{text}.json")
        return Path(str(ref))
    raise InputError(
        f"layout not found (a file, or a shipped layout: "
        f"{', '.join(shipped_layout_names())})",
        path=p,
    )


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
    kw["extra_grids"] = _checked_grids(d.get("extra_grids", []), source)
    return kw


_GRID_KEYS = ("x_mm", "y_mm", "patch_w_mm", "patch_h_mm", "pitch_x_mm", "pitch_y_mm")


def _checked_grids(grids: Any, source: str | None) -> tuple[PatchGrid, ...]:
    """``extra_grids``: a list of objects with rows, cols and the mm of _GRID_KEYS."""
    if not isinstance(grids, list | tuple) or len(grids) > MAX_SIDE:
        raise InputError("extra_grids: expected a list of grid objects", path=source)
    out = []
    for k, g in enumerate(grids):
        key = f"extra_grids[{k}]"
        if not isinstance(g, Mapping):
            raise InputError(f"{key}: expected an object", path=source)
        unknown = set(g) - {"rows", "cols", *_GRID_KEYS}
        if unknown:
            raise InputError(f"{key}: unknown key {sorted(unknown)[0]!r}", path=source)
        kw: dict[str, Any] = {
            n: valid_number(
                g.get(n), f"{key}.{n}", path=source, lo=1, hi=MAX_SIDE, integer=True
            )
            for n in ("rows", "cols")
        }
        total = kw["rows"] * kw["cols"] + sum(g.n_patches for g in out)
        if total > MAX_PATCHES:
            raise InputError(f"{key}: more than {MAX_PATCHES} patches", path=source)
        for n in _GRID_KEYS:
            default = 0.0 if n.startswith("pitch") else None
            kw[n] = float(
                valid_number(
                    g.get(n, default), f"{key}.{n}", path=source, lo=0, hi=MAX_MM
                )
            )
        try:
            out.append(PatchGrid(**kw))
        except InputError as exc:
            raise InputError(f"{key}: {exc.message}", path=source) from None
    return tuple(out)


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
