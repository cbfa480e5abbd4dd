"""How much of the estimate's error the light's reading noise adds beyond the intervals.

Issue 23 asks that the readings' noise reach the calibration, the per-LED corrections
and the Wiener estimate as errors in variables. The intervals carry the calibration's
covariance from the chart's responses, not from the readings. This measures the gap
by a parametric bootstrap: each camera of ``benchmarks/generalisation.py`` (one per
family) is calibrated and its test reflectances estimated again with the readings
perturbed by noise of the level measured in them
(:func:`tunespec.core.metering.reading_noise_fractions`), clipped at zero and
cleaned as the readers clean them; the replicates' spread is added to the intervals'
variance. A robust spread (the median squared deviation over 0.455, the median of a
chi-square with one degree of freedom) keeps a replicate whose calibration went
elsewhere from deciding it.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/readings_bootstrap.py --replicates 8
--meter-noise 0.003`` (``--systematic`` for the sensor effects); 40-70 s per camera.
"""

from __future__ import annotations

import argparse
import sys
import time

import generalisation as gen
import generalisation_data as gd
import numpy as np

from tunespec.core.metering import reading_noise_fractions, suppress_meter_floor
from tunespec.core.spectra import Grid, Spectra

#: Median of a chi-square with one degree of freedom.
CHI2_1_MEDIAN = 0.455


def _estimate(cam, session, native: Spectra, setup):
    """Calibrate on the chart with ``native`` readings and estimate the test
    reflectances, as the benchmark does."""
    reported = native.resample(gen.WORK, average=True)
    est = gen.calibrate(
        "bayes", session.resp, reported, setup[2], setup[4], cam.exclude
    )
    return gen.estimate_tests(est, session.resp_t, reported, reported, setup)


def _coverage(err, std) -> list[float]:
    return [float(np.mean(err[..., j] <= gen.Z95 * std[..., j])) for j in range(3)]


def run_camera(cam, leds, setup, rng, args) -> dict:
    session = gen.simulate_session(
        cam, leds, setup, rng, meter_noise=args.meter_noise, clean_meter=True,
        report_step_nm=args.report_step_nm, systematic=args.systematic,
    )  # fmt: skip
    native = session.reported_native
    frac = reading_noise_fractions(native)
    _, unc = _estimate(cam, session, native, setup)
    labs = []
    for _ in range(args.replicates):
        # one more reading's noise at the level measured, clipped and cleaned
        level = np.array([[frac[n]] for n in native.names])
        noisy = gd.metering_noise(native, rng, level, reads=1)
        _, u_k = _estimate(cam, session, suppress_meter_floor(noisy), setup)
        labs.append(u_k.lab)
    dev2 = (np.array(labs) - unc.lab) ** 2
    robust = np.median(dev2, axis=0) / CHI2_1_MEDIAN
    err = np.abs(unc.lab - gen.surface_lab(setup[1]))
    std = unc.lab_std
    return {
        "family": cam.family,
        "noise": float(np.median(list(frac.values()))),
        "as_stated": _coverage(err, std),
        "with_mean_square": _coverage(err, np.sqrt(std**2 + dev2.mean(axis=0))),
        "with_robust": _coverage(err, np.sqrt(std**2 + robust)),
        "ratio": [
            float(np.median(np.sqrt(robust[:, j]) / std[:, j])) for j in range(3)
        ],
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=8)
    ap.add_argument("--meter-noise", type=float, default=0.003)
    ap.add_argument("--report-step-nm", type=float, default=10.0)
    ap.add_argument("--systematic", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    gen.EST = Grid(400.0, 700.0, 10.0)
    setup = gen.load_setup()
    picked: dict[str, gd.Camera] = {}
    for cam in gd.all_cameras():
        picked.setdefault(cam.family, cam)
    leds = gd.light_sources()["cal1-model"]
    rng = np.random.default_rng(args.seed)
    rows = []
    print("L*/a*/b* coverage against the surface's colour, 400:700:10")
    print(
        f"{'family':<26}{'noise':>7}   as stated         + replicates (robust)   spread / u"
    )
    for cam in picked.values():
        t0 = time.perf_counter()
        r = run_camera(cam, leds, setup, rng, args)
        rows.append(r)
        fmt = lambda v: "/".join(f"{x:.3f}" for x in v)  # noqa: E731
        print(
            f"{r['family']:<26}{100 * r['noise']:>6.2f}%   {fmt(r['as_stated'])}   "
            f"{fmt(r['with_robust'])}   {fmt(r['ratio'])}  ({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
    for key in ("as_stated", "with_mean_square", "with_robust"):
        v = np.array([r[key] for r in rows])
        print(
            f"{key:<17} over families {'/'.join(f'{x:.3f}' for x in v.mean(axis=0))}, "
            f"min {'/'.join(f'{x:.3f}' for x in v.min(axis=0))}, "
            f"max {'/'.join(f'{x:.3f}' for x in v.max(axis=0))}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
