"""Build the sample target shipped in resources/: 8 CMY Neugebauer primaries (a model).

Reflectances of the eight Neugebauer primaries of a CMY(W) printer, as in the paper's
Table 2, from a simple two-pass Beer-Lambert model: a white base with the usual fall
towards the violet, times the squared transmittance of each colorant layer (smooth
absorption bands of typical cyan, magenta and yellow dyes), plus 2 % first-surface
reflection. This is a model, not a measurement. Run from the repository root:

    python tools/make_sample_target.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from make_led_set import write_columns_csv  # a sibling script (tools/)

ROOT = Path(__file__).resolve().parents[1]


def absorbance(
    wl: np.ndarray, centre: float, width: float, edge: float = 0.0
) -> np.ndarray:
    a = np.exp(-0.5 * ((wl - centre) / width) ** 2)
    if edge:  # a dye whose absorption continues into the short wavelengths
        a = np.maximum(a, 1.0 / (1.0 + np.exp((wl - centre) / edge)))
    return a


def main() -> None:
    wl = np.arange(380.0, 781.0, 5.0)
    base = 0.86 - 0.30 * np.exp(-(wl - 380.0) / 22.0) + 0.02 * np.sin((wl - 380) / 70)
    dyes = {
        "C": 1.25 * absorbance(wl, 630.0, 55.0) + 0.10 * absorbance(wl, 420.0, 30.0),
        "M": 1.35 * absorbance(wl, 540.0, 38.0) + 0.12 * absorbance(wl, 420.0, 40.0),
        "Y": 1.50 * absorbance(wl, 445.0, 28.0, edge=12.0),
    }
    cols = {}
    for c, m, y in [
        (0, 0, 0),
        (1, 0, 0),
        (0, 0, 1),
        (1, 0, 1),
        (0, 1, 0),
        (1, 1, 0),
        (0, 1, 1),
        (1, 1, 1),
    ]:
        a = c * dyes["C"] + m * dyes["M"] + y * dyes["Y"]
        cols[f"C{c}M{m}Y{y}"] = 0.02 + (base - 0.02) * np.exp(-2.0 * a)
    write_columns_csv(
        ROOT / "resources/charts/neugebauer_cmy_model.csv", wl, cols, ".6f"
    )
    layout = {
        "format": "tunespec-layout",
        "version": 1,
        "name": "CMY Neugebauer primaries",
        "rows": 2,
        "cols": 4,
        "width_mm": 100.0,
        "height_mm": 55.0,
        "margin_mm": [5.0, 5.0, 5.0, 5.0],
        "patch_fraction": 0.875,
        "roi_fraction": 0.2,
        "patch_names": list(cols),
        "corners_px": None,
        "meta": {
            "reflectances": "charts/neugebauer_cmy_model.csv",
            "patch_size": "1.75 cm as in the paper",
        },
    }
    _write_layout("neugebauer_cmy.json", layout)
    sg = {
        "format": "tunespec-layout",
        "version": 1,
        "name": "ColorChecker SG",
        "rows": 10,
        "cols": 14,
        "width_mm": 279.4,
        "height_mm": 215.9,
        "margin_mm": [13.7, 13.95, 13.7, 13.95],
        "patch_fraction": 0.88,
        "roi_fraction": 0.2,
        "patch_names": [],
        "corners_px": None,
        "meta": {
            "reflectances": "charts/colorchecker_sg.csv",
            "naming": "letter = column A-N, digit = row 1-10",
        },
    }
    _write_layout("colorchecker_sg.json", sg)
    print("wrote sample target reflectances and layouts")


def _write_layout(name: str, layout: dict) -> None:
    (ROOT / "resources/layouts" / name).write_text(json.dumps(layout, indent=2) + "\n")


if __name__ == "__main__":
    main()
