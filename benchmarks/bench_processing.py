"""Processing a 22-LED session at full 5D Mark III resolution, against rawpy's decode.

Usage::

    python benchmarks/bench_processing.py [--resolution 5760x3840] [--repeat 3]
                                          [--work DIR] [--fresh] [--before SOURCE]

The first run captures a session on the simulated bench (one dark frame, then a
white-background and a target frame under each of the 22 LEDs at the paper's fixed
6 s, 45 CFA DNGs of 44 MB each; about a minute) into ``--work`` (kept for later
runs). Then, in this process and on the same (page-cached) files:

- **decode**: ``rawpy.imread`` + ``raw_image_visible`` copy of every file, the least
  any raw pipeline must do;
- **process**: :func:`tunespec.app.pipeline.processing.process_session` (reads every file
  with ``load_raw``, dark subtraction, Eq. 2 flat field, automatic corners, ROI
  statistics of the 140 ColorChecker SG patches).

It prints the best time of each over ``--repeat`` rounds, their ratio (goal: at most
1.1, i.e. processing adds at most 10 % to decoding: issue 28), and the peak memory of
processing: ``tracemalloc``'s peak of one extra run (Python and numpy allocations)
and the process's peak resident set size (goal: under 2 GB).
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

from raw_session import child_json, decode_all, session_paths

GOAL_RATIO = 1.1
GOAL_PEAK_BYTES = 2e9


def _capture_code(work: Path, resolution: str) -> str:
    """Python source capturing the benchmark session into ``work``."""
    return f"""
import sys
from tunespec.core.layout import TargetLayout
from tunespec.core.datasets import resource_path
from tunespec.devices.registry import open_bench, parse_resolution
from tunespec.devices.capture import new_session, capture
bench = open_bench("sim", resolution=parse_resolution({resolution!r}), seed=0)
layout = TargetLayout.load(resource_path("layouts", "colorchecker_sg.json"))
session = new_session({str(work)!r}, bench.light, bench.camera, layout=layout, exposure=6.0)
def bar(f):
    sys.stderr.write(f"\\rcapturing {{f:6.1%}}"); sys.stderr.flush()
capture(session, bench.light, bench.camera, bench.stage, progress=bar)
sys.stderr.write("\\n")
bench.close()
"""


def _process_in(source: Path | None, session_dir: Path) -> float:
    """Wall seconds of ``process_session`` in a child process, with the TuneSpec of
    ``source`` (``SOURCE/tunespec/core``, ...: an earlier commit's ``git archive``)
    or this one's (``None``)."""
    code = f"""
import json, time
from tunespec.core.io.session import Session
from tunespec.app.pipeline.processing import process_session
s = Session.open({str(session_dir)!r})
process_session(s)  # imports, ROIs rasterised: as the in-process runs are warm
t0 = time.perf_counter()
process_session(Session.open({str(session_dir)!r}))
print(json.dumps(time.perf_counter() - t0))
"""
    return float(child_json(code, source))


def _process(session_dir: Path) -> float:
    from tunespec.app.pipeline.processing import process_session
    from tunespec.core.io.session import Session

    t0 = time.perf_counter()
    process_session(Session.open(session_dir))
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--resolution", default="5760x3840")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument("--fresh", action="store_true", help="capture again")
    parser.add_argument(
        "--before",
        type=Path,
        default=None,
        metavar="SOURCE",
        help="also time process_session of this source tree (SOURCE/tunespec/core, "
        "...: an earlier commit's 'git archive COMMIT core app devices resources' "
        "unpacked into SOURCE/tunespec) and this one's, each in a child process, "
        "alternating with the decode",
    )
    args = parser.parse_args(argv)
    work = (
        args.work or Path(tempfile.gettempdir()) / f"tunespec-bench-{args.resolution}"
    )
    paths = session_paths(
        work,
        work,
        args.resolution,
        fresh=args.fresh,
        code=_capture_code(work, args.resolution),
    )
    decode_all(paths)  # warm the page cache and the decoder
    decode_s, process_s, before_s, child_s = [], [], [], []
    for _ in range(args.repeat):
        decode_s.append(decode_all(paths)[0])
        process_s.append(_process(work))
        if args.before is not None:
            before_s.append(_process_in(args.before, work))
            child_s.append(_process_in(None, work))
    d, p = min(decode_s), min(process_s)
    ratio = p / d
    if before_s:
        b, c = min(before_s), min(child_s)
        print(
            f"child processes: before ({args.before}) {b:.2f} s = {b / d:.2f} x the "
            f"decode; now {c:.2f} s = {c / d:.2f} x"
        )

    tracemalloc.start()
    _process(work)
    _, peak_traced = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    peak_rss = maxrss if sys.platform == "darwin" else maxrss * 1024

    print(
        f"rawpy decode (imread + raw_image_visible copy): {d:7.2f} s  "
        f"({1000 * d / len(paths):.0f} ms/frame)"
    )
    print(
        f"process_session                               : {p:7.2f} s  "
        f"({1000 * p / len(paths):.0f} ms/frame)"
    )
    print(
        f"ratio process / decode: {ratio:.2f}  (goal <= {GOAL_RATIO}: "
        f"{'met' if ratio <= GOAL_RATIO else 'NOT met'})"
    )
    print(
        f"peak memory: tracemalloc {peak_traced / 1e6:.0f} MB, process max RSS "
        f"{peak_rss / 1e6:.0f} MB  (goal < {GOAL_PEAK_BYTES / 1e9:.1f} GB: "
        f"{'met' if max(peak_traced, peak_rss) < GOAL_PEAK_BYTES else 'NOT met'})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
