"""How the chart choice affects the calibration, on the simulated bench.

For each chart (the ColorChecker 24, SG and, optionally, the IT8.7/2), on one and the
same simulated bench (same camera, same light, same seed):

1. the chart is captured under every LED, processed, and the camera's sensitivities
   calibrated from it (``steps.calibrate``, the product's default method): Table 1
   (RGB mean on the chart itself) and the sensitivity RMS against the bench's true
   sensitivities (peak-normalised, :func:`~tunespec.core.stats.sensitivity_rms`);
2. a held-out card of 28 measured reflectances that none of the charts carries
   (colour-science: the CIE 13.3 test colour samples TCS01-TCS14, CIE 1995, and the
   NIST CQS 9.0 samples VS1-VS14) is captured on the same bench and estimated by
   Wiener (Eq. 5-6, SG prior) with those sensitivities: Table 2 (mean and worst
   CIEDE2000 under D50, mean spectral RMS).

:func:`compare_charts` returns the scores; :meth:`ChartComparison.save` writes them as
JSON, which the report's "Chart choice" section reads (``ReportData.chart_choice``).
``benchmarks/chart_choice.py`` runs it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.core.datasets import load_colorchecker_sg, resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.session import atomic_write_text
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import dumps_json
from tunespec.core.spectra import CALIBRATION_GRID, DEFAULT_GRID, Spectra
from tunespec.core.stats import sensitivity_rms

__all__ = ["CHARTS", "ChartComparison", "ChartScore", "compare_charts", "held_out_card"]

#: Chart key -> (layout file, shipped reflectances or None for the IT8 bench draw).
CHARTS = {
    "colorchecker_24": ("colorchecker_24.json", "colorchecker_24.csv"),
    "colorchecker_sg": ("colorchecker_sg.json", "colorchecker_sg.csv"),
    "it8_7_2": ("it8_7_2.json", None),
}
HELD_OUT_SOURCE = (
    "colour-science: CIE 13.3 TCS01-TCS14 (CIE 1995) and NIST CQS 9.0 VS1-VS14"
)


@dataclass(frozen=True)
class ChartScore:
    """One chart's calibration on the bench and its estimation of the held-out card."""

    chart: str
    n_patches: int
    table1_rgb_mean: float
    sensitivity_rms: float
    de00_mean: float
    de00_max: float
    spectral_rms_mean: float


@dataclass(frozen=True)
class ChartComparison:
    scores: tuple[ChartScore, ...]
    held_out: str = HELD_OUT_SOURCE
    n_held_out: int = 28
    seed: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "tunespec-chart-choice",
            "version": 1,
            "held_out": self.held_out,
            "n_held_out": self.n_held_out,
            "seed": self.seed,
            "scores": [asdict(s) for s in self.scores],
        }

    def save(self, path: str | PathLike[str]) -> None:
        """Write the comparison as standard JSON, atomically (a resumed run reads
        it back)."""
        atomic_write_text(Path(path), dumps_json(self.to_dict()))


def held_out_card(grid: Any = DEFAULT_GRID) -> tuple[TargetLayout, Spectra]:
    """The held-out card: 4 x 7 patches of 25 mm on a 200 x 130 mm card."""
    import colour

    sds = {
        **dict(list(colour.quality.datasets.SDS_TCS["CIE 1995"].items())[:14]),
        **dict(list(colour.quality.datasets.SDS_VS["NIST CQS 9.0"].items())[:14]),
    }
    wl = np.asarray(grid.wavelength_nm, dtype=np.float64)
    values = np.array([np.interp(wl, sd.wavelengths, sd.values) for sd in sds.values()])
    refl = Spectra(wl, values, tuple(sds), {"source": HELD_OUT_SOURCE})
    layout = TargetLayout(
        "held-out card",
        rows=4,
        cols=7,
        width_mm=200.0,
        height_mm=130.0,
        margin_mm=(12.5, 12.5, 12.5, 12.5),
        patch_fraction=0.85,
        patch_names=refl.names,
    )
    return layout, refl


def _chart(key: str) -> tuple[TargetLayout, Spectra]:
    from tunespec.devices.sim.scene import it8_bench_reflectances

    if key not in CHARTS:
        raise InputError(f"unknown chart {key!r}; expected one of {', '.join(CHARTS)}")
    layout_file, refl_file = CHARTS[key]
    layout = TargetLayout.load(resource_path("layouts", layout_file))
    if refl_file is None:
        return layout, it8_bench_reflectances(layout.patch_names, DEFAULT_GRID)
    if key == "colorchecker_sg":
        return layout, load_colorchecker_sg(DEFAULT_GRID)
    return layout, read_spectra_csv(resource_path("charts", refl_file), DEFAULT_GRID)


def score_chart(
    key: str,
    work_dir: Path,
    *,
    seed: int = 0,
    resolution: tuple[int, int] | None = None,
) -> ChartScore:
    """Calibrate on chart ``key`` and estimate the held-out card (module docstring)."""
    from tunespec.app.pipeline.steps import (
        bench_for_target,
        calibrate,
        capture_target,
        estimate,
        process,
    )
    from tunespec.devices.registry import open_bench

    layout, refl = _chart(key)
    card, card_refl = held_out_card()
    with open_bench(
        "sim", None, layout=layout, reflectances=refl, seed=seed, resolution=resolution
    ) as bench:
        session, _ = capture_target(bench, work_dir / key, layout)
        sample_bench = bench_for_target(bench, card, card_refl)
        sample, _ = capture_target(sample_bench, work_dir / f"{key}-held-out", card)
        truth = bench.truth["absolute_sensitivity"]
    cal = calibrate(process(session), refl)
    est = estimate(process(sample), cal.sensitivity, reference=card_refl)
    t2 = est.table2
    assert t2 is not None  # a reference was given
    return ChartScore(
        chart=layout.name,
        n_patches=layout.n_patches,
        table1_rgb_mean=float(cal.table1.mean[3]),
        sensitivity_rms=sensitivity_rms(
            cal.sensitivity.values, truth.resample(CALIBRATION_GRID).values
        ),
        de00_mean=float(np.mean(t2.delta_e00)),
        de00_max=float(np.max(t2.delta_e00)),
        spectral_rms_mean=float(np.mean(t2.spectral_rms)),
    )


def compare_charts(
    work_dir: str | PathLike[str],
    charts: Sequence[str] = ("colorchecker_24", "colorchecker_sg"),
    *,
    seed: int = 0,
    resolution: tuple[int, int] | None = None,
    progress: Callable[[float], None] | None = None,
) -> ChartComparison:
    """Score each of ``charts`` (keys of :data:`CHARTS`) on the same bench
    (simulated camera of ``resolution``, ``None``: its default)."""
    scores = []
    for k, key in enumerate(charts):
        scores.append(
            score_chart(key, Path(work_dir), seed=seed, resolution=resolution)
        )
        if progress is not None:
            progress((k + 1) / len(charts))
    _, card_refl = held_out_card()
    return ChartComparison(tuple(scores), n_held_out=len(card_refl), seed=seed)


def load_chart_comparison(path: str | PathLike[str]) -> dict[str, Any]:
    """A ``chart_choice.json`` as written by :meth:`ChartComparison.save`, checked."""
    from tunespec.core.limits import read_json

    d = read_json(Path(path))
    if not isinstance(d, dict) or d.get("format") != "tunespec-chart-choice":
        raise InputError("not a TuneSpec chart comparison", path=str(path))
    scores = d.get("scores")
    fields = set(ChartScore.__dataclass_fields__)
    if not isinstance(scores, list) or not all(
        isinstance(s, dict) and set(s) == fields for s in scores
    ):
        raise InputError(
            f"scores: expected objects with {sorted(fields)}", path=str(path)
        )
    return d
