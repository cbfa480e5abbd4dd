"""The sample's white board as a check of its linearity, where no covariance lets
Eq. 1 check the targets (``core.plausibility.board_bend_warning``): false alarms
and what it catches.

Under one LED a white board is one reflectance in every channel; a sample's frames
on a tone curve tilt its channels against Eq. 1. For every camera of
:mod:`generalisation_data` (``--per-family``) under both light sources, one session
of ``generalisation.simulate_session`` (10 nm readings with ``--meter-noise`` of
each LED's peak, the per-LED metering errors, the sensor's effects) and its white
board (``white_scale.with_board``: reflectance 0.9, the flat-field residual, the
sensor's non-linearity), seen through sensitivities without a covariance: the
camera's own curves with the light's readings (external curves as good as they
come), ``smooth`` and ``pca`` calibrations of the session's chart. The board's
responses are taken as measured and through the tone curves ``c^E`` of
``--tones``. Prints, per curve and tone, the range of the bend found and how many
sessions the product warns of.

    python benchmarks/board_bend.py                 # 1 camera a family (~1 min)
    python benchmarks/board_bend.py --per-family 999
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cli_protocol as cp
import generalisation as gen
import generalisation_data as gd
from white_scale import with_board

from tunespec.app.pipeline.lighting import estimation_lighting
from tunespec.core.plausibility import board_bend, board_bend_warning, white_response


def perfect_white(session, sensitivity) -> np.ndarray:
    """Eq. 1 for a perfect white under each light, as the estimate integrates it."""
    illum, sens, _ = estimation_lighting(
        session.reported_native, sensitivity, sensitivity.meta, cp.EST
    )
    return white_response(illum.select(list(session.resp_t.illuminants)), sens)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=1)
    ap.add_argument("--families", help="comma-separated (default: all)")
    ap.add_argument("--meter-noise", type=float, default=0.003)
    ap.add_argument("--tones", default="1,0.952381,1.1,0.8333333")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    gen.EST = cp.EST
    setup = gen.load_setup()
    tones = [float(t) for t in args.tones.split(",")]
    found: dict[tuple[str, float], list[tuple[float, bool]]] = defaultdict(list)
    t0 = time.perf_counter()
    for c, cam in enumerate(gd.cameras_per_family(args.per_family, args.families)):
        for j, (light, leds) in enumerate(gd.light_sources().items()):
            rng = np.random.default_rng([args.seed, c, j])
            session = cp.as_read(gen.simulate_session(
                cam, leds, setup, rng, meter_noise=args.meter_noise, meter_reads=1,
                systematic=True, report_step_nm=10.0,
            ))  # fmt: skip
            white = with_board(session, cam, rng, True).white_rgb
            curves = {"own curves": cam.truth.resample(gen.WORK)} | {
                m: gen.calibrate(
                    m, session.resp, session.reported, setup[2], setup[4], cam.exclude
                ).sensitivity
                for m in ("smooth", "pca")
            }
            for name, sens in curves.items():
                perfect = perfect_white(session, sens)
                for e in tones:
                    toned = np.maximum(white, 0.0) ** e
                    gamma, _ = board_bend(toned, perfect)
                    warned = board_bend_warning(toned, perfect) is not None
                    found[name, e].append((gamma, warned))
            print(f"{cam.name:<34} {light:<13} done", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s; the board's bend per curves and tone:")
    for (name, e), rows in found.items():
        g = np.array([r[0] for r in rows])
        print(
            f"  {name:<11} c^{e:<9.4g} gamma {g.min():+.4f} to {g.max():+.4f}, "
            f"warned {sum(r[1] for r in rows)} of {len(rows)}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
