"""Is the colour error shared by a session's targets? The mean and spread of z.

Coverage (``coverage_seeds.py``) says whether the 95 % intervals of L*, a*, b* hold as
a whole; ``budget_terms.py`` which budget line is off. This script asks whether the
errors of one session's targets share a sign: per session it prints the mean over
the targets of ``z = (estimate - truth) / u`` and its standard deviation, for L*, a*
and b*, against the colour of the truth's samples on the estimation grid and against
the surface's own (1 nm) colour, with the coverage of each. Under a right budget
the mean of z is about 0 (+-0.06 for 318 targets) and its spread about 1; a mean
that keeps its sign from session to session is a bias the intervals do not carry.

The conditions can be taken apart, each error source off in turn: ``--meter-noise
0`` (exact readings), ``--report-step-nm 1``, ``--exact-light`` (no per-LED shift
and gain), ``--ideal-sensor`` (no stray light, cross-talk or non-linearity),
``--true-sensitivities`` (the camera's own curves on the calibration's grid in
Eq. 1), ``--oracle-prior`` (the test reflectances themselves as Eq. 5's prior);
``--plain`` estimates with Eq. 5-6 as the paper has them (``K_e`` from the ROIs'
pixels, no uncertainty: the mean errors alone).

    python benchmarks/colour_bias.py --families rawtoaces:scitech,rawtoaces:wetadigital
    python benchmarks/colour_bias.py --meter-noise 0 --report-step-nm 1 \\
        --exact-light --ideal-sensor --true-sensitivities --oracle-prior
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import cli_protocol as cp
import generalisation as gen
import generalisation_data as gd


def session_errors(cam, leds, setup, rng, args) -> dict[str, tuple]:
    """One session's errors of L*, a*, b* (n_targets, 3) and their standard
    uncertainties (None with ``--plain``) against the samples' colour and against
    the surface's."""
    session = cp.as_read(gen.simulate_session(
        cam, leds, setup, rng, meter_noise=args.meter_noise, meter_reads=1,
        systematic=not args.ideal_sensor, report_step_nm=args.report_step_nm,
        metering=not args.exact_light,
    ))  # fmt: skip
    est = gen.calibrate(
        "bayes", session.resp, session.reported, setup[2], setup[4], cam.exclude
    )
    if args.true_sensitivities:
        est = gen.with_true_sensitivities(est, cam.truth)
    if args.plain:  # Eq. 5-6 as the paper has them: without a covariance
        est = replace(est, covariance=None)
    w, unc = gen.estimate_tests(
        est, session.resp_t, session.reported, session.reported, setup
    )
    lab, u = (
        (gen.lab_d50(w.reflectance), None) if unc is None else (unc.lab, unc.lab_std)
    )
    samples, surface = setup[5], gen.surface_lab(setup[1])
    order = [samples.names.index(n) for n in w.reflectance.names]
    return {
        "samples": (lab - gen.lab_d50(samples)[order], u),
        "surface": (lab - surface[order], u),
    }


def _row(error: np.ndarray, u: np.ndarray | None) -> str:
    out = "mean error " + " ".join(f"{v:+.4f}" for v in error.mean(0))
    if u is None:
        return out
    z = error / u
    cover = np.mean(np.abs(z) <= 1.96, axis=0)
    return (
        out + "  mean z " + " ".join(f"{v:+.2f}" for v in z.mean(0))
        + "  sd z " + " ".join(f"{v:.2f}" for v in z.std(0))
        + "  coverage " + " ".join(f"{v:.3f}" for v in cover)
    )  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", help="comma-separated (default: all)")
    ap.add_argument("--lights", default="cal1-model,heldout-leds")
    ap.add_argument("--seed", type=int, default=120)
    ap.add_argument("--meter-noise", type=float, default=0.003)
    ap.add_argument("--report-step-nm", type=float, default=10.0)
    ap.add_argument("--exact-light", action="store_true")
    ap.add_argument("--ideal-sensor", action="store_true")
    ap.add_argument("--true-sensitivities", action="store_true")
    ap.add_argument("--oracle-prior", action="store_true")
    ap.add_argument("--plain", action="store_true")
    args = ap.parse_args(argv)
    gen.EST = cp.EST
    setup = gen.load_setup()
    if args.oracle_prior:
        setup = (*setup[:3], setup[1], *setup[4:])
    lights = gd.light_sources()
    means: dict[str, list[np.ndarray]] = {"samples": [], "surface": []}
    t0 = time.perf_counter()
    for c, cam in enumerate(gd.cameras_per_family(1, args.families)):
        for li, light in enumerate(args.lights.split(",")):
            rng = np.random.default_rng([args.seed, c, li])
            errors = session_errors(cam, lights[light], setup, rng, args)
            for ref, (error, u) in errors.items():
                means[ref].append((error if u is None else error / u).mean(0))
                print(f"{cam.family[:24]:<24} {light:<13} {ref:<8} {_row(error, u)}",
                      flush=True)  # fmt: skip
    for ref, m in means.items():
        m = np.asarray(m)
        what = "error" if args.plain else "z"
        shown = " ".join(f"{v:+.4f}" if args.plain else f"{v:+.2f}" for v in m.mean(0))
        sign = " ".join(
            str(max(np.sum(m[:, j] > 0), np.sum(m[:, j] < 0))) for j in range(3)
        )
        print(
            f"\nagainst the {ref}' colour, over {len(m)} sessions: mean {what} of "
            f"L* a* b* {shown}, of the same sign in {sign}"
        )
    print(f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
