"""Speed of the core numerics on the paper's problem size: 140 patches x 22 LEDs, 71 nm samples.

Usage::

    python benchmarks/bench_core_speed.py [--repeat 20] [--threads N]

Times, on one simulated ColorChecker SG capture of the 5D Mark III (380-730 nm, 5 nm):

- ``estimate_camera_sensitivity`` with ``method="bayes"`` (the default: priors by the
  marginal likelihood and the per-LED self-calibration, with its covariance), ``"bayes"``
  with one common wavelength offset only, ``method="pca"`` (Eq. 4), ``"smooth"`` (the
  previous default, with the fit of the spectroradiometer's wavelength shift), and
  ``"smooth"`` without that fit;
- ``wiener_reflectance`` of the 140 patches (Eq. 5-6).

It prints the median and the best of ``--repeat`` runs in milliseconds. Goal: a
calibration well under one second.

BLAS threads are limited to ``--threads`` (default 1) before numpy is imported: the
matrices are small (71 x 71, 3080 x 71), so threads only add synchronisation, and on a
busy machine they make every LAPACK call many times slower.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable

GOAL_S = 1.0


def _time(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    fn()  # warm-up: imports, caches
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times)


def main(argv: list[str] | None = None) -> int:
    """Run the timings; exit status 1 if a calibration misses the goal."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--threads", type=int, default=1, help="BLAS threads")
    args = parser.parse_args(argv)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)

    import numpy as np

    from tunespec.core.datasets import (
        DEFAULT_CAMERA,
        load_camera_database,
        load_colorchecker_sg,
        load_led_set,
    )
    from tunespec.core.sensitivity import estimate_camera_sensitivity
    from tunespec.core.simulate import simulate_capture
    from tunespec.core.spectra import DEFAULT_GRID, Grid
    from tunespec.core.wiener import wiener_reflectance

    fine = Grid(380.0, 730.0, 1.0)
    db = load_camera_database(DEFAULT_GRID)
    sg = load_colorchecker_sg(DEFAULT_GRID)
    responses, reported = simulate_capture(
        load_colorchecker_sg(fine),
        load_led_set(fine),
        load_camera_database(fine)[DEFAULT_CAMERA],
        grid=DEFAULT_GRID,
        rng=np.random.default_rng(0),
    )
    n_p, n_i, _ = responses.rgb.shape
    print(
        f"problem: {n_p} patches x {n_i} LEDs x {DEFAULT_GRID.n} wavelengths "
        f"({n_p * n_i} stimuli), BLAS threads {args.threads}, {args.repeat} runs"
    )
    print(f"{'step':<52}{'median ms':>11}{'best ms':>10}")
    ok = True
    for label, kw in (
        ("calibration, 'bayes' (default: per-LED self-calibration)", {}),
        (
            "calibration, 'bayes' with one common offset",
            {"method": "bayes", "self_calibrate": False},
        ),
        ("calibration, method='pca' (Eq. 4)", {"method": "pca"}),
        ("calibration, 'smooth' (fits the SPD shift)", {"method": "smooth"}),
        (
            "calibration, 'smooth' without the SPD shift fit",
            {"method": "smooth", "fit_spd_shift": False},
        ),
    ):

        def run(kw: dict[str, object] = kw) -> object:
            return estimate_camera_sensitivity(
                responses, reported, sg, database=db, exclude=DEFAULT_CAMERA, **kw
            )

        med, best = _time(run, args.repeat)
        ok &= med < GOAL_S
        print(f"{label:<52}{med * 1e3:11.1f}{best * 1e3:10.1f}")
    est = estimate_camera_sensitivity(
        responses, reported, sg, database=db, exclude=DEFAULT_CAMERA
    )
    corrected = est.correct_illuminants(reported)
    med, best = _time(
        lambda: wiener_reflectance(responses, corrected, est.sensitivity, sg),
        args.repeat,
    )
    label = "Wiener estimation, 140 patches (Eq. 5-6)"
    print(f"{label:<52}{med * 1e3:11.1f}{best * 1e3:10.1f}")
    print(f"goal: each calibration under {GOAL_S:g} s: {'met' if ok else 'MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
