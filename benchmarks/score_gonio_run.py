"""Score a ``tunespec gonio-run`` session taken with the simulated camera.

Usage::

    python benchmarks/score_gonio_run.py SESSION

The registry's simulated camera renders the sample layout's model reflectances as a
matte target (no BRDF), so with the light at normal incidence every geometry's truth
is the model reflectance (``resources/charts/neugebauer_cmy_model.csv`` for the CMY
Neugebauer layout). Prints per geometry the spectral RMS of ``gonio.nc``'s
reflectance, the CIEDE2000 (D50) of those spectra and of the single-shot XYZ against
the truth, and the mix kept in ``mix.json``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import xarray as xr

from tunespec.core.colorimetry import delta_e_2000, lab_d50, xyz_d50, xyz_to_lab_d50
from tunespec.core.datasets import resource_path
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.spectra import DEFAULT_GRID


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("session", type=Path)
    ap.add_argument("--layout", default="neugebauer_cmy.json")
    ap.add_argument("--truth", default="neugebauer_cmy_model.csv")
    args = ap.parse_args()
    layout = TargetLayout.load(resource_path("layouts", args.layout))
    truth = read_spectra_csv(resource_path("charts", args.truth))
    truth = truth.select(layout.patch_names).resample(DEFAULT_GRID)
    wl = DEFAULT_GRID.wavelength_nm
    with xr.open_dataset(args.session / "gonio.nc", engine="scipy") as ds:
        R, xyz = ds.reflectance.values, ds.XYZ.values
        spectral, theta_r = ds.spectral.values.astype(bool), ds.theta_r.values
    for g in range(R.shape[1]):
        rms = np.sqrt(np.mean((R[:, g] - truth.values) ** 2))
        de = delta_e_2000(xyz_to_lab_d50(xyz_d50(R[:, g], wl)), lab_d50(truth))
        ss = delta_e_2000(xyz_to_lab_d50(xyz[:, g]), lab_d50(truth))
        kind = "spectral" if spectral[g] else "single shot"
        print(
            f"theta_r {theta_r[g]:5.1f} {kind:<11} RMS {rms:.4f}  dE00 spectra "
            f"{de.mean():.3f} (max {de.max():.2f})  single-shot XYZ {ss.mean():.3f} "
            f"(max {ss.max():.2f})"
        )
    mix = json.loads((args.session / "mix.json").read_text())
    print(f"mix {mix['mix']}: measured {mix['measured']}")


if __name__ == "__main__":
    main()
