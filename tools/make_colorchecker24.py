"""Write the shipped ColorChecker 24 chart: reflectances and target layout.

- ``resources/charts/colorchecker_24.csv``: colour-science's ``ColorChecker N Ohta``
  spectral reflectances (BSD-3-Clause), 380-780 nm at 5 nm, named A1 ... D6 (row
  letter A-D top to bottom, column digit 1-6 left to right, ArgyllCMS's naming).
- ``resources/layouts/colorchecker_24.json``: the patch grid of ArgyllCMS's
  ``ref/ColorChecker.cht`` recognition template (4 x 6 patches of 46 units at a 52.5
  unit pitch in a 330 x 228 unit chart box) scaled to the card's published 11 in
  (279.4 mm) width; the ROI is the template's box shrunk by ``BOX_SHRINK`` (6 units).

Run: ``python tools/make_colorchecker24.py [/usr/share/color/argyll/ref/ColorChecker.cht]``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tunespec.core.io.cht import read_cht
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Spectra

ROOT = Path(__file__).resolve().parent.parent
CHT = "/usr/share/color/argyll/ref/ColorChecker.cht"


def main(cht: str = CHT) -> None:
    import colour

    sds = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    names = [f"{r}{c}" for r in "ABCD" for c in range(1, 7)]
    wl = np.asarray(next(iter(sds.values())).wavelengths, dtype=np.float64)
    values = np.array([np.asarray(sd.values, dtype=np.float64) for sd in sds.values()])
    refl = Spectra(wl, values, tuple(names))
    write_spectra_csv(refl, ROOT / "resources/charts/colorchecker_24.csv")
    layout = read_cht(cht).to_layout("ColorChecker 24", width_mm=279.4)
    meta = {
        "reflectances": "charts/colorchecker_24.csv",
        "naming": "letter = row A-D (top to bottom), digit = column 1-6",
        "source": "geometry of ArgyllCMS ref/ColorChecker.cht scaled to 279.4 mm",
    }
    layout = type(layout)(**{**layout.__dict__, "meta": meta})
    layout.save(ROOT / "resources/layouts/colorchecker_24.json")


if __name__ == "__main__":
    main(*sys.argv[1:])
