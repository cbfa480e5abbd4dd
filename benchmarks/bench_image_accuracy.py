"""Per-pixel images against the simulated bench's per-pixel truth.

Usage::

    python benchmarks/bench_image_accuracy.py [--resolution 768x512] [--work DIR]

Captures the ColorChecker SG with a CMY halftone and strokes of measured
reflectances beside it (``devices.sim.scene.default_regions``; auto exposure),
processes it, calibrates on it (``bayes``), runs ``tunespec estimate-image`` and
prints, for the SG's patches, the mixed regions and the white board:

- per-pixel RMS and CIEDE2000 against the truth, and the patch-wise CIEDE2000
  (``tunespec estimate`` on the processed session) for comparison (goal: the
  per-pixel mean within 1.5x of the patch-wise mean);
- the fraction of true values inside the 95 % intervals of L* and of the spectrum;
- the patch means of the per-pixel spectra against the patch-wise estimates.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolution", default="768x512")
    parser.add_argument("--work", type=Path, default=None)
    args = parser.parse_args(argv)
    import shutil

    import spectral
    import tifffile

    from tunespec.app.cli import main as cli
    from tunespec.app.pipeline.plan import ESTIMATION_GRID as GRID
    from tunespec.core.colorimetry import delta_e_2000, lab_d50
    from tunespec.core.datasets import load_colorchecker_sg, read_sensitivities
    from tunespec.core.io.export import read_sensitivity_meta
    from tunespec.core.io.raw import full_to_plane_px
    from tunespec.core.io.session import Session
    from tunespec.core.processing import RoiSet, process_session, write_processed
    from tunespec.core.sensitivity import correct_illuminants_from_meta
    from tunespec.core.wiener import wiener_reflectance
    from tunespec.devices.capture import capture, new_session
    from tunespec.devices.registry import open_bench, parse_resolution
    from tunespec.devices.sim.scene import default_regions

    res = parse_resolution(args.resolution)
    work = args.work or Path(tempfile.gettempdir()) / f"tunespec-acc-{args.resolution}"
    shutil.rmtree(work, ignore_errors=True)
    bench = open_bench(
        "sim", resolution=res, seed=0, scene_options={"regions": default_regions()}
    )
    session = new_session(
        work / "session", bench.light, bench.camera, layout=bench.truth["layout"],
        exposure="auto",
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
         str(work / "ill.csv"), "--reflectances", chart, "-o", str(sens_csv)])  # fmt: skip
    cli(["estimate-image", str(work / "session"), "--sensitivities", str(sens_csv),
         "--out", str(work / "images")])  # fmt: skip

    cube = np.array(
        spectral.open_image(str(work / "images" / "cube.hdr")).open_memmap()
    )
    lab = tifffile.imread(work / "images" / "lab.tif").astype(np.float64)
    unc = tifffile.imread(work / "images" / "uncertainty.tif").astype(np.float64)
    mlab = lab_d50(mats.values, GRID.wavelength_nm)
    n_patch = p.layout.n_patches

    meta = read_sensitivity_meta(sens_csv)
    ill = correct_illuminants_from_meta(
        p.illuminants.resample(GRID, average=True), meta
    )
    est = wiener_reflectance(
        p.responses, ill, read_sensitivities(sens_csv, GRID), load_colorchecker_sg(GRID)
    ).reflectance.values
    truth_p = mats.select(p.layout.patch_names).values
    de_patch = delta_e_2000(
        lab_d50(est, GRID.wavelength_nm), lab_d50(truth_p, GRID.wavelength_nm)
    )
    print(f"{args.resolution}: patch-wise mean dE00 {de_patch.mean():.3f}")
    for name, sel in (
        ("patches", (pm >= 2) & (pm < 2 + n_patch)),
        ("regions", pm >= 2 + n_patch),
        ("board", pm == 0),
    ):
        m = pm[sel]
        de = delta_e_2000(lab[sel], mlab[m])
        cov_l = np.mean(np.abs(lab[sel][:, 0] - mlab[m][:, 0]) < 1.96 * unc[sel][:, 0])
        cov_r = np.mean(np.abs(cube[sel] - mats.values[m]) < 1.96 * unc[sel][:, 1:2])
        rms = np.sqrt(np.mean((cube[sel] - mats.values[m]) ** 2))
        print(
            f"  {name:8s} {int(sel.sum()):7d} px: RMS {rms:.4f}, mean dE00 "
            f"{de.mean():.3f} ({de.mean() / de_patch.mean():.1f}x patch-wise), "
            f"95 % coverage L* {cov_l:.3f}, spectrum {cov_r:.3f}"
        )
    rois = RoiSet.from_quads(
        p.layout.patch_names, full_to_plane_px(p.layout.roi_quads_px()), pm.shape
    )
    starts = np.concatenate([[0], np.cumsum(rois.n_pixels)[:-1]])
    means = np.add.reduceat(cube[rois.rows, rois.cols], starts, axis=0)
    means /= rois.n_pixels[:, None]
    print(
        f"  patch means of pixels vs patch-wise estimate: RMS "
        f"{np.sqrt(np.mean((means - est) ** 2)):.4f}, max {np.abs(means - est).max():.4f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
