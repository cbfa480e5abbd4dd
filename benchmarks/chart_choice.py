"""How the chart choice affects the calibration: ColorChecker 24 vs SG (vs IT8.7/2).

Runs :func:`tunespec.app.pipeline.chart_choice.compare_charts` on the simulated bench
(each chart captured, processed and calibrated with the default method; a held-out
card of 28 measured reflectances estimated with each calibration), prints the table,
writes ``chart_choice.json`` and a report (``chart_choice.html``/``.pdf``) whose
"Chart choice" section reads that JSON.

Usage::

    python benchmarks/chart_choice.py                       # CC24, SG, IT8 (~30 s)
    python benchmarks/chart_choice.py --charts colorchecker_24,colorchecker_sg
    python benchmarks/chart_choice.py --out results/ --seed 1
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import tempfile
from pathlib import Path

from tunespec.app.pipeline.chart_choice import CHARTS, compare_charts
from tunespec.app.report.report import ReportData, write_report


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--charts", default=",".join(CHARTS), help="comma-separated keys")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("chart_choice_out"))
    args = ap.parse_args(argv)
    charts = [c.strip() for c in args.charts.split(",") if c.strip()]
    with tempfile.TemporaryDirectory() as work:
        result = compare_charts(work, charts, seed=args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    result.save(args.out / "chart_choice.json")
    head = f"{'chart':<18}{'patches':>8}{'T1 RGB':>10}{'sens RMS':>10}"
    print(head + f"{'dE00 mean':>11}{'dE00 max':>10}{'spec RMS':>10}")
    for s in result.scores:
        print(
            f"{s.chart:<18}{s.n_patches:>8}{s.table1_rgb_mean:>10.5f}"
            f"{s.sensitivity_rms:>10.4f}{s.de00_mean:>11.3f}{s.de00_max:>10.3f}"
            f"{s.spectral_rms_mean:>10.4f}"
        )
    report = ReportData(title="Chart choice", chart_choice=result.to_dict())
    html, _ = write_report(args.out, report, stem="chart_choice")
    print(f"wrote {args.out / 'chart_choice.json'} and {html}")


if __name__ == "__main__":
    main()
