"""The session's single-shot mix on the simulated gonio bench: D50 match vs camera-tuned.

Usage::

    python benchmarks/bench_gonio_mix.py [--seeds 0,1,2,3] [--geometries 14]

For each seed, two gonio sessions (``run_gonio_demo``, the default plan: 3 spectral
geometries) differ only in the plan's ``mix``: ``d50`` (the plain D50 match) and
``camera`` (that match tuned for the calibrated camera, CIE 51.2 category B kept).
Prints, side by side, the single-shot XYZ's mean CIEDE2000 against the bench's truth
at the single-shot-only geometries (what the mix is for), the fused spectra's D50
colorimetry and spectral RMS ratio, and the mix's own figures (the camera's noise-free
RMS CIELAB error over the SG, CIE Ra / TM-30 Rf of the SPD the light reported).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from tunespec.app.pipeline.gonio_bench import run_gonio_demo


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3")
    ap.add_argument("--geometries", type=int, default=14)
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    head = (
        f"{'seed':>4} {'mix':>6} | {'ss dE00':>7} {'ss max':>6} | {'fused':>6} "
        f"{'RMS x':>5} | {'cam dEab':>9} {'Ra':>5} {'Rf':>5}"
    )
    print(head + "\n" + "-" * len(head))
    gains = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            row = {}
            for kind in ("d50", "camera"):
                folder = Path(tmp) / f"{kind}{seed}"
                s = run_gonio_demo(
                    folder, n_geometries=args.geometries, mix=kind, seed=seed
                )
                doc = json.loads((folder / "mix.json").read_text())
                cam = doc.get("camera_mix", {})
                m = doc["measured"]
                row[kind] = s["de00_single_shot_fused_mean"]
                cam_err = (
                    f"{cam['camera_rms_deab_d50_match']:.2f}>{cam['camera_rms_deab']:.2f}"
                    if cam
                    else "-"
                )
                print(
                    f"{seed:>4} {kind:>6} | {s['de00_single_shot_fused_mean']:7.3f} "
                    f"{s['de00_single_shot_fused_max']:6.2f} | "
                    f"{s['de00_fused_mean']:6.3f} {s['rms_ratio_fused_to_full']:5.2f} | "
                    f"{cam_err:>9} {m['cri_ra']:5.1f} {m['tm30_rf']:5.1f}"
                )
            gains.append(row["camera"] / row["d50"])
    print(
        "camera-tuned / D50 match, single-shot mean dE00 at the single-shot-only "
        f"geometries: {', '.join(f'{g:.2f}' for g in gains)} "
        f"(mean {sum(gains) / len(gains):.2f})"
    )


if __name__ == "__main__":
    main()
