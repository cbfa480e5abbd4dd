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
whose patches form regular grids (ColorChecker 24, SG, DC, Passport, IT8.7/2) into a
:class:`~tunespec.core.layout.TargetLayout` (the ``D`` box is the outer rectangle, in
the template's units or scaled to ``width_mm``); the ROI is the shrunk box. Templates
of several grids (the Passport's panels, the IT8.7/2's grey scale) become a layout
with ``extra_grids``; labels may carry a prefix (``GS00``-``GS23``) and ``_`` is an
empty part.

References
----------
ArgyllCMS ``doc/cht_format.html`` and its ``ref/*.cht`` files (Graeme W. Gill).
"""

from __future__ import annotations

import math
import string
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError
from tunespec.core.layout import PatchGrid, TargetLayout
from tunespec.core.limits import MAX_COUNT, read_text, shown

__all__ = ["ChtGrid", "ChtTemplate", "load_layout", "read_cht"]

#: A main grid whose patch size / pitch differs in x and y by up to this is drawn
#: with their geometric mean (SpyderChecker: 42 on 49 and 50, 2 %).
MAX_FRACTION_MISMATCH = 0.05
#: Patches of an extra grid wider than their pitch by up to this are cut to it.
MAX_OVERLAP = 0.01


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
    chart_box: tuple[float, float, float, float] | None  # D ALL box: x0, y0, w, h
    grids: tuple[ChtGrid, ...]
    box_shrink: float
    expected: dict[str, tuple[float, ...]]

    @property
    def patch_names(self) -> tuple[str, ...]:
        return tuple(n for g in self.grids for n in g.names)

    def to_layout(
        self, name: str | None = None, *, width_mm: float | None = None
    ) -> TargetLayout:
        """The template as a :class:`TargetLayout`: its largest patch grid is the
        layout's main grid, the others (the Passport's panels, the IT8's grey steps)
        its ``extra_grids``; names row-major per grid, top to bottom.

        The chart's outline is the ``D ALL`` box (at its offset, e.g. the IT8's
        ``1 1``) when it holds every patch centre, grown to hold patches that
        overhang it; otherwise the box around the patches and fiducials, widened by
        half the smallest patch side (the Passport's ``D ALL`` is a small strip).
        ``width_mm`` scales the template's units to millimetres (default: keep
        them, which the homography does not mind). The ROI is the
        patch shrunk by ``BOX_SHRINK`` on every side, as scanin reads it (for the
        main grid's patch size; TuneSpec has one ROI fraction per layout).

        Raises
        ------
        InputError
            A main grid whose size/pitch differ in x and y, grids that overlap.
        """
        grids = [_upright(g) for g in self.grids]
        x0, y0, W, H = self._outline(grids)
        main = max(range(len(grids)), key=lambda k: len(grids[k][0]))
        names, b, (rows, cols) = grids[main]
        w, h = float(b[0, 2]), float(b[0, 3])
        xi = float(b[1, 0] - b[0, 0]) if cols > 1 else w
        yi = float(b[cols, 1] - b[0, 1]) if rows > 1 else h
        if min(w, h, xi, yi) <= 0:
            raise InputError(
                "a patch grid with zero patch size or pitch", path=self.source
            )
        meta = {"source": f"ArgyllCMS template {Path(self.source).name}"}
        frac = w / xi
        if abs(h / yi - frac) > 0.01 * frac:
            # one patch fraction per layout: the patch centres stay exact (they
            # follow the pitch), the patch is drawn a little off in size
            if abs(h / yi - frac) > MAX_FRACTION_MISMATCH * frac:
                raise InputError(
                    f"patch size / pitch differs in x ({frac:.3f}) and y "
                    f"({h / yi:.3f}) by more than {MAX_FRACTION_MISMATCH:.0%}",
                    path=self.source,
                )
            meta["approximation"] = (
                f"patch size / pitch {frac:.3f} in x and {h / yi:.3f} in y, drawn "
                f"as {math.sqrt(frac * h / yi):.3f} (centres exact)"
            )
            frac = math.sqrt(frac * h / yi)
        left = float(b[0, 0]) - x0 - 0.5 * (xi - w)
        top = float(b[0, 1]) - y0 - 0.5 * (yi - h)
        # the grid's cells (half a gap around the outer patches) may reach past
        # the chart box (QPcard 201): grow the outline to hold them
        grow_l, grow_t = max(-left, 0.0), max(-top, 0.0)
        x0, y0, W, H = x0 - grow_l, y0 - grow_t, W + grow_l, H + grow_t
        left, top = left + grow_l, top + grow_t
        W = max(W, left + cols * xi)
        H = max(H, top + rows * yi)
        margins = (left, top, W - left - cols * xi, H - top - rows * yi)
        s = 1.0 if width_mm is None else width_mm / W
        extra, extra_names = [], []
        for k, (gn, gb, (gr, gc)) in enumerate(grids):
            if k == main:
                continue
            extra_names.extend(gn)
            pw, ph = float(gb[0, 2]), float(gb[0, 3])
            px = float(gb[1, 0] - gb[0, 0]) if gc > 1 else 0.0
            py = float(gb[gc, 1] - gb[0, 1]) if gr > 1 else 0.0
            # patches a hair wider than their pitch (it8Wolf's grey scale: 25.625
            # on 25.57) are drawn as wide as the pitch
            if gc > 1 and px < pw <= px * (1 + MAX_OVERLAP):
                pw = px
            if gr > 1 and py < ph <= py * (1 + MAX_OVERLAP):
                ph = py
            try:
                extra.append(
                    PatchGrid(
                        rows=gr,
                        cols=gc,
                        x_mm=(float(gb[0, 0]) - x0) * s,
                        y_mm=(float(gb[0, 1]) - y0) * s,
                        patch_w_mm=pw * s,
                        patch_h_mm=ph * s,
                        pitch_x_mm=px * s,
                        pitch_y_mm=py * s,
                    )
                )
            except InputError as exc:
                raise InputError(
                    f"patch grid {gn[0]}..{gn[-1]}: {exc.message}", path=self.source
                ) from None
        shrunk = max(w - 2 * self.box_shrink, 0.0) * max(h - 2 * self.box_shrink, 0.0)
        try:
            return TargetLayout(
                name=name or Path(self.source).stem,
                rows=rows,
                cols=cols,
                width_mm=W * s,
                height_mm=H * s,
                margin_mm=tuple(max(m, 0.0) * s for m in margins),  # type: ignore[arg-type]
                patch_fraction=min(frac, 1.0),
                roi_fraction=min(max(shrunk / (w * h), 1e-3), 1.0),
                patch_names=(*names, *extra_names),
                meta=meta,
                extra_grids=tuple(extra),
            )
        except InputError as exc:
            raise InputError(exc.message, path=self.source) from None

    def _outline(
        self, grids: list[tuple[tuple[str, ...], NDArray[np.float64], tuple[int, int]]]
    ) -> tuple[float, float, float, float]:
        """(x0, y0, width, height) of the chart in template units."""
        boxes = np.concatenate([b for _, b, _ in grids])
        lo = boxes[:, :2].min(axis=0)
        hi = (boxes[:, :2] + boxes[:, 2:]).max(axis=0)
        centres = boxes[:, :2] + 0.5 * boxes[:, 2:]
        box = self.chart_box
        if box is not None and np.all(
            (centres >= [box[0], box[1]])
            & (centres <= [box[0] + box[2], box[1] + box[3]])
        ):
            # the D box, grown to hold patches that overhang it (the IT8's grey
            # scale starts 1 unit left of its D box)
            x0, y0, W, H = box
            lo = np.minimum(lo, [x0, y0])
            hi = np.maximum(hi, [x0 + W, y0 + H])
            return (
                float(lo[0]),
                float(lo[1]),
                float(hi[0] - lo[0]),
                float(hi[1] - lo[1]),
            )
        if len(self.fiducials):
            lo = np.minimum(lo, self.fiducials.min(axis=0))
            hi = np.maximum(hi, self.fiducials.max(axis=0))
        pad = 0.5 * float(boxes[:, 2:].min())
        lo = np.maximum(lo - pad, 0.0)
        hi = hi + pad
        return float(lo[0]), float(lo[1]), float(hi[0] - lo[0]), float(hi[1] - lo[1])


def _upright(
    g: ChtGrid,
) -> tuple[tuple[str, ...], NDArray[np.float64], tuple[int, int]]:
    """A grid's names and boxes with positive pitches (rows top to bottom, columns
    left to right): Argyll's lines may step backwards (the Passport's ``-15.0``)."""
    rows, cols = g.shape
    b = g.boxes.reshape(rows, cols, 4)
    n = np.array(g.names, dtype=object).reshape(rows, cols)
    if cols > 1 and b[0, 1, 0] < b[0, 0, 0]:
        b, n = b[:, ::-1], n[:, ::-1]
    if rows > 1 and b[1, 0, 1] < b[0, 0, 1]:
        b, n = b[::-1], n[::-1]
    return tuple(str(v) for v in n.ravel()), b.reshape(-1, 4).copy(), (rows, cols)


def _labels(first: str, last: str, *, path: str, line: int) -> list[str]:
    """``A``..``D`` or ``01``..``12``: the label range of a patch line."""
    if first == last == "_":
        return [""]  # no second part, e.g. the IT8's grey steps GS00 ... GS23
    pre, pre2 = first.rstrip(string.digits), last.rstrip(string.digits)
    if pre == pre2 and first[len(pre) :].isdigit() and last[len(pre) :].isdigit():
        lo, hi = int(first[len(pre) :]), int(last[len(pre) :])
        digits = first[len(pre) :]
        width = len(digits) if digits.startswith("0") else 0
        out = [pre + str(v).zfill(width) for v in range(lo, hi + 1)]
    elif (
        len(first) == len(last)
        and first[:-1] == last[:-1]
        and first[-1].isalpha()
        and last[-1].isalpha()
    ):
        # a letter range after a common prefix: A..D, or 2A..2D (CMP Digital Target)
        stem, a, b = first[:-1], first[-1], last[-1]
        letters = string.ascii_uppercase if a.isupper() else string.ascii_lowercase
        i, j = letters.find(a), letters.find(b)
        out = [stem + c for c in letters[i : j + 1]] if 0 <= i <= j else []
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
        elif section == "BOXES" and key == "D" and tokens[1:3] == ["ALL", "ALL"]:
            # D ALL ALL _ _ W H XO YO XI YI: the whole chart at (XO, YO) for the
            # ColorChecker, SG, DC and IT8 (to_layout checks that it holds the patches)
            chart_box = tuple(  # type: ignore[assignment]
                _float(tokens, k, path=path, line=lineno) for k in (7, 8, 5, 6)
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


def load_layout(path: str | PathLike[str]) -> TargetLayout:
    """A layout from a file: TuneSpec JSON, an ArgyllCMS ``.cht`` template (by its
    suffix), or the stem of a shipped layout (``"colorchecker_24"``).

    What every ``--layout`` option and the ``chart.layout``/``sample.layout`` keys of
    a run config take; :meth:`TargetLayout.load` reads the JSON alone.
    """
    if Path(path).suffix.lower() == ".cht":
        return read_cht(path).to_layout()
    return TargetLayout.load(path)
