"""Build the nominal CAL1-like LED set shipped in resources/leds/cal1_model_22.csv.

This is a *model*, not a measurement of a CAL1: 20 narrowband LEDs from colour-science's
LED model (Ohno 2005) with peak wavelengths spread over 410-700 nm and widths taken
from measured LEDs (ISETCam six-LED set: 444/20, 468/24, 508/32, 524/33, 636/20 nm
peak/FWHM), plus two phosphor-converted whites built from the measured 444 nm blue
pump (led450) and the measured phosphor-converted amber (led600) of the same set.
Relative powers follow the usual LED efficiency pattern (strong blue and red, a
"green gap" around 550-590 nm). Run from the repository root:

    python tools/make_led_set.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import colour
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHAPE = colour.SpectralShape(360, 780, 1)

PEAKS_NM = [
    410,
    420,
    435,
    450,
    465,
    480,
    495,
    510,
    525,
    540,
    555,
    570,
    585,
    600,
    615,
    630,
    645,
    660,
    680,
    700,
]
# FWHM vs peak: interpolated through the measured ISETCam LEDs for InGaN (blue-green)
# and typical AlInGaP (amber-red) datasheet values.
FWHM_KNOTS_NM = (
    [410, 444, 468, 508, 524, 555, 585, 636, 700],
    [14, 20, 24, 32, 33, 30, 16, 20, 26],
)
POWER_KNOTS = (
    [410, 450, 500, 530, 560, 590, 620, 660, 700],
    [0.55, 1.0, 0.75, 0.55, 0.30, 0.40, 0.85, 0.9, 0.6],
)


def main() -> None:
    wl = SHAPE.wavelengths
    measured = colour.io.read_sds_from_csv_file(
        ROOT / "resources/leds/isetcam_sixleds.csv"
    )
    blue = (
        measured["led450"]
        .copy()
        .align(SHAPE, extrapolator_kwargs={"method": "Constant", "left": 0, "right": 0})
        .values
    )
    amber = (
        measured["led600"]
        .copy()
        .align(SHAPE, extrapolator_kwargs={"method": "Constant", "left": 0, "right": 0})
        .values
    )
    blue, amber = blue / blue.max(), amber / amber.max()
    cols: dict[str, np.ndarray] = {}
    for peak in PEAKS_NM:
        fwhm = float(np.interp(peak, *FWHM_KNOTS_NM))
        sd = colour.sd_single_led(peak, shape=SHAPE, half_spectral_width=fwhm)
        v = sd.values / sd.values.max() * float(np.interp(peak, *POWER_KNOTS))
        cols[f"LED{peak:03d}"] = v
    yellow = colour.sd_single_led(560, shape=SHAPE, half_spectral_width=110).values
    yellow /= yellow.max()
    cool = 0.9 * blue + 0.45 * yellow + 0.1 * amber
    warm = 0.35 * blue + 0.35 * yellow + 0.6 * amber
    cols["WHITE_COOL"] = cool / cool.max() * 0.8
    cols["WHITE_WARM"] = warm / warm.max() * 0.8
    out = ROOT / "resources/leds/cal1_model_22.csv"
    write_columns_csv(out, wl, cols, ".6g")
    print(f"wrote {out} ({len(cols)} LEDs)")


def write_columns_csv(out: Path, wl: np.ndarray, cols: dict, fmt: str) -> None:
    """A spectral CSV: ``wavelength_nm`` then one column per key of ``cols``."""
    with out.open("w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["wavelength_nm", *cols])
        for i, x in enumerate(wl):
            w.writerow([f"{x:g}", *(format(cols[k][i], fmt) for k in cols)])


if __name__ == "__main__":
    main()
