"""Where the time of ``tunespec estimate-image`` goes, stage by stage.

Usage::

    python benchmarks/bench_image_stages.py [--resolution 5760x3840] [--work DIR]

Runs the stages of :mod:`tunespec.app.pipeline.image_session` one after the other in this
thread (no Dask: the sum of the stages is the work the threads share) on the
session ``benchmarks/bench_image.py`` captures (the same ``--work`` folder; captured
here if missing), and prints wall, user and system seconds and minor page faults
of each stage and of the steps inside them (raw decode, planes, dark, Eq. 2, the
response stack's writes and reads, the per-pixel Wiener estimate, the writers).
"""

from __future__ import annotations

import argparse
import resource
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

_TOTALS: dict[str, np.ndarray] = {}


def _now() -> np.ndarray:
    r = resource.getrusage(resource.RUSAGE_THREAD)
    return np.array([time.perf_counter(), r.ru_utime, r.ru_stime, r.ru_minflt])


def _timed(owner: Any, name: str, label: str) -> None:
    """Replace ``owner.name`` by a wrapper that adds its costs to ``label``."""
    func: Callable[..., Any] = getattr(owner, name)

    def run(*args: Any, **kwargs: Any) -> Any:
        t0 = _now()
        try:
            return func(*args, **kwargs)
        finally:
            _TOTALS[label] = _TOTALS.get(label, 0) + (_now() - t0)

    setattr(owner, name, run)


def _instrument() -> None:
    import tunespec.app.pipeline.image_session as st
    from tunespec.core.io import image_formats, raw

    for owner, name, label in (
        (st, "load_raw", "  raw decode (load_raw)"),
        (raw.RawFrame, "planes_in", "  planes (black, scale)"),
        (raw.RawFrame, "planes_minus", "  planes (black, scale)"),  # and the dark
        (raw.RawFrame, "saturated_in", "  clipped cells"),
        (st, "block_noise_stats", "  photon-transfer points"),
        (st, "pwrite_all", "  response stack: write"),
        (st, "_read_stack_rows", "  response stack: read"),
        (st, "estimate_pixels", "  Wiener, colour, uncertainty"),
        # the outputs' writes (direct where large; all cached in older trees)
        (image_formats, "pwrite_direct", "  cube + TIFF writes"),
        (image_formats, "_write_file", "  Zarr chunk writes"),  # older trees
    ):
        if hasattr(owner, name):  # older trees lack some steps
            _timed(owner, name, label)
    if not hasattr(image_formats, "pwrite_direct"):
        _timed(image_formats, "pwrite_all", "  cube + TIFF writes")


def run_stages(session_dir: Path, sensitivities: Path, out: Path) -> np.ndarray:
    """Every stage of one session in this thread; returns the total costs."""
    import tunespec.app.pipeline.image_session as st
    from tunespec.app.pipeline import image as pim
    from tunespec.app.pipeline.image_systematic import systematic_table
    from tunespec.core.io.session import Session

    settings = pim.ImageSettings()
    cal = pim._load_calibration(sensitivities, pim._default_grid())
    shutil.rmtree(out, ignore_errors=True)
    t_all = _now()

    def stage(label: str, func: Callable[..., Any], *args: Any, **kw: Any) -> Any:
        t0 = _now()
        try:
            return func(*args, **kw)
        finally:
            _TOTALS[label] = _TOTALS.get(label, 0) + (_now() - t0)

    session = Session.open(session_dir)
    job = stage("plan", st.plan_image_job, session, out / pim.WORK_DIR)
    for i in range(len(job.dark_keys)):
        stage("1 darks", st.prepare_darks, job, i)
    if hasattr(st, "warm_up"):
        stage("warm-up (imports, D50 weights)", st.warm_up, cal.grid.wavelength_nm)
    results = [
        stage("2 LEDs: read, dark, Eq. 2, stack", st.prepare_channel, job, j)
        for j in range(len(job.channels))
    ]
    bank = stage(
        "3 setup (noise, F, Wiener bank)", st.setup_estimation, job, results,
        cal.sensitivity, cal.meta, cal.prior, cal.grid, noise=settings.noise,
    )  # fmt: skip
    systematic = stage(
        "3 systematic uncertainty table", systematic_table, job, bank, cal.path,
        cal.meta, cal.prior, cal.grid,
    )  # fmt: skip
    shape = job.plane_shape
    rows = st.block_rows_for(shape[1])
    prov = pim._provenance(session, job, cal, settings, None, shape)
    outputs = stage(
        "create outputs", pim._create_outputs, out, shape, bank, rows, prov,
        settings.formats,
    )  # fmt: skip

    def block(r0: int) -> Any:
        r1 = min(r0 + rows, shape[0])
        return st.estimate_block(job, bank, outputs, r0, r1, keep_uncertainty=True)

    blocks = [
        stage("4 blocks: read, Eq. 5, write", block, r0)
        for r0 in range(0, shape[0], rows)
    ]
    stage(
        "5 uncertainty, preview, provenance", pim._finish, job, outputs, bank,
        blocks, prov, systematic,
    )  # fmt: skip
    return _now() - t_all


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolution", default="5760x3840")
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument(
        "--floor-cpu-s",
        type=float,
        default=None,
        help="the decode + write floor's CPU seconds: adds each stage's CPU as a "
        "multiple of it (bench_image.py --stages passes its own)",
    )
    args = parser.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).parent))
    import bench_image

    work = (
        args.work or Path(tempfile.gettempdir()) / f"tunespec-image-{args.resolution}"
    )
    from raw_session import session_paths

    session_paths(
        work / "session", work, args.resolution, fresh=False,
        code=bench_image._capture_code(work, args.resolution),
    )  # fmt: skip
    from tunespec.app.pipeline.engine import limit_blas_threads

    limit_blas_threads()
    _instrument()
    try:  # as estimate_images runs them: freed frame buffers reused
        from tunespec.app.pipeline.heap import reused_heap
    except ImportError:  # an older tree
        from contextlib import nullcontext as reused_heap
    with reused_heap():
        total = run_stages(
            work / "session",
            work / "truth" / "truth_sensitivity_absolute.csv",
            work / "images_stages",
        )
    print(f"{args.resolution}, stages in one thread (steps indented, inside them):")
    floor = args.floor_cpu_s
    head = f"{'':36s} {'wall s':>7s} {'user s':>7s} {'sys s':>7s} {'faults':>8s}"
    print(head + (" CPU/floor" if floor else ""))

    def row(label: str, v: np.ndarray) -> None:
        ratio = f" {(v[1] + v[2]) / floor:9.2f}" if floor else ""
        print(f"{label:36s} {v[0]:7.2f} {v[1]:7.2f} {v[2]:7.2f} {v[3]:8.0f}{ratio}")

    for label, v in sorted(_TOTALS.items(), key=lambda kv: kv[0].lstrip()):
        row(label, v)
    row("total", total)
    shutil.rmtree(work / "images_stages", ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
