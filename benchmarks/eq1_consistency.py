"""How far legitimate responses are from Eq. 1: the estimate's chi-square per response.

``core.plausibility.check_response_consistency`` refuses an estimate whose patches'
median chi-square per response (``ReflectanceUncertainty.chi2_per_response``) is above
``MAX_CHI2_PER_RESPONSE``. This script measures the value on sessions that hold no
mistake (:func:`generalisation.simulate_session` with ``numpy.random.default_rng(100)``,
the test reflectances as the sample, through ``generalisation.estimate_tests``) and
prints, per camera, its median, 99th percentile and largest over the 318 targets, then
over all of them: the margin the limit leaves.

    python benchmarks/eq1_consistency.py --meter-noise 0.003 --systematic
    python benchmarks/eq1_consistency.py --per-family 3 --meter-noise 0.001 \\
        --report-step-nm 5 --systematic
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import cli_protocol as cp
import generalisation as gen
import generalisation_data as gd

from tunespec.core.plausibility import MAX_CHI2_PER_RESPONSE
from tunespec.core.simulate import NoiseModel


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=1)
    ap.add_argument("--light", default="cal1-model")
    ap.add_argument("--meter-noise", type=float, default=0.003)
    ap.add_argument("--report-step-nm", type=float, default=10.0)
    ap.add_argument("--systematic", action="store_true")
    ap.add_argument("--flat-field", type=float, default=NoiseModel.flat_field_residual)
    args = ap.parse_args(argv)
    gen.EST = cp.EST
    setup = gen.load_setup()
    leds = gd.light_sources()[args.light]
    every = []
    for cam in gd.cameras_per_family(args.per_family):
        session = gen.simulate_session(
            cam, leds, setup, np.random.default_rng(100),
            meter_noise=args.meter_noise, meter_reads=1,
            systematic=args.systematic, report_step_nm=args.report_step_nm,
            flat_field=args.flat_field,
        )  # fmt: skip
        _, unc = cp.estimate_session(cp.as_read(session), cam, setup)
        c = unc.chi2_per_response
        every.append(c)
        print(
            f"{cam.family:<26} {cam.name[:20]:<20} median {np.median(c):.2f}  "
            f"q99 {np.quantile(c, 0.99):.2f}  largest {c.max():.2f}",
            flush=True,
        )
    c = np.concatenate(every)
    print(
        f"all {c.size} targets: median {np.median(c):.2f}, largest {c.max():.2f}; "
        f"{int(np.sum(c > MAX_CHI2_PER_RESPONSE))} above the limit "
        f"{MAX_CHI2_PER_RESPONSE:g}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
