"""Single-shot XYZ on the simulated bench: three ways to D50 colorimetry, side by side.

Usage::

    python benchmarks/bench_single_shot.py [--seeds 3] [--cameras NAME ...]

For each camera (default: the 5D Mark III and two others from the database) the bench
is simulated at 1 nm: the ColorChecker SG under the 22 LEDs calibrates the camera
(``estimate_camera_sensitivity``, default method), the LEDs are matched to D50
(``match_illuminant``), and a test set the calibration never saw (colour-science's 190
rawtoaces reflectances) is measured three ways, scored in CIEDE2000 against its true
D50 colorimetry:

- *single shot*: one capture under the matched mix, XYZ by the transform derived from
  the calibrated sensitivities, the mix SPD the light reports and the SG as prior
  (``xyz_transform``, root-polynomial; also the 3x3 variant);
- *baseline*: the same capture, a 3x3 fitted by least squares on the SG's measured RGB;
- *spectral*: the full 22-LED capture and Wiener estimation (Eq. 5-6);

and again under the mix optimised for the camera (``optimise_mix_for_camera``, CIE 51.2
category B kept). Prints mean / 95th percentile dE00 per camera and seed.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from tunespec.core.colorimetry import delta_e_2000, lab_d50, xyz_d50, xyz_to_lab_d50
from tunespec.core.datasets import (
    load_camera,
    load_colorchecker_sg,
    load_training_reflectances_190,
    resource_path,
)
from tunespec.core.illuminant_match import (
    colour_rendering,
    illuminant_spd,
    match_illuminant,
)
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.sensitivity import estimate_camera_sensitivity
from tunespec.core.simulate import simulate_capture
from tunespec.core.single_shot import (
    fit_chart_matrix,
    optimise_mix_for_camera,
    xyz_transform,
)
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra
from tunespec.core.wiener import wiener_reflectance

FINE = Grid(380.0, 730.0, 1.0)


def _stats(de: np.ndarray) -> str:
    return f"{de.mean():5.2f} / {np.percentile(de, 95):5.2f}"


def run_camera(name: str | None, seed: int) -> dict[str, np.ndarray]:
    """Every method's dE00 over the test set for one camera and seed."""
    leds = read_spectra_csv(resource_path("leds", "cal1_model_22.csv"), FINE)
    cam = load_camera(name, FINE) if name else load_camera(grid=FINE)
    sg_f, sg = load_colorchecker_sg(FINE), load_colorchecker_sg()
    test = load_training_reflectances_190(FINE)
    truth = lab_d50(test)
    resp, rep = simulate_capture(sg_f, leds, cam, grid=DEFAULT_GRID, rng=seed)
    est = estimate_camera_sensitivity(resp, rep, sg)
    S = est.sensitivity
    r22, rep22 = simulate_capture(test, leds, cam, grid=DEFAULT_GRID, rng=seed + 100)
    w = wiener_reflectance(r22, est.correct_illuminants(rep22), S, sg)
    out = {"spectral (22 LEDs)": delta_e_2000(lab_d50(w.reflectance), truth)}
    plain = match_illuminant(leds, illuminant_spd("D50"), sg)
    tuned = optimise_mix_for_camera(leds, S, sg, plain.levels)
    both = Spectra(FINE.wavelength_nm, np.vstack([sg_f.values, test.values]),
                   sg_f.names + test.names)  # fmt: skip
    for label, levels in (("D50 match", plain.levels), ("camera-tuned", tuned.levels)):
        mix = Spectra(FINE.wavelength_nm, levels @ leds.values, ("mix",))
        r, reported = simulate_capture(
            both, mix, cam, grid=DEFAULT_GRID, rng=seed + 200
        )
        rgb = r.rgb[:, 0, :]
        for kind in ("root-polynomial", "matrix"):
            T = xyz_transform(S, reported, sg, kind=kind)
            out[f"{label}: single shot {kind}"] = delta_e_2000(
                xyz_to_lab_d50(T(rgb[len(sg) :])), truth
            )
        M = fit_chart_matrix(rgb[: len(sg)], xyz_d50(sg))
        out[f"{label}: baseline SG 3x3"] = delta_e_2000(
            xyz_to_lab_d50(rgb[len(sg) :] @ M.T), truth
        )
        ra, rf = colour_rendering(Spectra(FINE.wavelength_nm, mix.values, ("m",)))
        print(f"  {label} mix: Ra {ra:.1f}, Rf {rf:.1f}"
              + (f", metamerism {tuned.metamerism_de00:.2f}" if label != "D50 match" else ""))  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--cameras", nargs="*", default=[
        "Canon EOS 5D Mark III", "Nikon D810", "Sony ILCE-7RM2"])  # fmt: skip
    args = ap.parse_args()
    from tunespec.core.datasets import camera_names

    known = camera_names()
    for name in args.cameras:
        if name not in known:
            near = [k for k in known if name.split()[0].lower() in k.lower()][:5]
            print(f"skip {name}: not in the database (e.g. {', '.join(near)})")
            continue
        for seed in range(args.seeds):
            print(f"{name}, seed {seed}: mean / p95 dE00 over 190 reflectances")
            for label, de in run_camera(name, seed).items():
                print(f"  {label:<40} {_stats(de)}")


if __name__ == "__main__":
    main()
