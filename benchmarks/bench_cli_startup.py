"""Start-up time of the ``tunespec`` command line, side by side with a bare Python.

Usage::

    python benchmarks/bench_cli_startup.py [--repeat 15]

Runs, alternately so that a busy machine slows both alike, ``python -c pass`` (the
floor: the interpreter and ``site``), ``tunespec --help``, ``tunespec --version`` and
one error (``tunespec calibrate`` on a file that does not exist), each as a fresh
process, and prints the median and best wall time of ``--repeat`` runs and each
median's ratio to the floor. Goal (issue 13): every one well under 0.5 s, which
holds as long as nothing imports scipy's estimators, colour-science or matplotlib
before a command needs them (``tests/test_cli_core.py`` checks the imports).

``tunespec`` is the console script installed beside this interpreter (the one
``pip install`` made), or ``python -m tunespec.app.cli`` where there is none.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GOAL_S = 0.5


def _run(cmd: list[str], cwd: str) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, cwd=cwd, capture_output=True, check=False)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    """Time the commands; exit status 1 if one misses the goal."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=15)
    args = parser.parse_args(argv)
    py = sys.executable
    script = Path(py).with_name("tunespec")
    cli = [str(script)] if script.is_file() else [py, "-m", "tunespec.app.cli"]
    cases = {
        "python -c pass": [py, "-c", "pass"],
        "tunespec --help": [*cli, "--help"],
        "tunespec --version": [*cli, "--version"],
        "tunespec calibrate (missing file)": [
            *cli,
            "calibrate",
            "--responses",
            "missing.csv",
            "--illuminants",
            "missing.csv",
            "--reflectances",
            "missing.csv",
            "-o",
            "out.csv",
        ],
    }
    times: dict[str, list[float]] = {name: [] for name in cases}
    with tempfile.TemporaryDirectory() as cwd:
        for cmd in cases.values():  # warm-up: the page cache, .pyc files
            _run(cmd, cwd)
        for _ in range(args.repeat):
            for name, cmd in cases.items():
                times[name].append(_run(cmd, cwd))
    floor = statistics.median(times["python -c pass"])
    print(f"{'command':<36} {'median':>9} {'best':>9} {'ratio':>7}")
    ok = True
    for name, ts in times.items():
        median = statistics.median(ts)
        print(
            f"{name:<36} {1000 * median:7.0f}ms {1000 * min(ts):7.0f}ms "
            f"{median / floor:6.1f}x"
        )
        ok &= median < GOAL_S
    print(
        f"tunespec --help / python -c pass: "
        f"{statistics.median(times['tunespec --help']) / floor:.1f}x "
        f"(goal: every command < {GOAL_S} s: {'met' if ok else 'MISSED'}; "
        f"{Path(py).name}, {args.repeat} runs each)"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
