"""Per-pixel images against the simulated bench's per-pixel truth.

Usage::

    python benchmarks/bench_image_accuracy.py [--resolution 768x512] [--work DIR]
                                              [--repeats N] [--dark pixel|smooth] [--seed N]
                                              [--noise-free]

Captures the ColorChecker SG with a CMY halftone and strokes of measured
reflectances beside it (``devices.sim.scene.default_regions``; auto exposure),
processes it, calibrates on it (``bayes``), runs ``tunespec estimate-image`` and
prints, for the SG's patches, the mixed regions and the white board:

- per-pixel RMS and CIEDE2000 against the truth, and the patch-wise CIEDE2000
  (``tunespec estimate`` on the processed session) for comparison (goal: the
  per-pixel mean within 1.5x of the patch-wise mean);
- the fraction of true values inside the 95 % intervals of L* and of the spectrum;
- the patch means of the per-pixel spectra against the patch-wise estimates;
- the decomposition of the per-pixel error of the patches: CIEDE2000 of each
  patch's mean per-pixel spectrum against the truth (bias of the per-pixel path:
  rectification, flat field, binning), and of every pixel against its patch's mean
  (noise);
- with ``--repeats N``, ``N`` frames per LED and bracket are captured and averaged
  (``tunespec capture --repeats N --darks N``): the photon and read noise of one
  exposure shrinks by ``sqrt(N)``;
- with ``--noise-free``, the same for a second capture with the simulated camera's
  photon and read noise switched off (and the sensor's own noise model,
  ``--noise-model camera:67000,30``, for the Wiener matrices): what remains of the
  per-pixel error without noise is bias.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from tunespec.core.intervals import COVERAGE_FACTOR_95


class _NoNoise:
    """Stands in for the simulated camera's random generator: every photon and read
    noise draw is zero (the sim adds ``sigma * standard_normal``)."""

    def standard_normal(self, shape: tuple[int, ...], dtype: type = np.float64):
        return np.zeros(shape, dtype=dtype)


def _capture(
    work: Path, res: tuple[int, int], noise_free: bool, repeats: int = 1, seed: int = 0
) -> dict:
    """Capture, process and calibrate a session; the per-pixel truth."""
    import shutil

    from tunespec.app.cli import main as cli
    from tunespec.app.pipeline.plan import ESTIMATION_GRID as GRID
    from tunespec.app.pipeline.processing import process_session, write_processed
    from tunespec.core.io.session import Session
    from tunespec.devices.capture import capture, new_session
    from tunespec.devices.registry import open_bench
    from tunespec.devices.sim.scene import default_regions

    shutil.rmtree(work, ignore_errors=True)
    bench = open_bench(
        "sim", resolution=res, seed=seed, scene_options={"regions": default_regions()}
    )
    if noise_free:
        bench.sim_camera._rng = _NoNoise()
    session = new_session(
        work / "session", bench.light, bench.camera, layout=bench.truth["layout"],
        exposure="auto", repeats=repeats, n_darks=repeats,
    )  # fmt: skip
    capture(session, bench.light, bench.camera, bench.stage)
    mats = bench.sim_stage.materials.resample(GRID)
    pm = bench.sim_stage.plane_materials(*res)
    bench.close()
    p = process_session(Session.open(work / "session"))
    write_processed(p, work / "resp.csv", work / "ill.csv")
    sens_csv = work / "S.csv"
    chart = "resources/charts/colorchecker_sg.csv"
    if not Path(chart).is_file():
        from tunespec.core.datasets import resource_path

        chart = str(resource_path("charts", "colorchecker_sg.csv"))
    cli(["calibrate", "--responses", str(work / "resp.csv"), "--illuminants",
         str(work / "ill.csv"), "--reflectances", chart, "-o", str(sens_csv),
         "--quiet"])  # fmt: skip
    return {"processed": p, "sens": sens_csv, "mats": mats, "pm": pm}


def _evaluate(work: Path, cap: dict, label: str, extra: list[str]) -> None:
    """``estimate-image`` of the capture and its per-pixel error against the truth."""
    import spectral
    import tifffile

    from tunespec.app.cli import main as cli
    from tunespec.app.pipeline.plan import ESTIMATION_GRID as GRID
    from tunespec.core.calibration import correct_illuminants_from_meta
    from tunespec.core.colorimetry import delta_e_2000, lab_d50
    from tunespec.core.datasets import load_colorchecker_sg, read_sensitivities
    from tunespec.core.io.export import read_sensitivity_meta
    from tunespec.core.io.raw import full_to_plane_px
    from tunespec.core.processing import RoiSet
    from tunespec.core.wiener import wiener_reflectance

    p, sens_csv, mats, pm = cap["processed"], cap["sens"], cap["mats"], cap["pm"]
    cli(["estimate-image", str(work / "session"), "--sensitivities", str(sens_csv),
         "--out", str(work / "images"), "--quiet", *extra])  # fmt: skip
    cube = np.array(
        spectral.open_image(str(work / "images" / "cube.hdr")).open_memmap()
    )
    lab = tifffile.imread(work / "images" / "lab.tif").astype(np.float64)
    unc = tifffile.imread(work / "images" / "uncertainty.tif").astype(np.float64)
    wl = GRID.wavelength_nm
    mlab = lab_d50(mats.values, wl)
    n_patch = p.layout.n_patches

    meta = read_sensitivity_meta(sens_csv)
    ill = correct_illuminants_from_meta(
        p.illuminants.resample(GRID, average=True), meta
    )
    est = wiener_reflectance(
        p.responses, ill, read_sensitivities(sens_csv, GRID), load_colorchecker_sg(GRID)
    ).reflectance.values
    truth_p = mats.select(p.layout.patch_names).values
    de_patch = delta_e_2000(lab_d50(est, wl), lab_d50(truth_p, wl))
    print(f"{label}: patch-wise mean dE00 {de_patch.mean():.3f}")
    for name, sel in (
        ("all", pm >= 0),
        ("patches", (pm >= 2) & (pm < 2 + n_patch)),
        ("regions", pm >= 2 + n_patch),
        ("board", pm == 0),
    ):
        m = pm[sel]
        de = delta_e_2000(lab[sel], mlab[m])
        cov_l = np.mean(
            np.abs(lab[sel][:, 0] - mlab[m][:, 0]) < COVERAGE_FACTOR_95 * unc[sel][:, 0]
        )
        cov_r = np.mean(
            np.abs(cube[sel] - mats.values[m]) < COVERAGE_FACTOR_95 * unc[sel][:, 1:2]
        )
        rms = np.sqrt(np.mean((cube[sel] - mats.values[m]) ** 2))
        print(
            f"  {name:8s} {int(sel.sum()):7d} px: RMS {rms:.4f}, mean dE00 "
            f"{de.mean():.3f} ({de.mean() / de_patch.mean():.1f}x patch-wise), "
            f"95 % coverage L* {cov_l:.3f}, spectrum {cov_r:.3f}"
        )
    # decomposition over the patches' pixels: bias (patch means) and noise
    sel = (pm >= 2) & (pm < 2 + n_patch)
    idx = pm[sel] - 2
    sums = np.zeros((n_patch, cube.shape[2]))
    np.add.at(sums, idx, cube[sel].astype(np.float64))
    means = sums / np.bincount(idx, minlength=n_patch)[:, None]
    lab_means = lab_d50(means, wl)
    de_bias = delta_e_2000(lab_means, lab_d50(truth_p, wl))
    de_noise = delta_e_2000(lab[sel], lab_means[idx])
    print(
        f"  patches decomposed: mean of each patch's pixels vs truth {de_bias.mean():.3f} "
        f"dE00 (bias), pixels vs their patch's mean {de_noise.mean():.3f} (noise)"
    )
    rois = RoiSet.from_quads(
        p.layout.patch_names, full_to_plane_px(p.layout.roi_quads_px()), pm.shape
    )
    starts = np.concatenate([[0], np.cumsum(rois.n_pixels)[:-1]])
    centre = np.add.reduceat(cube[rois.rows, rois.cols], starts, axis=0)
    centre /= rois.n_pixels[:, None]
    print(
        f"  patch centres (20 %) of pixels vs patch-wise estimate: RMS "
        f"{np.sqrt(np.mean((centre - est) ** 2)):.4f}, max {np.abs(centre - est).max():.4f}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolution", default="768x512")
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument(
        "--noise-free", action="store_true", help="also a capture without noise"
    )
    parser.add_argument(
        "--dark", choices=("pixel", "smooth"), default="pixel",
        help="estimate-image's --dark",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=0, help="the bench's seed")
    parser.add_argument(
        "--repeats", type=int, default=1,
        help="frames per LED, averaged (capture --repeats)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    from tunespec.devices.registry import parse_resolution

    res = parse_resolution(args.resolution)
    work = args.work or Path(tempfile.gettempdir()) / f"tunespec-acc-{args.resolution}"
    dark = ["--dark", args.dark]
    _evaluate(
        work, _capture(work, res, False, args.repeats, args.seed),
        f"{args.resolution}, seed {args.seed}, dark {args.dark}, {args.repeats} "
        "frame(s) per LED", dark,
    )  # fmt: skip
    if args.noise_free:
        quiet = work / "noise-free"
        _evaluate(
            quiet, _capture(quiet, res, True, 1, args.seed),
            f"{args.resolution} without noise",
            ["--noise-model", "camera:67000,30", *dark],
        )  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
