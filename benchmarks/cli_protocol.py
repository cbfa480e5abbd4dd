"""The generalisation protocol through the command line, as an evaluator runs it.

``benchmarks/generalisation.py`` calls the calibration and the estimate as functions.
An evaluation runs files through ``tunespec calibrate`` (defaults) and ``tunespec
estimate --prior SG --grid 400:700:10``: the light's readings as the instrument wrote
them (every 10 nm, noisy, clipped at zero, no metadata), the responses as a CSV with
their ROI statistics, the chart and prior as the SG's 10 nm file. This script writes a
simulated session (:func:`generalisation.simulate_session`, the same conditions and
flags) as those files, runs the two commands in this process, reads what they wrote
(the reflectances, ``*_colorimetry.csv``, ``*_uncertainty.csv``) and scores them
against the surfaces (mean CIEDE2000, coverage of the 95 % intervals), beside the
function path on the very same session. The database leaves the camera's own source
out (as ``generalisation.py`` does; an evaluation's cameras are not in it at all).

    python benchmarks/cli_protocol.py --meter-noise 0.003 --systematic [--per-family N]
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import generalisation as gen
import generalisation_data as gd

from tunespec.app.cli import main as cli
from tunespec.core import sensitivity as sensitivity_module
from tunespec.core.colorimetry import delta_e_2000
from tunespec.core.datasets import resource_path
from tunespec.core.io.responses_csv import write_responses_csv
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Grid

#: The evaluation's estimation grid.
EST = Grid(400.0, 700.0, 10.0)
SG_FILE = resource_path("charts", "colorchecker_sg.csv")


def read_colorimetry(path: Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Names, L*a*b* and their standard uncertainties from ``*_colorimetry.csv``."""
    with path.open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    lab = np.array([[float(r[k]) for k in ("L", "a", "b")] for r in rows])
    u = np.array([[float(r[k]) for k in ("u_L", "u_a", "u_b")] for r in rows])
    return [r["patch"] for r in rows], lab, u


def run_cli(
    session: gen.Session, cam: gd.Camera, work: Path, truth
) -> dict[str, float]:
    """The session's files through ``calibrate`` and ``estimate``; the scores."""
    write_responses_csv(session.resp, work / "chart.csv")
    write_responses_csv(session.resp_t, work / "test.csv")
    write_spectra_csv(session.reported_native, work / "leds.csv")
    full = sensitivity_module.load_camera_database

    def database(grid):
        return {n: s for n, s in full(grid).items() if n not in set(cam.exclude)}

    with mock.patch.object(sensitivity_module, "load_camera_database", database):
        rc = cli([
            "calibrate", "-q", "--responses", str(work / "chart.csv"),
            "--illuminants", str(work / "leds.csv"), "--reflectances", str(SG_FILE),
            "-o", str(work / "S.csv"),
        ])  # fmt: skip
    if rc != 0:
        raise SystemExit(f"{cam.name}: tunespec calibrate exited {rc}")
    rc = cli([
        "estimate", "-q", "--responses", str(work / "test.csv"),
        "--illuminants", str(work / "leds.csv"), "--sensitivities", str(work / "S.csv"),
        "--prior", str(SG_FILE), "--grid", str(EST), "-o", str(work / "R.csv"),
    ])  # fmt: skip
    if rc != 0:
        raise SystemExit(f"{cam.name}: tunespec estimate exited {rc}")
    names, lab, u = read_colorimetry(work / "R_colorimetry.csv")
    refl = read_spectra_csv(work / "R.csv", EST)
    std = read_spectra_csv(work / "R_uncertainty.csv", EST)
    return score(truth, names, refl.values, std.values, lab, u)


def score(truth, names, refl, std, lab, u) -> dict[str, float]:
    """Mean CIEDE2000 against the surfaces' colour and the coverage of the 95 %
    intervals (:func:`generalisation.coverage`) of the reflectance samples (``R``)
    and of L*, a*, b* against the surface; ``truth`` the test reflectances on
    :data:`EST` and the surfaces' L*a*b*."""
    samples, lab_surface = truth
    order = [samples.names.index(n) for n in names]
    values = samples.values[order]
    cov = gen.coverage(
        refl, std, lab, u, values, gen.lab_d50(samples)[order], lab_surface[order]
    )
    out = {"de00": float(np.mean(delta_e_2000(lab, lab_surface[order])))}
    out["R"] = cov["reflectance"]
    # L, a, b against the surface; against the samples' colour as *_samples
    out |= {f"{k}_samples": cov[k] for k in "Lab"}
    return out | {k: cov[f"{k}_surface"] for k in "Lab"}


def as_read(session: gen.Session) -> gen.Session:
    """The session's readings cleaned, as the product's readers clean them (the
    function path's input)."""
    cleaned = gen.suppress_meter_floor(session.reported_native)
    session.reported = cleaned.resample(gen.WORK, average=True)
    session.reported_native = cleaned
    return session


def estimate_session(session: gen.Session, cam: gd.Camera, setup):
    """``generalisation.py``'s function path on a session read as the product reads
    it (:func:`as_read`): the ``"bayes"`` calibration, then the test targets'
    estimate and its uncertainty."""
    est = gen.calibrate(
        "bayes", session.resp, session.reported, setup[2], setup[4], cam.exclude
    )
    return gen.estimate_tests(
        est, session.resp_t, session.reported, session.reported, setup
    )


def run_functions(
    session: gen.Session, cam: gd.Camera, setup, truth
) -> dict[str, float]:
    """The same session through ``generalisation.py``'s function path."""
    w, unc = estimate_session(session, cam, setup)
    refl = w.reflectance
    return score(
        truth, refl.names, refl.values, unc.reflectance_std, unc.lab, unc.lab_std
    )


def compare(
    cam: gd.Camera, leds, setup, rng, **conditions
) -> tuple[dict[str, float], dict[str, float]]:
    """One camera's session (:func:`generalisation.simulate_session` with
    ``conditions``) through the command line and through the functions: their
    scores."""
    truth = (setup[5], gen.surface_lab(setup[1]))
    session = gen.simulate_session(cam, leds, setup, rng, **conditions)
    with tempfile.TemporaryDirectory() as tmp:
        via_cli = run_cli(session, cam, Path(tmp), truth)
    return via_cli, run_functions(as_read(session), cam, setup, truth)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-family", type=int, default=1)
    ap.add_argument("--lights", default="cal1-model")
    ap.add_argument("--meter-noise", type=float, default=0.003)
    ap.add_argument("--meter-reads", type=int, default=1)
    ap.add_argument("--report-step-nm", type=float, default=10.0)
    ap.add_argument("--systematic", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    gen.EST = EST
    setup = gen.load_setup()
    cams = gd.cameras_per_family(args.per_family)
    lights = gd.light_sources()
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    print(f"{'camera':<28} {'light':<13} {'path':<9} dE00    R     L*    a*    b*")
    for light in args.lights.split(","):
        for cam in cams:
            via_cli, via_fn = compare(
                cam, lights[light], setup, rng, meter_noise=args.meter_noise,
                meter_reads=args.meter_reads, systematic=args.systematic,
                report_step_nm=args.report_step_nm,
            )  # fmt: skip
            for label, s in (("cli", via_cli), ("functions", via_fn)):
                print(
                    f"{cam.name[:28]:<28} {light:<13} {label:<9} {s['de00']:.4f} "
                    + " ".join(f"{s[k]:.3f}" for k in "RLab"),
                    flush=True,
                )
    print(
        f"\n{len(cams)} cameras in {time.perf_counter() - t0:.0f} s, seed {args.seed}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
