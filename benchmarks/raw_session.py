"""The captured raw session and the rawpy baseline that the speed benchmarks share.

``bench_image.py`` and ``bench_processing.py`` both time a pipeline against the least
any raw pipeline must do, ``rawpy.imread`` + ``raw_image_visible`` copy of the same
files, on a full-resolution session captured once on the simulated bench and kept in
a work folder for later runs.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any


def session_paths(
    session_dir: Path, work: Path, resolution: str, *, fresh: bool, code: str
) -> list[Path]:
    """The raw files of the session in ``session_dir``; captured first if absent.

    ``code`` is the Python source that captures it into ``work``; it runs in a child
    process, so that its memory is not the benchmark's to measure.
    """
    from tunespec.core.io.session import Session

    if (
        fresh
        or not (session_dir / "manifest.json").is_file()
        or Session.open(session_dir).missing(verify=False)
    ):
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir(parents=True)
        print(f"capturing a 22-LED session at {resolution} into {work} ...")
        subprocess.run([sys.executable, "-c", code], check=True)
    session = Session.open(session_dir)
    paths = [session.path_of(f) for f in session.frames]
    size_mb = sum(p.stat().st_size for p in paths) / 1e6
    print(f"session: {len(paths)} raw files, {size_mb:.0f} MB, {resolution}")
    return paths


def decode_all(paths: list[Path]) -> tuple[float, float]:
    """Wall and CPU seconds of decoding every file (``raw_image_visible`` copy)."""
    import rawpy

    t0, c0 = time.perf_counter(), time.process_time()
    for p in paths:
        with rawpy.imread(str(p)) as raw:
            mosaic = raw.raw_image_visible.copy()
        del mosaic
    return time.perf_counter() - t0, time.process_time() - c0


def child_json(code: str, source: Path | None = None) -> Any:
    """Run Python ``code`` in a child process and return the JSON its last stdout
    line prints; with ``source``, the child imports the TuneSpec there
    (``SOURCE/tunespec/core``, ...: an earlier commit's ``git archive``) instead of
    this one, so both can be timed side by side in one run."""
    env = dict(os.environ)
    if source is not None:
        env["PYTHONPATH"] = str(source)
    done = subprocess.run(
        [sys.executable, "-c", code], check=True, capture_output=True, text=True,
        env=env,
    )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])
