"""The sample-against-chart scale check under a lab's conditions: false alarms and
what it catches (``core.plausibility.check_white_scale``).

A sample whose illuminants or responses are on another scale than its chart's (an
exposure typed in another unit, another aperture, a light moved) gives reflectances
off by that scale, and only the white background both sessions are flat-fielded to
tells it from a darker sample. ``calibrate`` keeps the board's reflectance by Eq. 1
under each light; ``estimate`` computes the sample's and refuses a median ratio
outside 1 +- ``WHITE_SCALE_TOLERANCE`` or a light that far off the others.

For every camera of :mod:`generalisation_data` (``--per-family``) under both light
sources, two sessions of ``generalisation.simulate_session``: the reading noise and
the sensor's effects drawn for each, the light's metering errors (a wavelength
offset and a gain per LED) the instrument's, the same in both (``--redraw-metering``:
drawn again for the sample, as after a re-calibrated spectroradiometer, which the
chart's LED corrections then do not undo), 10 nm readings with ``--meter-noise`` of each LED's peak,
``--systematic``. The white board (reflectance 0.9) is Eq. 1 under the true light
with the noise model's flat-field residual (a draw per light) over a 100 x 100 px
window and the sensor's non-linearity. The chart session is calibrated with the
default estimator; both sessions' board is then computed as the product does
(``lighting.white_background``, after the calibration's linearisation).

Prints per family: the median ratio's range over the sessions, the largest light's
deviation from its session's median, how many sessions the check refuses (false
alarms), and how many it refuses with the sample's illuminants x 2^(1/3) (a third of
a stop) and x 0.95 (a 5 % scale, inside the tolerance: not meant to be caught).

    python benchmarks/white_scale.py                   # 2 cameras a family (~4 min)
    python benchmarks/white_scale.py --per-family 1 --meter-noise 0.001
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import contextlib
import sys
import time
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import cli_protocol as cp
import generalisation as gen
import generalisation_data as gd

from tunespec.app.pipeline.lighting import white_background
from tunespec.core.calibration import linearise_from_meta
from tunespec.core.plausibility import Implausible, check_white_scale
from tunespec.core.simulate import NoiseModel, simulate_responses
from tunespec.core.spectra import Spectra

#: The board's reflectance.
BOARD = 0.9
#: Pixels of the white frame's centre window Eq. 2 averages.
WINDOW_PX = 100 * 100
#: The sample's scales tried: a third of a stop (caught) and 5 % (inside).
SCALES = (2 ** (1 / 3), 0.95)


def with_board(session, cam, rng, systematic: bool):
    """The session's test responses with the board's level under each light."""
    scaled = session.scaled
    board = Spectra(
        scaled.wavelength_nm, np.full((1, scaled.wavelength_nm.size), BOARD), ("board",)
    )
    white = simulate_responses(
        board, scaled, cam.truth, noise=NoiseModel(n_pixels=WINDOW_PX), rng=rng
    ).rgb[0]
    if systematic:  # gd.systematic_effects' non-linearity
        white = np.sign(white) * np.abs(white) ** 1.003
    return replace(session.resp_t, white_rgb=white)


@contextlib.contextmanager
def same_instrument(chart, redraw: bool):
    """The sample session's readings with the chart session's metering errors (one
    spectroradiometer, its errors its own), unless ``redraw``."""
    if redraw:
        yield
        return
    draw = gd.metering_error

    def chart_errors(leds, rng, **_):
        values = np.stack([
            np.interp(gd.WL - d, gd.WL, v) * g
            for v, d, g in zip(leds.values, chart.shifts, chart.gains, strict=True)
        ])  # fmt: skip
        return leds.with_values(values), chart.shifts, chart.gains

    gd.metering_error = chart_errors
    try:
        yield
    finally:
        gd.metering_error = draw


def board_of(est, session, board, scale: float = 1.0) -> dict[str, float]:
    """The board's reflectance by Eq. 1 in ``session`` as the product computes it,
    with its illuminants as read times ``scale``."""
    meta = est.sensitivity.meta
    lit = session.reported_native
    lit = lit.with_values(lit.values * scale)
    out = white_background(linearise_from_meta(board, meta), lit, est.sensitivity, meta)
    assert out is not None
    return out


def refused(sample: dict[str, float], chart: dict[str, float]) -> bool:
    try:
        check_white_scale(sample, chart)
    except Implausible:
        return True
    return False


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=2)
    ap.add_argument("--families", help="comma-separated (default: all)")
    ap.add_argument("--meter-noise", type=float, default=0.003)
    ap.add_argument("--report-step-nm", type=float, default=10.0)
    ap.add_argument("--no-systematic", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--redraw-metering",
        action="store_true",
        help="draw the sample's metering errors anew (a re-calibrated instrument)",
    )
    args = ap.parse_args(argv)
    setup = gen.load_setup()
    systematic = not args.no_systematic
    conditions = {
        "meter_noise": args.meter_noise,
        "meter_reads": 1,
        "report_step_nm": args.report_step_nm,
        "systematic": systematic,
    }
    rows: dict[str, list[tuple[float, float, bool, list[bool]]]] = defaultdict(list)
    t0 = time.perf_counter()
    cams = gd.cameras_per_family(args.per_family, args.families)
    for c, cam in enumerate(cams):
        for j, (light, leds) in enumerate(gd.light_sources().items()):
            rng = np.random.default_rng([args.seed, c, j])
            chart_session = gen.simulate_session(cam, leds, setup, rng, **conditions)
            with same_instrument(chart_session, args.redraw_metering):
                sample_session = gen.simulate_session(
                    cam, leds, setup, rng, **conditions
                )
            # the readings cleaned as the product's readers clean them
            sessions = [cp.as_read(s) for s in (chart_session, sample_session)]
            boards = [with_board(s, cam, rng, systematic) for s in sessions]
            est = gen.calibrate(
                "bayes", sessions[0].resp, sessions[0].reported, setup[2],
                setup[4], cam.exclude,
            )  # fmt: skip
            chart, sample = (
                board_of(est, s, b) for s, b in zip(sessions, boards, strict=True)
            )
            ratio = np.array([sample[n] / chart[n] for n in chart if n in sample])
            median = float(np.median(ratio))
            worst = float(np.max(np.abs(ratio / median - 1.0)))
            caught = [
                refused(board_of(est, sessions[1], boards[1], f), chart) for f in SCALES
            ]
            rows[cam.family].append((median, worst, refused(sample, chart), caught))
            print(
                f"{cam.name:<34} {light:<13} median {median:.4f}  worst light "
                f"{100 * worst:.2f} %  refused {refused(sample, chart)}  "
                f"x{SCALES[0]:.2f} {caught[0]}  x{SCALES[1]:.2f} {caught[1]}",
                flush=True,
            )
    print(f"\n{time.perf_counter() - t0:.0f} s; per family over cameras x lights:")
    print(
        f"{'family':<28} {'n':>3} {'median ratio':>15} {'worst light':>12} "
        f"{'false alarms':>13} {'x1.26 caught':>13} {'x0.95 caught':>13}"
    )
    every = [r for rs in rows.values() for r in rs]
    for family, rs in [*rows.items(), ("all", every)]:
        m = np.array([r[0] for r in rs])
        w = max(r[1] for r in rs)
        print(
            f"{family:<28} {len(rs):>3} {m.min():>7.4f}-{m.max():.4f} "
            f"{100 * w:>10.2f} % {sum(r[2] for r in rs):>13} "
            f"{sum(r[3][0] for r in rs):>13} {sum(r[3][1] for r in rs):>13}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
