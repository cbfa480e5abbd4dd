"""Which part of the uncertainty budget is off: its prediction against a Monte Carlo of
the error it stands for (issue 23).

Coverage says whether the intervals are right as a whole; this says which terms are
not. For one session per camera (one per family of ``benchmarks/generalisation.py``)
the calibration is held fixed and the test reflectances' responses are drawn again
``--draws`` times (photon and read noise, the flat-field residual and, with
``--systematic``, stray light, cross-talk and the non-linearity), each estimated as
the benchmark estimates them. Per target, over the draws:

- the *random part*: the variance of L*, a*, b* from draw to draw, against what the
  budget predicts for the response noise, the flat field and the systematic term;
- the *fixed part*: the squared distance of the draws' mean from the colour of the
  truth's samples (less the mean's own variance), against the prior mismatch, the
  calibration and the readings.

Printed: summed empirical over summed predicted variance, per L*, a*, b*; 1 is right.
The non-linearity is the same in every draw but the budget counts it under
``systematic``: with ``--systematic`` it adds to the fixed part's measure and to the
random part's prediction; ``--linear`` leaves it out of the sensor effects.
``--true-sensitivities`` puts the camera's true sensitivities into Eq. 1 (the
calibration's error model kept, its covariance dropped) and the light's spectra into
its readings without their wavelength and gain errors: the fixed part is then the
prior mismatch alone.

    OPENBLAS_NUM_THREADS=1 python benchmarks/budget_terms.py --draws 8 \\
        --families synthetic:narrow,synthetic:broad --true-sensitivities
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import cli_protocol as cp
import generalisation as gen
import generalisation_data as gd

from tunespec.core.simulate import NoiseModel, simulate_responses

#: The budget's terms that change from one draw of the responses to the next, and
#: those that the session fixes.
RANDOM_TERMS = ("response noise", "flat field", "systematic")
FIXED_TERMS = ("prior mismatch", "calibration", "readings")


def _predicted(budget, terms) -> np.ndarray:
    """The CIELAB variance (n_p, 3) the budget gives ``terms`` together."""
    return sum(budget[t][1] for t in terms if t in budget)


@contextmanager
def _sensor_effects(linear: bool) -> Iterator[None]:
    """:func:`generalisation_data.systematic_effects` as the session and the draws
    apply it, without the non-linearity where ``linear``."""
    original = gd.systematic_effects
    if linear:
        gd.systematic_effects = functools.partial(original, nonlinearity=1.0)
    try:
        yield
    finally:
        gd.systematic_effects = original


def run_camera(cam: gd.Camera, leds, setup, args) -> dict[str, np.ndarray]:
    """One session's calibration, its budget at the session's test responses, and
    the random and fixed parts of the error over ``args.draws`` new draws of them:
    summed empirical over summed predicted variance, (3,) each."""
    with _sensor_effects(args.linear):
        return _parts(cam, leds, setup, args)


def _parts(cam: gd.Camera, leds, setup, args) -> dict[str, np.ndarray]:
    session = cp.as_read(
        gen.simulate_session(
            cam, leds, setup, np.random.default_rng(args.seed),
            meter_noise=args.meter_noise, meter_reads=1,
            metering=not args.true_sensitivities,
            systematic=args.systematic, report_step_nm=args.report_step_nm,
        )
    )  # fmt: skip
    reported = session.reported
    est = gen.calibrate(
        "bayes", session.resp, reported, setup[2], setup[4], cam.exclude
    )
    if args.true_sensitivities:
        est = gen.with_true_sensitivities(est, cam.truth)
    w, unc = gen.estimate_tests(est, session.resp_t, reported, reported, setup)
    samples = setup[5]
    truth = gen.lab_d50(samples)[[samples.names.index(n) for n in w.reflectance.names]]
    rng = np.random.default_rng(10_000 + args.seed)
    labs = []
    for _ in range(args.draws):
        resp = simulate_responses(
            setup[1], session.scaled, cam.truth, noise=NoiseModel(), rng=rng
        )
        if args.systematic:
            resp = gd.systematic_effects(resp, rng)
        labs.append(gen.estimate_tests(est, resp, reported, reported, setup)[1].lab)
    lab = np.stack(labs)
    random = lab.var(axis=0, ddof=1)
    fixed = (lab.mean(axis=0) - truth) ** 2 - random / args.draws
    return {
        "random": random.sum(0) / _predicted(unc.budget, RANDOM_TERMS).sum(0),
        "fixed": fixed.sum(0) / _predicted(unc.budget, FIXED_TERMS).sum(0),
        "total": (random + fixed).sum(0) / (unc.lab_std**2).sum(0),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", help="comma-separated (default: all)")
    ap.add_argument("--lights", default="cal1-model,heldout-leds")
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--meter-noise", type=float, default=0.0)
    ap.add_argument("--report-step-nm", type=float, default=10.0)
    ap.add_argument("--systematic", action="store_true")
    ap.add_argument("--linear", action="store_true")
    ap.add_argument("--true-sensitivities", action="store_true")
    args = ap.parse_args(argv)
    if args.draws < 2:
        ap.error("--draws: at least 2")
    gen.EST = cp.EST
    setup = gen.load_setup()
    cams = gd.cameras_per_family(1, args.families)
    lights = gd.light_sources()
    t0 = time.perf_counter()
    print("empirical / predicted variance, L* a* b*")
    print(f"{'family':<26} {'light':<13} {'random part':<17} {'fixed part':<17} total")
    rows = []
    for cam in cams:
        for light in args.lights.split(","):
            r = run_camera(cam, lights[light], setup, args)
            rows.append(r)
            print(
                f"{cam.family:<26} {light:<13} "
                + " ".join(" ".join(f"{x:5.2f}" for x in r[k]) + " " for k in r),
                flush=True,
            )
    print(
        f"{'median':<40} "
        + " ".join(
            " ".join(f"{x:5.2f}" for x in np.median([r[k] for r in rows], axis=0)) + " "
            for k in rows[0]
        )
    )
    print(f"\n{len(rows)} sessions in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
