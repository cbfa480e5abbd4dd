"""Leave-one-camera-out benchmark of the sensitivity estimators (``pca`` vs ``smooth``).

For every camera of the shipped database (52), with that camera *excluded* from the
database the estimators may use:

1. Simulate the calibration capture realistically: ColorChecker SG under the 22-LED
   set, rendered on a 1 nm grid (close to the continuous Eq. 1), exposure set per LED
   so the brightest patch reaches 80 % of full scale, photon + read noise of the
   5D Mark III averaged over 400 ROI pixels, a 0.3 % flat-field residual per patch
   and LED, and a spectroradiometer that reports the SPDs shifted by 1 nm with a 1 %
   power error per LED. The estimators work on the 380-730 nm / 5 nm grid with the
   *reported* SPDs.
2. Estimate the sensitivities with ``pca`` (the paper's Eq. 4, 4 components),
   ``smooth`` (the default, which also fits the spectroradiometer's wavelength
   shift) and ``smooth-noshift`` (``fit_spd_shift=False``; with the shift fitted it is
   undone before Wiener estimation).
3. Score them:

   * sensitivity RMS: each channel of the estimated and of the true set is divided by
     its own peak, then the RMS over all wavelengths and the three channels
     (:func:`tunespec.core.stats.sensitivity_rms`; 0.01 = 1 % of the peak);
   * Table 1 of the paper (response prediction errors) on the 3080 fitted stimuli,
     and on patches held aside from a second fit (every 5th patch, 28 x 22 stimuli);
   * Table 2-like: the 190 rawtoaces training reflectances (not used as the prior)
     captured under the same LEDs and exposures with the same noise, reflectances by
     Wiener estimation (Eq. 5-6, SG prior) with each estimated sensitivity, CIEDE2000
     (D50) and spectral RMS against the truth. Skipped if ``core.wiener`` or
     ``core.colorimetry`` are not importable.

Targets (issue "Core engine"): ``smooth`` beats ``pca`` on the median sensitivity RMS,
``smooth`` median sensitivity RMS <= 0.02, and mean dE00 <= 0.3 on the 190 set. The
last one is out of reach without ``fit_spd_shift``: a 1 nm wavelength error of the
reported SPDs alone costs about 0.3-0.5 dE00, even with the *true* sensitivity (the
``truth`` column), because no sensitivity can absorb it.

Usage::

    python benchmarks/loo_cameras.py              # all 52 cameras, seed 0 (~30 s)
    python benchmarks/loo_cameras.py --cameras 10 --seed 1 --json out.json

Exit status 1 if a target of the default ``smooth`` is missed (``smooth-noshift``
misses the dE00 target, see above; it is printed for comparison).
"""

from __future__ import annotations

import os

# The matrices here are small (71 x 71); BLAS threads only add overhead and, on a
# shared machine, contention. Set before numpy is imported; override from the shell.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tunespec.core.datasets import (
    DEFAULT_CAMERA,
    load_camera_database,
    load_colorchecker_sg,
    load_led_set,
    load_training_reflectances_190,
)
from tunespec.core.sensitivity import estimate_camera_sensitivity
from tunespec.core.simulate import (
    NoiseModel,
    perturb_spd,
    scale_to_exposure,
    simulate_responses,
)
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra
from tunespec.core.stats import (
    PredictionStats,
    calibration_report,
    sensitivity_rms,
    split_patches,
)

try:
    from tunespec.core.colorimetry import reflectance_stats
    from tunespec.core.wiener import wiener_reflectance
except ImportError:  # another part of the engine, may not be there yet
    wiener_reflectance = None  # type: ignore[assignment]
    reflectance_stats = None  # type: ignore[assignment]

#: Variants compared: label -> (method, fit_spd_shift).
VARIANTS: dict[str, tuple[str, bool]] = {
    "pca": ("pca", False),
    "smooth-noshift": ("smooth", False),
    "smooth": ("smooth", True),
}
METHODS = tuple(VARIANTS)
#: Rendering grid of the simulated truth (1 nm: close to the continuous integral).
FINE_GRID = Grid(380.0, 730.0, 1.0)
#: Spectroradiometer errors: 1 nm wavelength-scale shift, 1 % power error per LED.
SHIFT_NM = 1.0
SCALE_SIGMA = 0.01
EXPOSURE_TARGET = 0.8


@dataclass
class CameraResult:
    """Scores of both methods for one held-out camera."""

    camera: str
    rms: dict[str, float] = field(default_factory=dict)
    table1: dict[str, PredictionStats] = field(default_factory=dict)
    table1_held: dict[str, PredictionStats] = field(default_factory=dict)
    de00: dict[str, float] = field(default_factory=dict)
    spec_rms: dict[str, float] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    shift: dict[str, float] = field(default_factory=dict)


@dataclass
class Setup:
    """Data shared by all cameras."""

    work: Grid
    db_work: dict[str, Spectra]
    db_fine: dict[str, Spectra]
    sg_work: Spectra
    sg_fine: Spectra
    leds_fine: Spectra
    t190_work: Spectra | None
    t190_fine: Spectra | None


def load_setup(work: Grid = DEFAULT_GRID, *, with_190: bool = True) -> Setup:
    """Load the database, chart, LEDs (and the 190 set) on both grids."""
    t190_fine = t190_work = None
    if with_190:
        t190_fine = load_training_reflectances_190(FINE_GRID)
        t190_work = load_training_reflectances_190(work)
    return Setup(
        work=work,
        db_work=load_camera_database(work),
        db_fine=load_camera_database(FINE_GRID),
        sg_work=load_colorchecker_sg(work),
        sg_fine=load_colorchecker_sg(FINE_GRID),
        leds_fine=load_led_set(FINE_GRID),
        t190_work=t190_work,
        t190_fine=t190_fine,
    )


def run_camera(
    setup: Setup,
    camera: str,
    rng: np.random.Generator,
    *,
    noise: NoiseModel | None = NoiseModel(),  # noqa: B008 (frozen)
    held_out: bool = True,
    table2: bool = True,
) -> CameraResult:
    """Simulate one camera's capture and score both methods with it left out."""
    truth_fine = setup.db_fine[camera]
    truth = setup.db_work[camera]
    scaled = scale_to_exposure(
        setup.sg_fine, setup.leds_fine, truth_fine, target=EXPOSURE_TARGET
    )
    responses = simulate_responses(
        setup.sg_fine, scaled, truth_fine, noise=noise, rng=rng
    )
    reported = perturb_spd(
        scaled, shift_nm=SHIFT_NM, scale_sigma=SCALE_SIGMA, rng=rng
    ).resample(setup.work)
    resp190 = None
    do_t2 = table2 and wiener_reflectance is not None and setup.t190_fine is not None
    if do_t2:
        resp190 = simulate_responses(
            setup.t190_fine, scaled, truth_fine, noise=noise, rng=rng
        )
    fit_patches, held_patches = split_patches(responses.patches)
    out = CameraResult(camera)
    for label, (method, fit_shift) in VARIANTS.items():

        def fit(resp, method=method, fit_shift=fit_shift):
            return estimate_camera_sensitivity(
                resp,
                reported,
                setup.sg_work,
                method=method,
                database=setup.db_work,
                exclude=camera,
                fit_spd_shift=fit_shift,
            )

        t0 = time.perf_counter()
        est = fit(responses)
        out.seconds[label] = time.perf_counter() - t0
        out.rms[label] = sensitivity_rms(est.sensitivity, truth)
        out.shift[label] = est.spd_shift_nm
        out.table1[label] = calibration_report(
            est, responses, reported, setup.sg_work
        ).training
        if held_out:
            est_fit = fit(responses.subset(list(fit_patches)))
            rep = calibration_report(
                est_fit,
                responses,
                reported,
                setup.sg_work,
                held_out_patches=held_patches,
            )
            assert rep.held_out is not None
            out.table1_held[label] = rep.held_out
        if do_t2:
            assert resp190 is not None and setup.t190_work is not None
            w = wiener_reflectance(
                resp190,
                est.correct_illuminants(reported),
                est.sensitivity,
                setup.sg_work,
            )
            st = reflectance_stats(w.reflectance, setup.t190_work)
            out.de00[label] = st.mean_delta_e00
            out.spec_rms[label] = st.mean_spectral_rms
    if do_t2:
        # The floor: Wiener with the true sensitivity (and the same reported SPDs).
        assert resp190 is not None and setup.t190_work is not None
        w = wiener_reflectance(resp190, reported, truth, setup.sg_work)
        st = reflectance_stats(w.reflectance, setup.t190_work)
        out.de00["truth"] = st.mean_delta_e00
        out.spec_rms["truth"] = st.mean_spectral_rms
    return out


def summarize(results: list[CameraResult]) -> dict[str, Any]:
    """Medians (and means, maxima) over cameras, JSON-friendly."""

    def agg(values: list[float]) -> dict[str, float]:
        a = np.asarray(values)
        return {
            "median": float(np.median(a)),
            "mean": float(a.mean()),
            "max": float(a.max()),
        }

    summary: dict[str, Any] = {"n_cameras": len(results)}
    for method in METHODS:
        s: dict[str, Any] = {
            "sensitivity_rms": agg([r.rms[method] for r in results]),
            "table1_rgb_mean": agg([r.table1[method].mean[3] for r in results]),
            "table1_rgb_max": agg([r.table1[method].max[3] for r in results]),
            "seconds": agg([r.seconds[method] for r in results]),
        }
        if all(method in r.table1_held for r in results):
            s["held_out_rgb_mean"] = agg(
                [r.table1_held[method].mean[3] for r in results]
            )
        if all(method in r.de00 for r in results):
            s["de00_190_mean"] = agg([r.de00[method] for r in results])
            s["spectral_rms_190_mean"] = agg([r.spec_rms[method] for r in results])
        summary[method] = s
    if results and all("truth" in r.de00 for r in results):
        summary["truth"] = {
            "de00_190_mean": agg([r.de00["truth"] for r in results]),
            "spectral_rms_190_mean": agg([r.spec_rms["truth"] for r in results]),
        }
    return summary


SHORT = {
    "pca": "pca",
    "smooth-noshift": "noshift",
    "smooth": "smooth",
    "truth": "truth",
}


def print_report(results: list[CameraResult], summary: dict[str, Any]) -> None:
    """Side-by-side table per camera, the medians and Table 1 for the 5D Mark III."""
    t2 = "de00_190_mean" in summary["smooth"]
    groups: list[tuple[str, list[str], str]] = [
        ("sensitivity RMS", list(METHODS), "7.4f"),
        ("Table 1 RGB mean", list(METHODS), "7.4f"),
    ]
    if t2:
        groups.append(("mean dE00, 190 set", [*METHODS, "truth"], "7.3f"))

    def cell(r: CameraResult, g: int, key: str) -> float:
        if g == 0:
            return r.rms[key]
        if g == 1:
            return float(r.table1[key].mean[3])
        return r.de00[key]

    summary_key = {0: "sensitivity_rms", 1: "table1_rgb_mean", 2: "de00_190_mean"}
    top = f"{'':<26}" + "".join(
        f"| {title:<{8 * len(keys) - 2}}" for title, keys, _ in groups
    )
    head = f"{'camera':<26}" + "".join(
        "|" + "".join(f"{SHORT[k]:>8}" for k in keys)[1:] for _, keys, _ in groups
    )
    print(top)
    print(head)
    print("-" * len(head))
    for r in results:
        line = f"{r.camera[:25]:<26}"
        for g, (_, keys, f) in enumerate(groups):
            line += "|" + "".join(f" {cell(r, g, k):{f}}" for k in keys)[1:]
        print(line)
    print("-" * len(head))
    for stat in ("median", "mean", "max"):
        line = f"{stat:<26}"
        for g, (_, keys, f) in enumerate(groups):
            line += (
                "|"
                + "".join(f" {summary[k][summary_key[g]][stat]:{f}}" for k in keys)[1:]
            )
        print(line)
    print(
        "\nsensitivity RMS: each channel of estimate and truth normalised to its own "
        "peak, RMS over\n  wavelengths and channels (0.01 = 1 % of the peak).\n"
        "Table 1 RGB mean: mean per-stimulus RMS response error over the 3080 fitted "
        "stimuli (full scale).\n"
        "smooth: with fit_spd_shift=True (default) (the spectroradiometer's wavelength "
        "shift is fitted and\n  undone before Wiener estimation)."
    )
    if t2:
        print(
            "mean dE00: CIEDE2000 (D50) of Wiener estimates (SG prior) of the 190 "
            "rawtoaces training\n  reflectances; 'truth' = Wiener with the true "
            "sensitivity and the reported SPDs."
        )
    shifts = [r.shift["smooth"] for r in results]
    print(
        f"fitted SPD shift (true {SHIFT_NM:g} nm): median {np.median(shifts):.3f} nm, "
        f"range {min(shifts):.3f} .. {max(shifts):.3f} nm"
    )
    for method in METHODS:
        s = summary[method]
        line = (
            f"\n{method}: median sensitivity RMS {s['sensitivity_rms']['median']:.4f}, "
            f"median Table 1 RGB mean {s['table1_rgb_mean']['median']:.4f}"
        )
        if "held_out_rgb_mean" in s:
            line += f" (held-aside patches {s['held_out_rgb_mean']['median']:.4f})"
        if "de00_190_mean" in s:
            line += (
                f",\n  median of mean dE00 (190 set) "
                f"{s['de00_190_mean']['median']:.3f}, "
                f"spectral RMS {s['spectral_rms_190_mean']['median']:.4f}"
            )
        line += f", median time {s['seconds']['median'] * 1e3:.0f} ms"
        print(line)
    default = next((r for r in results if r.camera == DEFAULT_CAMERA), None)
    if default is not None:
        for method in METHODS:
            print()
            print(
                default.table1[method].format_table(
                    f"Table 1, {DEFAULT_CAMERA} (excluded from the database), "
                    f"{method!r}, fitted stimuli"
                )
            )
            if method in default.table1_held:
                print(
                    default.table1_held[method].format_table(
                        f"Table 1, same, {method!r} fitted without every 5th patch: "
                        "the held-aside patches"
                    )
                )
    print()
    for label, ok in check_targets(summary):
        print(f"[{'PASS' if ok else 'FAIL'}] {label}")


def check_targets(summary: dict[str, Any]) -> list[tuple[str, bool]]:
    """The issue's targets, each with whether it is met."""
    sm, pc = summary["smooth"], summary["pca"]
    checks = [
        (
            "smooth beats pca (median sensitivity RMS)",
            sm["sensitivity_rms"]["median"] < pc["sensitivity_rms"]["median"],
        ),
        (
            "smooth median sensitivity RMS <= 0.02",
            sm["sensitivity_rms"]["median"] <= 0.02,
        ),
    ]
    for label in ("smooth",):
        if "de00_190_mean" in summary[label]:
            checks.append(
                (
                    f"{label}: mean dE00 on the 190 set <= 0.3 (median over cameras)",
                    summary[label]["de00_190_mean"]["median"] <= 0.3,
                )
            )
    return checks


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; exit status 1 if a target is missed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--cameras",
        type=int,
        default=None,
        help="only the first N cameras (default: all)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--no-table2", action="store_true", help="skip Wiener / dE00")
    parser.add_argument(
        "--no-held-out", action="store_true", help="skip the held-aside-patch fits"
    )
    parser.add_argument("--json", help="also write the summary and per-camera scores")
    args = parser.parse_args(argv)
    if wiener_reflectance is None and not args.no_table2:
        print("core.wiener / core.colorimetry not importable: Table 2 skipped")
    setup = load_setup(with_190=not args.no_table2)
    names = list(setup.db_work)[: args.cameras]
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    results = [
        run_camera(
            setup,
            name,
            rng,
            held_out=not args.no_held_out,
            table2=not args.no_table2,
        )
        for name in names
    ]
    summary = summarize(results)
    print_report(results, summary)
    print(
        f"\n{len(results)} cameras in {time.perf_counter() - t0:.1f} s (seed {args.seed})"
    )
    if args.json:
        doc = {
            "summary": summary,
            "cameras": [
                {
                    "camera": r.camera,
                    "sensitivity_rms": r.rms,
                    "table1": {m: s.as_dict() for m, s in r.table1.items()},
                    "table1_held_out": {
                        m: s.as_dict() for m, s in r.table1_held.items()
                    },
                    "de00_190_mean": r.de00,
                    "spectral_rms_190_mean": r.spec_rms,
                }
                for r in results
            ],
        }
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=1)
    ok = all(passed for _, passed in check_targets(summary))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
