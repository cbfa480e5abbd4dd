"""The gonio sessions' HDR brackets as a check of their frames' linearity
(``core.hdr.fit_bracket_bend``, ``core.plausibility.bracket_bend_warning``): what
a linear sensor's brackets show, and what frames on a tone curve do.

For each seed, the simulated gonio bench's session (``gonio-demo``, the default
plan of ``--geometries``: HDR brackets 1, 1/8, 1/64 from theta_r 25 deg on) is
captured once; copies of it get every frame's dark-subtracted signal through
``c^E`` for each tone ``E`` of ``--tones`` (as a JPEG's or a gamma TIFF's would
be) and are processed again. Prints, per seed and tone, the range of the bend
found over the HDR geometries and how many of them are warned of, with the
session's D50 dE00 (fused and full captures) against the bench's truth.

    python benchmarks/bracket_bend.py                      # 3 seeds (~3 min)
    python benchmarks/bracket_bend.py --seeds 0,1,2,3,4 --geometries 14
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import re
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from tunespec.app.pipeline.gonio import GonioPlan
from tunespec.app.pipeline.gonio_bench import run_gonio_demo

_GAMMA = re.compile(r"gamma ([+-]\d+\.\d+)")


def _toned(src: Path, dst: Path, tone: float) -> None:
    """``src``'s session with every frame's signal above its dark through ``c^tone``."""
    shutil.copytree(src, dst)
    plan = GonioPlan.load(dst / "plan.json")
    for i in range(len(plan.steps)):
        gdir = dst / plan.folder(i)
        dark = np.load(gdir / "dark_e0.npy")
        for path in gdir.glob("*_e*.npy"):
            if path.name.startswith("dark_"):
                continue
            frame = np.load(path)
            signal = np.maximum(frame - dark, 0.0) ** tone
            np.save(path, (signal + dark).astype(frame.dtype))


def _bracket_bend(gdir: Path) -> float:
    """The bend of a geometry's mix brackets over the whole frame (the product
    fits the target's ROI pixels of every illuminant)."""
    from tunespec.app.pipeline.gonio import HDR_EXPOSURES, MIX
    from tunespec.core.hdr import fit_bracket_bend

    dark = np.load(gdir / "dark_e0.npy").astype(np.float64)
    stack = np.stack(
        [np.load(gdir / f"{MIX}_e{k}.npy") - dark for k in range(len(HDR_EXPOSURES))]
    )
    return fit_bracket_bend(stack.reshape(len(HDR_EXPOSURES), -1), HDR_EXPOSURES)[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--geometries", type=int, default=8)
    ap.add_argument("--tones", default="1,0.952381,1.1,0.833333")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    tones = [float(t) for t in args.tones.split(",")]
    t0 = time.perf_counter()
    print(
        "seed  tone    HDR geometries  warned  gamma (whole frames)      dE00 fused / full"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            base = Path(tmp) / f"s{seed}"
            run_gonio_demo(base, n_geometries=args.geometries, seed=seed)
            for tone in tones:
                root = base if tone == 1.0 else Path(tmp) / f"s{seed}_{tone:g}"
                if tone != 1.0:
                    _toned(base, root, tone)
                s = run_gonio_demo(root, n_geometries=args.geometries, seed=seed)
                plan = GonioPlan.load(root / "plan.json")
                hdr = [i for i, st in enumerate(plan.steps) if st.hdr]
                said = [float(_GAMMA.search(w).group(1)) for w in s["warnings"]]
                whole = [_bracket_bend(root / plan.folder(i)) for i in hdr]
                print(
                    f"{seed:4d}  {tone:6.4f}  {len(hdr):14d}  {len(said):6d}  "
                    f"{min(whole):+.4f} to {max(whole):+.4f}       "
                    f"{s['de00_fused_mean']:.3f} / {s['de00_full_captures_mean']:.3f}"
                )
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
