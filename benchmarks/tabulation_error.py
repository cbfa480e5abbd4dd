"""How far the colour of a surface's samples lies from the surface's own colour, and
whether anything in the samples predicts it (issue 23's missing budget line).

The L*a*b* an estimate writes is the colour of its samples on the estimation grid
(ASTM E308's weights), compared like with like with the colour of the truth's samples.
The responses integrate the surface itself, so a surface's structure between its
samples enters the estimate and not that colour. Per collection this prints the
standard deviation over its surfaces of L*, a*, b* of the 10 nm samples against the
1 nm surface, split into the part of ASTM E308's weights against the 1 nm integral of
the spline through the samples (the curve Eq. 1's matrix assumes between them) and
the surface's own departure from that spline; then the ratio of the latter to a
predictor from the samples alone (each sample's second difference through the
colour's gradient). A budget line sized on some collections holds on others only if
that ratio is the same for all of them.

The benchmark's four test collections (``generalisation_data.test_reflectances``)
and any more given as CSV files, a wavelength column then one column per surface, 1
nm, no header (luxpy's ``data/rfls/*.dat``, for example ``Munsell1269.dat`` and
``Opstelten1983_215.dat``: ``pip download --no-deps luxpy`` and unzip; GPL-3, not a
dependency):

    python benchmarks/tabulation_error.py
    python benchmarks/tabulation_error.py lux/data/rfls/Munsell1269.dat
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import generalisation as gen
import generalisation_data as gd

from tunespec.core.colorimetry import lab_d50
from tunespec.core.spectra import Grid, Spectra, spline_matrix

FINE = Grid(400.0, 700.0, 1.0)


def read_columns(path: Path) -> Spectra:
    """A wavelength column, then one column per spectrum (comma-separated)."""
    a = np.loadtxt(path, delimiter=",")
    names = tuple(f"{path.stem}-{j}" for j in range(a.shape[1] - 1))
    return Spectra(a[:, 0], a[:, 1:].T, names)


def _lab_gradient(samples: Spectra, step: float = 1e-4) -> np.ndarray:
    """d(L*, a*, b*) / d(each sample), per surface: (n, 3, n_samples)."""
    base = lab_d50(samples)
    out = np.empty((*base.shape, samples.values.shape[1]))
    for k in range(samples.values.shape[1]):
        v = samples.values.copy()
        v[:, k] += step
        out[:, :, k] = (lab_d50(samples.with_values(v)) - base) / step
    return out


def decompose(surfaces: Spectra, grid: Grid) -> dict[str, np.ndarray]:
    """Per surface, L*a*b* of its samples on ``grid`` against its 1 nm colour, and the
    two parts of that difference; the predictor from the samples alone."""
    fine, samples = surfaces.resample(FINE), surfaces.resample(grid)
    spline = Spectra(
        FINE.wavelength_nm,
        samples.values @ spline_matrix(grid.wavelength_nm, FINE.wavelength_nm).T,
        samples.names,
    )
    lab_samples, lab_spline, lab_fine = lab_d50(samples), lab_d50(spline), lab_d50(fine)
    second = np.zeros_like(samples.values)
    second[:, 1:-1] = np.diff(samples.values, n=2, axis=1)
    predictor = np.sqrt(np.einsum("njk,nk->nj", _lab_gradient(samples) ** 2, second**2))
    return {
        "samples vs surface": lab_samples - lab_fine,
        "E308 vs spline": lab_samples - lab_spline,
        "spline vs surface": lab_spline - lab_fine,
        "predictor": predictor,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path, help="more collections (1 nm CSV)")
    ap.add_argument("--step-nm", type=float, default=10.0)
    args = ap.parse_args(argv)
    tests = gd.test_reflectances()
    groups = np.array([gen.collection(n) for n in tests.names])
    sets = {
        g: tests.select([n for n, h in zip(tests.names, groups, strict=True) if h == g])
        for g in sorted(set(groups))
    }
    sets.update({p.stem: read_columns(p) for p in args.files})
    grid = Grid(FINE.start_nm, FINE.end_nm, args.step_nm)
    print(
        f"colour of the {args.step_nm:g} nm samples against the 1 nm surface, "
        "standard deviation of L* / a* / b*, and the ratio of the surface's part "
        "to the predictor from the samples (rms over rms):"
    )
    for name, surfaces in sets.items():
        d = decompose(surfaces, grid)

        def sd(key: str, d: dict = d) -> str:
            return " / ".join(f"{v:.4f}" for v in d[key].std(0))

        ratio = np.sqrt(np.mean(d["spline vs surface"] ** 2, 0)) / np.sqrt(
            np.mean(d["predictor"] ** 2, 0)
        )
        print(
            f"  {name:<18} n {len(surfaces):>4}: {sd('samples vs surface')}; "
            f"E308 vs spline {sd('E308 vs spline')}; spline vs surface "
            f"{sd('spline vs surface')}; ratio {' / '.join(f'{r:.3f}' for r in ratio)}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
