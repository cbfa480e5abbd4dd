"""Per-pixel images of a full-resolution 22-LED session, against rawpy's decode.

Usage::

    python benchmarks/bench_image.py [--resolution 5760x3840] [--repeat 1]
                                     [--work DIR] [--fresh] [--workers N]
                                     [--formats envi,zarr,tiff] [--before SOURCE]
                                     [--stages]

The first run captures a session on the simulated bench (the ColorChecker SG with a
CMY halftone and measured-reflectance strokes beside it; one dark frame, then a
white-background and a target frame under each of the 22 LEDs at a fixed 6 s: 45
CFA DNGs) into ``--work`` (kept for later runs). Then, side by side in one run:

- **decode**: ``rawpy.imread`` + ``raw_image_visible`` copy of the same 45 files
  (page-cached), the least any raw pipeline must do;
- **images**: ``tunespec estimate-image`` of the session
  (:func:`tunespec.app.pipeline.image.estimate_images`, Dask's local threaded
  scheduler, ``--formats``) in a child process, which reports its wall time and its
  peak resident set size (goal: at most 1.5x the decode + write floor, under 2 GB);
- **Wiener stage vs. matrix product**: the per-pixel Eq. 5 of one block
  (:data:`~tunespec.app.pipeline.image_session.BLOCK_PIXELS` pixels as rows, 66
  responses, 61 wavelengths; binning, sorting by bin, the products per bin,
  limiting to [0, 1], unsorting) against ``numpy.matmul`` of the same float32
  shapes in one product, both with one BLAS thread, as the pipeline runs its
  tasks (one per core), on this machine (goal: the stage at >= 50 % of the product's throughput); the
  product with BLAS's default threads is printed beside it;
- **write floor**: writing as many bytes as the outputs hold into a fresh file, with
  no computing, right after each estimate-image run: what the page cache of this
  machine charges for the outputs alone;
- **stages** (``--stages``): every stage in one thread
  (``bench_image_stages.py``), its CPU seconds and their multiple of the floor's
  (decode CPU + write);
- **binning error**: binned vs. exact per-pixel solutions (own ``K_e`` per pixel) of
  noisy pixels of the 190 training reflectances, RMS and CIEDE2000.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from raw_session import child_json, decode_all, session_paths

DEFAULT_FORMATS = "envi,zarr,tiff"
GOAL_RATIO = 1.5
GOAL_PEAK_BYTES = 2e9
GOAL_MATMUL_FRACTION = 0.5


def _capture_code(work: Path, resolution: str) -> str:
    """Python source capturing the benchmark session into ``work``."""
    return f"""
from tunespec.devices.registry import open_bench, parse_resolution
from tunespec.devices.capture import new_session, capture
from tunespec.devices.sim.scene import default_regions
bench = open_bench("sim", resolution=parse_resolution({resolution!r}), seed=0,
                   scene_options={{"regions": default_regions()}})
session = new_session({str(work / "session")!r}, bench.light, bench.camera,
                      layout=bench.truth["layout"], exposure=6.0)
capture(session, bench.light, bench.camera, bench.stage)
bench.sim_camera.write_truth({str(work / "truth")!r})
bench.close()
"""


def _images(
    work: Path,
    out: Path,
    workers: int | None,
    formats: str,
    source: Path | None = None,
) -> dict[str, float]:
    """``tunespec estimate-image`` in a child process: wall time, CPU, peak RSS.

    ``source``: run the TuneSpec of that tree instead (``SOURCE/tunespec/core``
    ...: ``git archive COMMIT core app devices resources`` unpacked into
    ``SOURCE/tunespec``), for a before/after comparison in one run.
    """
    extra = [] if formats == DEFAULT_FORMATS else ["--formats", formats]
    code = f"""
import json, resource, shutil, sys, time
import dask
from tunespec.app.cli import main
shutil.rmtree({str(out)!r}, ignore_errors=True)
if {workers!r}:
    dask.config.set(num_workers={workers!r})
t0 = time.perf_counter()
code = main(["estimate-image", {str(work / "session")!r}, "--sensitivities",
             {str(work / "truth" / "truth_sensitivity_absolute.csv")!r},
             "--out", {str(out)!r}, "--quiet", *{extra!r}])
wall = time.perf_counter() - t0
assert code == 0, code
ru = resource.getrusage(resource.RUSAGE_SELF)
rss = ru.ru_maxrss * (1 if sys.platform == "darwin" else 1024)
print(json.dumps({{"wall_s": wall, "peak_rss_bytes": rss, "user_s": ru.ru_utime,
                  "sys_s": ru.ru_stime}}))
"""
    return child_json(code, source)


def _output_bytes(out: Path) -> int:
    """Bytes of the files ``estimate-image`` wrote (cube, TIFFs, PNG), each file
    once (``cube.img`` is a hard link to the Zarr shard: the cube is written once)
    and without holes (the padding of the shard's last chunk)."""
    seen: dict[tuple[int, int], int] = {}
    for p in out.rglob("*"):
        if p.is_file():
            st = p.stat()
            seen[(st.st_dev, st.st_ino)] = min(st.st_size, st.st_blocks * 512)
    return sum(seen.values())


def _write_floor(folder: Path, n_bytes: int) -> float:
    """Wall seconds to write ``n_bytes`` of float32 noise into a fresh file in
    ``folder`` with positioned writes of 64 MB (as the outputs are written): what
    the outputs cost this machine's page cache alone, without computing them."""

    import numpy as np

    chunk = np.random.default_rng(0).random((16 << 20,), dtype=np.float32)
    view = memoryview(chunk).cast("B")
    path = folder / "write-floor.tmp"
    t0 = time.perf_counter()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    try:
        for offset in range(0, n_bytes, view.nbytes):
            os.pwrite(fd, view[: min(view.nbytes, n_bytes - offset)], offset)
    finally:
        os.close(fd)
    wall = time.perf_counter() - t0
    path.unlink()
    return wall


def _synthetic_system() -> tuple:
    """Grid, F (22 LEDs x the 5D Mark III, the white board at 0.75 full scale in
    each LED's strongest channel), the white levels and the camera's noise model."""
    import numpy as np

    from tunespec.core.datasets import load_camera, load_led_set
    from tunespec.core.forward_model import lighting_matrix
    from tunespec.core.image import NoiseModel
    from tunespec.core.spectra import Grid

    grid = Grid(400.0, 700.0, 5.0)
    F = lighting_matrix(load_led_set(grid).values, load_camera(grid=grid).values, 5.0)
    white = F @ np.full(grid.n, 0.9)
    F *= np.repeat(0.75 / white.reshape(-1, 3).max(axis=1), 3)[:, None]
    noise = NoiseModel.from_camera(full_well_e=67000.0, read_noise_e=30.0)
    return grid, F, F @ np.full(grid.n, 0.9), noise


def _wiener_vs_matmul() -> dict[str, float]:
    """The binned Wiener stage of one block against one float32 product: the stage
    as :func:`~tunespec.core.image.estimate_pixels` runs it in the pipeline
    (:func:`~tunespec.core.image_bins.apply_bank`: levels, bins, sorting, the
    products, limiting to [0, 1] as ``estimate-image`` does unless ``--no-clip``,
    unsorting)."""
    import numpy as np

    from tunespec.app.pipeline.image_session import BLOCK_PIXELS
    from tunespec.core.datasets import load_colorchecker_sg
    from tunespec.core.image import build_wiener_bank, estimate_pixels
    from tunespec.core.image_bins import apply_bank

    grid, F, white, noise = _synthetic_system()
    sg = load_colorchecker_sg(grid).values
    bank = build_wiener_bank(
        F, sg, white, noise, grid.wavelength_nm, phi_range=(1, 1.9)
    )
    rng = np.random.default_rng(0)
    n = BLOCK_PIXELS
    truth = sg[rng.integers(0, len(sg), n)] * rng.uniform(0.3, 1.1, (n, 1))
    phi = rng.uniform(1.0, 1.9, n).astype(np.float32)
    c = (truth @ F.T).astype(np.float32)  # pixels as rows
    c += rng.standard_normal(c.shape).astype(np.float32) * 1e-3
    m, n_wl = F.shape[0], grid.n
    W0 = bank.Wt[0].copy()
    flops = 2.0 * n_wl * m * n

    def best(fn, k=5):
        times = []
        for _ in range(k):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return min(times)

    from threadpoolctl import threadpool_limits

    t_mm_default = best(lambda: c @ W0)  # BLAS's own thread count
    with threadpool_limits(1):  # as the pipeline runs it: one BLAS thread a task
        t_mm = best(lambda: c @ W0)
        # into a preallocated result, as the pipeline's blocks (a scratch buffer)
        est = np.empty((n, n_wl), dtype=np.float32)
        t_stage = best(lambda: apply_bank(bank, c, phi, est, clip=True))
        t_pix = best(lambda: estimate_pixels(bank, c, phi), k=3)
    return {
        "pixels": n,
        "matmul_1thread_gflops": flops / t_mm / 1e9,
        "matmul_default_gflops": flops / t_mm_default / 1e9,
        "stage_gflops": flops / t_stage / 1e9,
        "fraction": t_mm / t_stage,  # both with one thread, as the pipeline runs
        "matmul_s": t_mm,
        "stage_s": t_stage,
        "estimate_pixels_s": t_pix,
    }


def _binning_error() -> dict[str, float]:
    """Binned vs. exact per-pixel Eq. 5 on noisy pixels (photon + read noise)."""
    import numpy as np

    from tunespec.core.colorimetry import delta_e_2000, lab_d50
    from tunespec.core.datasets import (
        load_colorchecker_sg,
        load_training_reflectances_190,
    )
    from tunespec.core.image import build_wiener_bank, estimate_pixels

    grid, F, white, noise = _synthetic_system()
    bank = build_wiener_bank(
        F, load_colorchecker_sg(grid).values, white, noise, grid.wavelength_nm,
        phi_range=(1.0, 1.9),
    )  # fmt: skip
    rng = np.random.default_rng(1)
    truth = np.repeat(load_training_reflectances_190(grid).values, 20, axis=0)
    phi = rng.uniform(1.0, 1.9, len(truth))
    c = truth @ F.T
    var = noise.variance(c, phi[:, None], bank.channel_index)
    c = (c + rng.standard_normal(c.shape) * np.sqrt(var)).astype(np.float32)
    binned = estimate_pixels(bank, c, phi)
    exact = estimate_pixels(bank, c, phi, exact=True)
    lab_t = lab_d50(truth, grid.wavelength_nm)
    rms = lambda a, b: float(np.sqrt(np.mean((a - b) ** 2)))  # noqa: E731
    return {
        "pixels": len(truth),
        "rms_binned_vs_exact": rms(binned.reflectance, exact.reflectance),
        "rms_exact_vs_truth": rms(exact.reflectance, truth),
        "rms_binned_vs_truth": rms(binned.reflectance, truth),
        "de00_binned_vs_exact_mean": float(
            delta_e_2000(binned.lab.astype(float), exact.lab.astype(float)).mean()
        ),
        "de00_exact_vs_truth_mean": float(
            delta_e_2000(exact.lab.astype(float), lab_t).mean()
        ),
        "de00_binned_vs_truth_mean": float(
            delta_e_2000(binned.lab.astype(float), lab_t).mean()
        ),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolution", default="5760x3840")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument("--fresh", action="store_true", help="capture again")
    parser.add_argument("--workers", type=int, default=None, help="Dask threads")
    parser.add_argument(
        "--stages",
        action="store_true",
        help="also run every stage in one thread (bench_image_stages.py, a child "
        "process) and print each one's CPU as a multiple of the decode + write floor",
    )
    parser.add_argument(
        "--formats", default=DEFAULT_FORMATS, help="estimate-image --formats"
    )
    parser.add_argument(
        "--before",
        type=Path,
        default=None,
        metavar="SOURCE",
        help="also time the estimate-image of this source tree (SOURCE/tunespec/"
        "core, ...: an earlier commit's 'git archive COMMIT core app devices "
        "resources' unpacked into SOURCE/tunespec), alternating with this one",
    )
    args = parser.parse_args(argv)
    work = (
        args.work or Path(tempfile.gettempdir()) / f"tunespec-image-{args.resolution}"
    )
    paths = session_paths(
        work / "session",
        work,
        args.resolution,
        fresh=args.fresh,
        code=_capture_code(work, args.resolution),
    )
    decode_all(paths)  # warm the page cache and the decoder
    decode, images, floors, before = [], [], [], []
    for _ in range(args.repeat):
        decode.append(decode_all(paths))
        if args.before is not None:
            before.append(
                _images(work, work / "images", args.workers, DEFAULT_FORMATS,
                        args.before)
            )  # fmt: skip
        images.append(_images(work, work / "images", args.workers, args.formats))
        floors.append(_write_floor(work, _output_bytes(work / "images")))
    d, d_cpu = min(decode)
    floor = min(floors)
    best = min(images, key=lambda r: r["wall_s"])
    ratio = best["wall_s"] / (d + floor)
    peak = max(r["peak_rss_bytes"] for r in images)
    cpu = best["user_s"] + best["sys_s"]
    print(f"rawpy decode of the {len(paths)} files : {d:7.2f} s  (CPU {d_cpu:.2f} s)")
    print(
        f"estimate-image (cube, Zarr, TIFFs) : {best['wall_s']:7.2f} s  (CPU "
        f"{cpu:.2f} s: user {best['user_s']:.2f}, system {best['sys_s']:.2f}; "
        f"CPU ratio {cpu / d_cpu:.1f})"
    )
    n_out = _output_bytes(work / "images")
    print(
        f"writing the outputs' {n_out / 1e9:.2f} GB alone (no computing): {floor:.2f} s "
        f"= {floor / d:.2f} x the decode"
    )
    if before:
        b = min(before, key=lambda r: r["wall_s"])
        print(
            f"before ({args.before}): {b['wall_s']:.2f} s (CPU user {b['user_s']:.2f}, "
            f"system {b['sys_s']:.2f}) -> ratio to decode + write "
            f"{b['wall_s'] / (d + floor):.2f}; now / before "
            f"{best['wall_s'] / b['wall_s']:.2f}"
        )
    print(
        f"ratio images / (decode + write): {ratio:.2f}  (goal <= {GOAL_RATIO}: "
        f"{'met' if ratio <= GOAL_RATIO else 'NOT met'}); images / decode "
        f"{best['wall_s'] / d:.2f}; formats {args.formats}"
    )
    print(
        f"peak RSS of estimate-image: {peak / 1e6:.0f} MB  (goal < "
        f"{GOAL_PEAK_BYTES / 1e9:.0f} GB: {'met' if peak < GOAL_PEAK_BYTES else 'NOT met'})"
    )
    if args.stages:
        # the floor's CPU: the decode's, and the write's (system time, all of it)
        print(f"stages (floor: decode CPU {d_cpu:.2f} s + write {floor:.2f} s):")
        sys.stdout.flush()
        subprocess.run(
            [sys.executable, str(Path(__file__).parent / "bench_image_stages.py"),
             "--resolution", args.resolution, "--work", str(work),
             "--floor-cpu-s", f"{d_cpu + floor:.3f}"],
            check=True,
        )  # fmt: skip
    w = _wiener_vs_matmul()
    print(
        f"Wiener stage, {w['pixels']} px, one BLAS thread (as the pipeline's tasks "
        f"run it): {w['stage_gflops']:.1f} GFLOP/s vs float32 matmul of the same "
        f"shapes, one BLAS thread, {w['matmul_1thread_gflops']:.1f} GFLOP/s (BLAS's "
        f"default threads: {w['matmul_default_gflops']:.1f}) -> "
        f"{w['fraction']:.0%} (goal >= {GOAL_MATMUL_FRACTION:.0%}: "
        f"{'met' if w['fraction'] >= GOAL_MATMUL_FRACTION else 'NOT met'}); "
        f"whole per-pixel estimate (colour, uncertainty) {w['estimate_pixels_s']:.3f} s"
    )
    b = _binning_error()
    print(
        f"binning error ({b['pixels']} noisy pixels of 190 reflectances): RMS "
        f"binned-exact {b['rms_binned_vs_exact']:.4f} vs exact-truth "
        f"{b['rms_exact_vs_truth']:.4f} (binned-truth {b['rms_binned_vs_truth']:.4f}); "
        f"dE00 binned-exact {b['de00_binned_vs_exact_mean']:.3f} vs exact-truth "
        f"{b['de00_exact_vs_truth_mean']:.3f} (binned-truth "
        f"{b['de00_binned_vs_truth_mean']:.3f})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
