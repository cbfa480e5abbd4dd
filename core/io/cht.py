"""ArgyllCMS ``.cht`` chart recognition templates, read as target layouts.

A ``.cht`` (ArgyllCMS ``scanin``'s template; the Debian ``argyll-ref`` package installs
``ColorChecker.cht``, ``ColorCheckerSG.cht``, ... in ``/usr/share/color/argyll/ref``)
describes a chart in its own units::

    BOXES 25
      F _ _ 10.0 9.75  321.25 9.75  321.26 217  10.0 217      fiducial marks
      D ALL ALL _ _ 330 228  0 0  0 0                         the whole chart
      Y 1 6 A D  46.0 46.0  12.0 11.5  52.5 52.5              a grid of patches
    BOX_SHRINK 6.0
    EXPECTED XYZ 24
      A1 11.773 10.213 4.9219 ...

A patch line ``X|Y FIRST LAST FIRST2 LAST2 W H XO YO XI YI`` is a grid: the first
label range runs along x (``XI`` apart), the second along y (``YI`` apart), each patch
``W x H`` with its top-left at ``XO + i XI, YO + j YI``. ``X`` names a patch x-part
first (``A1`` = column A, row 1, as the SG), ``Y`` y-part first (``A1`` = row A,
column 1, as the ColorChecker 24). Labels are letters (``A``-``Z``) or numbers (their
zero padding kept, ``01``-``12``). ``BOX_SHRINK`` is the margin scanin leaves inside
every patch when it reads it.

:func:`read_cht` reads the template; :meth:`ChtTemplate.to_layout` turns a template
whose patches form one regular grid (ColorChecker 24, SG, DC) into a
:class:`~tunespec.core.layout.TargetLayout` (the ``D`` box is the outer rectangle, in
the template's units or scaled to ``width_mm``); the ROI is the shrunk box. Templates
of several grids (the Passport) are read but refused by ``to_layout``: the layout
model is one grid (the layout editor's file format; arbitrary boxes are future work).

References
----------
ArgyllCMS ``doc/cht_format.html`` and its ``ref/*.cht`` files (Graeme W. Gill).
"""

from __future__ import annotations

import string
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import MAX_COUNT, read_text, shown

__all__ = ["ChtGrid", "ChtTemplate", "read_cht"]


@dataclass(frozen=True)
class ChtGrid:
    """One ``X``/``Y`` patch line: names and boxes ``(x, y, w, h)`` in template units."""

    names: tuple[str, ...]
    boxes: NDArray[np.float64]
    shape: tuple[int, int]  # (rows along y, columns along x)


@dataclass(frozen=True)
class ChtTemplate:
    """A parsed ``.cht``: fiducials, the chart box, patch grids, box shrink, expected values."""

    source: str
    fiducials: NDArray[np.float64]  # (4, 2), or (0, 2)
    chart_box: tuple[float, float] | None  # (width, height) of a D box at the origin
    grids: tuple[ChtGrid, ...]
    box_shrink: float
    expected: dict[str, tuple[float, ...]]

    @property
    def patch_names(self) -> tuple[str, ...]:
        return tuple(n for g in self.grids for n in g.names)

    def to_layout(
        self, name: str | None = None, *, width_mm: float | None = None
    ) -> TargetLayout:
        """The template as a one-grid :class:`TargetLayout` (row-major names).

        ``width_mm`` scales the template's units to millimetres (default: keep them,
        which the homography does not mind). The ROI is the patch shrunk by
        ``BOX_SHRINK`` on every side, as scanin reads it.

        Raises
        ------
        InputError
            Several patch grids, unequal pitch and size ratios, a grid outside the
            chart box.
        """
        if len(self.grids) != 1:
            raise InputError(
                f"{len(self.grids)} patch grids: TuneSpec's layouts are one regular "
                "grid (a .cht with several, e.g. the Passport, is not supported yet)",
                path=self.source,
            )
        if self.chart_box is None:
            raise InputError(
                "no D (chart) box at the origin (D ALL ALL _ _ W H 0 0 ...): the "
                "chart's outline is unknown",
                path=self.source,
            )
        g = self.grids[0]
        rows, cols = g.shape
        b = g.boxes
        w, h = float(b[0, 2]), float(b[0, 3])
        xi = float(b[1, 0] - b[0, 0]) if cols > 1 else w
        yi = float(b[cols, 1] - b[0, 1]) if rows > 1 else h
        if xi <= 0 or yi <= 0:
            raise InputError(
                "patches must run left to right, top to bottom", path=self.source
            )
        frac = w / xi
        if abs(h / yi - frac) > 0.01 * frac:
            raise InputError(
                f"patch size / pitch differs in x ({frac:.3f}) and y ({h / yi:.3f})",
                path=self.source,
            )
        W, H = self.chart_box
        left = float(b[0, 0]) - 0.5 * (xi - w)
        top = float(b[0, 1]) - 0.5 * (yi - h)
        margins = (left, top, W - left - cols * xi, H - top - rows * yi)
        if min(margins) < -1e-6:
            raise InputError("the patch grid leaves the chart box", path=self.source)
        s = 1.0 if width_mm is None else width_mm / W
        shrunk = max(w - 2 * self.box_shrink, 0.0) * max(h - 2 * self.box_shrink, 0.0)
        return TargetLayout(
            name=name or Path(self.source).stem,
            rows=rows,
            cols=cols,
            width_mm=W * s,
            height_mm=H * s,
            margin_mm=tuple(max(m, 0.0) * s for m in margins),  # type: ignore[arg-type]
            patch_fraction=min(frac, 1.0),
            roi_fraction=min(max(shrunk / (w * h), 1e-3), 1.0),
            patch_names=g.names,
            meta={"source": f"ArgyllCMS template {Path(self.source).name}"},
        )


def _labels(first: str, last: str, *, path: str, line: int) -> list[str]:
    """``A``..``D`` or ``01``..``12``: the label range of a patch line."""
    if first.isdigit() and last.isdigit():
        lo, hi = int(first), int(last)
        width = len(first) if first.startswith("0") else 0
        out = [str(v).zfill(width) for v in range(lo, hi + 1)]
    elif len(first) == len(last) == 1 and first.isalpha() and last.isalpha():
        letters = string.ascii_uppercase if first.isupper() else string.ascii_lowercase
        i, j = letters.find(first), letters.find(last)
        out = list(letters[i : j + 1]) if 0 <= i <= j else []
    elif first == last:
        out = [first]  # a fixed part, e.g. the Passport's "SAT"
    else:
        out = []
    if not out or len(out) > MAX_COUNT:
        raise InputError(
            f"bad label range {shown(first)} to {shown(last)}", path=path, line=line
        )
    return out


def _grid(tokens: list[str], *, path: str, line: int) -> ChtGrid:
    if len(tokens) != 11:
        raise InputError(
            f"{tokens[0]} line: expected 10 values (FIRST LAST FIRST2 LAST2 W H XO YO "
            "XI YI)",
            path=path,
            line=line,
        )
    xs = _labels(tokens[1], tokens[2], path=path, line=line)
    ys = _labels(tokens[3], tokens[4], path=path, line=line)
    try:
        w, h, xo, yo, xi, yi = (float(t) for t in tokens[5:])
    except ValueError:
        raise InputError("not a number in a patch line", path=path, line=line) from None
    names, boxes = [], []
    for j, ly in enumerate(ys):
        for i, lx in enumerate(xs):
            names.append(ly + lx if tokens[0] == "Y" else lx + ly)
            boxes.append((xo + i * xi, yo + j * yi, w, h))
    return ChtGrid(tuple(names), np.array(boxes), (len(ys), len(xs)))


def read_cht(path: str | PathLike[str]) -> ChtTemplate:
    """Read an ArgyllCMS ``.cht`` recognition template.

    Raises
    ------
    InputError
        Naming the file and line: no ``BOXES`` section with patch lines, a malformed
        box line, duplicate patch names.
    """
    path = str(path)
    lines = read_text(path).splitlines()
    fiducials = np.zeros((0, 2))
    chart_box: tuple[float, float] | None = None
    grids: list[ChtGrid] = []
    shrink = 0.0
    expected: dict[str, tuple[float, ...]] = {}
    section = ""
    for lineno, raw in enumerate(lines, start=1):
        tokens = raw.split()
        if not tokens:
            continue
        key = tokens[0]
        if key in ("BOXES", "XLIST", "YLIST", "EXPECTED", "REF_ROTATION"):
            section = key
            continue
        if key == "BOX_SHRINK":
            shrink = _float(tokens, 1, path=path, line=lineno)
            continue
        if section == "BOXES" and key == "F":
            fiducials = np.array(
                [_float(tokens, k, path=path, line=lineno) for k in range(3, 11)]
            ).reshape(4, 2)
        elif section == "BOXES" and key == "D":
            # D ALL ALL _ _ W H XO YO XI YI: a box at (XO, YO); the chart box when
            # it starts at the origin (ColorChecker, SG, DC), a diagnostic area else
            offset = [_float(tokens, k, path=path, line=lineno) for k in (7, 8)]
            if offset == [0.0, 0.0]:
                chart_box = (
                    _float(tokens, 5, path=path, line=lineno),
                    _float(tokens, 6, path=path, line=lineno),
                )
        elif section == "BOXES" and key in ("X", "Y"):
            grids.append(_grid(tokens, path=path, line=lineno))
        elif section == "EXPECTED" and len(tokens) >= 2:
            expected[key] = tuple(
                _float(tokens, k, path=path, line=lineno) for k in range(1, len(tokens))
            )
    if not grids:
        raise InputError(
            "not an ArgyllCMS .cht: expected a BOXES section with X/Y patch lines",
            path=path,
        )
    names = [n for g in grids for n in g.names]
    if len(set(names)) != len(names):
        raise InputError("duplicate patch names in the patch lines", path=path)
    return ChtTemplate(path, fiducials, chart_box, tuple(grids), shrink, expected)


def _float(tokens: list[str], k: int, *, path: str, line: int) -> float:
    try:
        v = float(tokens[k])
    except (IndexError, ValueError):
        raise InputError(
            f"{tokens[0]}: expected a number in field {k + 1}", path=path, line=line
        ) from None
    if not np.isfinite(v) or abs(v) > 1e7:
        raise InputError(f"{tokens[0]}: number out of range", path=path, line=line)
    return v
