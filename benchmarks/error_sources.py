"""Where a camera's estimation error comes from: the same session with each source of
error switched off in turn (issue 23).

For one camera per family (``benchmarks/generalisation.py``'s) and light, one session
(seed ``--seed``, 10 nm readings, the estimate on 400:700:10 as
``cli_protocol.py``) is simulated under issue 23's conditions and again without
parts of them, each calibrated with ``"bayes"`` and its test targets estimated as
the product does. Printed: the mean CIEDE2000 of each.

- ``all``: the readings' noise (``--meter-noise``, one reading, cleaned as the
  product cleans it), the metering error (U(-1, 1) nm, 1 % gain per LED) and the
  sensor effects (stray light, cross-talk, non-linearity; the flat field always);
- ``exact readings``: without the readings' noise;
- ``no sensor effects``: without stray light, cross-talk and non-linearity;
- ``true spectra``: the light's spectra reported exactly, the sensor effects on;
- then with the true spectra reported, one sensor effect at a time, and none
  (``ideal sensor``).

    OPENBLAS_NUM_THREADS=1 python benchmarks/error_sources.py --families colour-science
"""

from __future__ import annotations

import argparse
import functools
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import cli_protocol as cp
import generalisation as gen
import generalisation_data as gd

from tunespec.core.colorimetry import reflectance_stats


def _rows(noise: float) -> list[tuple[str, dict, object]]:
    """Each row: its name, :func:`generalisation.simulate_session`'s options beyond
    the seed's, and the sensor effects in place of
    :func:`generalisation_data.systematic_effects` (None: as they are)."""
    one = functools.partial(functools.partial, gd.systematic_effects)
    return [
        ("all", {"meter_noise": noise, "systematic": True}, None),
        ("exact readings", {"systematic": True}, None),
        ("no sensor effects", {"meter_noise": noise}, None),
        ("true spectra", {"systematic": True, "metering": False}, None),
        ("  stray light only", {"systematic": True, "metering": False},
         one(crosstalk=0.0, nonlinearity=1.0)),
        ("  cross-talk only", {"systematic": True, "metering": False},
         one(stray=0.0, nonlinearity=1.0)),
        ("  non-linearity only", {"systematic": True, "metering": False},
         one(stray=0.0, crosstalk=0.0)),
        ("  linear effects", {"systematic": True, "metering": False},
         one(nonlinearity=1.0)),
        ("ideal sensor", {"metering": False}, None),
    ]  # fmt: skip


def run(cam: gd.Camera, leds, setup, args) -> list[tuple[str, float]]:
    """The mean CIEDE2000 of each row for one camera and light."""
    out = []
    original = gd.systematic_effects
    for name, options, effects in _rows(args.meter_noise):
        gd.systematic_effects = effects or original
        try:
            session = gen.simulate_session(
                cam, leds, setup, np.random.default_rng(args.seed),
                meter_reads=1, report_step_nm=10.0, **options,
            )  # fmt: skip
        finally:
            gd.systematic_effects = original
        if options.get("meter_noise"):
            session = cp.as_read(session)
        est = gen.calibrate(
            "bayes", session.resp, session.reported, setup[2], setup[4], cam.exclude
        )
        w, _ = gen.estimate_tests(
            est, session.resp_t, session.reported, session.reported, setup
        )
        out.append((name, reflectance_stats(w.reflectance, setup[5]).mean_delta_e00))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", help="comma-separated (default: all)")
    ap.add_argument("--lights", default="cal1-model,heldout-leds")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--meter-noise", type=float, default=0.001)
    args = ap.parse_args(argv)
    gen.EST = cp.EST
    setup = gen.load_setup()
    lights = gd.light_sources()
    t0 = time.perf_counter()
    for cam in gd.cameras_per_family(1, args.families):
        for light in args.lights.split(","):
            print(f"{cam.family} ({cam.name}), {light}: mean dE00")
            for name, de in run(cam, lights[light], setup, args):
                print(f"  {name:<22} {de:.3f}", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
