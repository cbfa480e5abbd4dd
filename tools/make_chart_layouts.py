"""Write the shipped IT8.7/2 and ColorChecker Passport target layouts.

- ``resources/layouts/it8_7_2.json``: the IT8.7/2 reflective target (ANSI IT8.7/2-1993,
  ISO 12641:1997) in its common 4 x 6 in print, built from the standard's field
  geometry: square fields of 1/4 in (6.35 mm) on a 24 x 16 field card, 12 rows
  ``A``-``L`` x 22 columns ``01``-``22`` of colour fields starting one field in from the
  top-left corner, and the 24-step grey scale ``GS00`` (white) ... ``GS23`` (black) of
  fields 1 x 2 fields high along the bottom (rows 14-15), from the left edge to the
  right. Names as ArgyllCMS's ``ref/it8.cht`` and the vendors' CGATS reference files.
  ROI: the field shrunk by 1/8 of its side on every side (``it8.cht``'s
  ``BOX_SHRINK 3.2`` of its 25.625-unit fields).
- ``resources/layouts/colorchecker_passport.json``: X-Rite ColorChecker Passport, both
  panels as ArgyllCMS's ``ref/ColorCheckerPassport.cht`` recognition template draws
  them (Graeme W. Gill; units taken as millimetres): the classic 24 patches (``A1``
  ... ``D6``, the ColorChecker 24's names and colours) in portrait on the right, the
  creative-enhancement panel on the left (8 saturated ``SAT1``-``SAT8``, white balance
  ``WBP1``-``WBP5`` and ``WBL1``-``WBL5``, 8 neutrals ``NEU1``-``NEU8``). The numbers
  below are that template's patch lines; the chart's outline is the box around
  patches and fiducials widened by half the smallest patch (5 mm), as
  :meth:`~tunespec.core.io.cht.ChtTemplate.to_layout` reads any ``.cht`` without a
  chart box.

Run: ``python tools/make_chart_layouts.py``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from tunespec.core.io.cht import read_cht
from tunespec.core.layout import PatchGrid, TargetLayout

ROOT = Path(__file__).resolve().parent.parent
FIELD_MM = 6.35  # 1/4 in
#: ArgyllCMS ref/ColorCheckerPassport.cht, its BOXES and BOX_SHRINK lines.
PASSPORT_CHT = """BOXES 51
  F _ _ 97.0 17.0 157.3 17.0 157.3 107.0 97.0 107.0
  X SAT SAT 1 8 10.0 10.0 13.5 102.1  0.0 -12.9
  X WBP WBP 1 5 13.4 13.4 26.4  87.0  0.0 -16.0
  X WBL WBL 1 5 13.4 13.4 42.5  87.0  0.0 -16.0
  X NEU NEU 1 8 10.0 10.0 58.6 102.1  0.0 -12.9
  X   A   D 1 6 12.4 12.4 98.5  93.4 15.0 -15.0
BOX_SHRINK 2.0
"""


def it8_layout() -> TargetLayout:
    """The IT8.7/2 from its field geometry (see the module docstring)."""
    f = FIELD_MM
    colour = [f"{r}{c:02d}" for r in "ABCDEFGHIJKL" for c in range(1, 23)]
    grey = [f"GS{k:02d}" for k in range(24)]
    return TargetLayout(
        name="IT8.7/2",
        rows=12,
        cols=22,
        width_mm=24 * f,
        height_mm=16 * f,
        margin_mm=(f, f, f, 3 * f),
        patch_fraction=1.0,
        roi_fraction=(1 - 2 * 3.2 / 25.625) ** 2,
        patch_names=(*colour, *grey),
        extra_grids=(PatchGrid(1, 24, 0.0, 14 * f, f, 2 * f, f, 0.0),),
        meta={
            "source": "ANSI IT8.7/2-1993 / ISO 12641 layout, 1/4 in fields on a "
            "4 x 6 in card (as ArgyllCMS ref/it8.cht)",
            "naming": "row letter A-L + column 01-22; grey scale GS00 (white) ... GS23",
            "reflectances": "batch-specific: use the vendor's CGATS reference file",
        },
    )


def passport_layout() -> TargetLayout:
    """The ColorChecker Passport from ArgyllCMS's template numbers."""
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "ColorCheckerPassport.cht"
        p.write_text(PASSPORT_CHT, encoding="utf-8")
        lay = read_cht(p).to_layout("ColorChecker Passport")
    meta = {
        "source": "ArgyllCMS ref/ColorCheckerPassport.cht patch lines, units as mm",
        "naming": "classic panel A1 ... D6 as the ColorChecker 24 (portrait, right); "
        "creative panel SAT1-8, WBP1-5, WBL1-5, NEU1-8 (left)",
        "reflectances": "charts/colorchecker_24.csv for A1 ... D6",
    }
    return TargetLayout(**{**lay.__dict__, "meta": meta})


def main() -> None:
    it8_layout().save(ROOT / "resources/layouts/it8_7_2.json")
    passport_layout().save(ROOT / "resources/layouts/colorchecker_passport.json")


if __name__ == "__main__":
    main()
