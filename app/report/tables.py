"""The report's tables (:class:`_Table`: title, header, rows of text, note),
built from a :class:`~.data.ReportData`; the HTML and the PDF draw the same ones."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from tunespec.app.pipeline.record import (
    chart_reference,
    instrument_rows,
    software_versions,
)
from tunespec.app.report.data import (
    COLORIMETRY_DATA,
    PAPER_TABLE1,
    PAPER_TABLE2_AVERAGE,
    ReportData,
    _as_dict,
    _created_text,
    _self_check,
    _table1_parts,
    export_label,
    quality_flags,
    shipped_datasets,
)
from tunespec.core.intervals import COVERAGE_FACTOR_95
from tunespec.core.io.export import tunespec_version
from tunespec.core.plausibility import MAX_CHI2_PER_RESPONSE

if TYPE_CHECKING:
    from tunespec.core.colorimetry import ReflectanceStats
    from tunespec.core.stats import PredictionStats


@dataclass(frozen=True)
class _Table:
    title: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    note: str = ""


def _key_numbers(report: ReportData) -> _Table:
    """The summary's numbers beside the paper's."""
    rows: list[tuple[str, str, str]] = []
    fitted, held = _table1_parts(report)
    if fitted is not None:
        d = _as_dict(fitted)
        rows.append(
            (
                "Table 1 RGB mean error (full scale)",
                f"{d['RGB']['mean']:.4f}",
                f"{PAPER_TABLE1['RGB'][0]:.4f}",
            )
        )
        rows.append(
            (
                "Table 1 RGB max. error (full scale)",
                f"{d['RGB']['max']:.4f}",
                f"{PAPER_TABLE1['RGB'][1]:.4f}",
            )
        )
        rows.append(("Stimuli (patch x LED)", str(d["n_stimuli"]), "3080"))
    if held is not None:
        d = _as_dict(held)
        rows.append(("Held-aside RGB mean error", f"{d['RGB']['mean']:.4f}", "-"))
    checked = _self_check(report)
    if checked is not None and checked.get("held_out") is not None:
        h = checked["held_out"]
        rows.append(
            (
                f"Left-out patches' RGB mean error (1 in {h['every']}, self-check)",
                f"{h['prediction']['RGB']['mean']:.4f}",
                "-",
            )
        )
    if report.table2 is not None:
        d = _as_dict(report.table2)
        de, rms = PAPER_TABLE2_AVERAGE
        rows.append(
            (
                "Table 2 mean CIEDE2000 (D50)",
                f"{d['average']['delta_e00']:.2f}",
                f"{de:.2f}",
            )
        )
        rows.append(("Table 2 max. CIEDE2000", f"{d['max']['delta_e00']:.2f}", "-"))
        rows.append(
            (
                "Table 2 mean spectral RMS (reflectance factor)",
                f"{d['average']['spectral_rms']:.4f}",
                f"{rms:.4f}",
            )
        )
        rows.append(("Patches compared", str(len(d["patches"])), "8"))
    n_warn = sum(f.level == "warning" for f in quality_flags(report))
    rows.append(("Warnings", str(n_warn), "-"))
    return _Table(
        "Key numbers",
        ("Quantity", "This measurement", "Paper"),
        tuple(rows),
        "Paper: Trichromatic Reflectance Capture Using a Tunable Light Source, "
        "Table 1 (ColorChecker SG, 22 LEDs) and Table 2 (eight Neugebauer primaries).",
    )


def _worst_patches_table(report: ReportData, n: int = 10) -> _Table | None:
    errors = report.table1_patches
    if not errors:
        return None
    mean = sum(errors.values()) / len(errors) or 1.0
    worst = sorted(errors.items(), key=lambda kv: -kv[1])[:n]
    rows = tuple((name, f"{e:.4f}", f"{e / mean:.2f}") for name, e in worst)
    return _Table(
        f"Table 1: the {len(worst)} worst patches",
        ("Patch", "RGB error (mean over LEDs, full scale)", "x mean of all patches"),
        rows,
        "Per patch: the mean over its LEDs of the RMS over R, G, B of measured minus "
        f"predicted (Eq. 1), full-scale units; the last column is that error over "
        f"the mean of the {len(errors)} fitted patches ({mean:.4f}).",
    )


def _table1_patch_table(report: ReportData) -> _Table | None:
    """Every fitted patch's Table 1 error, three patches a row."""
    errors = report.table1_patches
    if not errors:
        return None
    return _Table(
        "Table 1 per patch (RGB error, mean over the LEDs, full scale)",
        ("Patch", "Error") * 3,
        # read across: a page break between rows keeps the order
        _side_by_side([(k, f"{v:.4f}") for k, v in errors.items()], down=False),
    )


def _record_table(report: ReportData) -> _Table | None:
    """The operator's record: who, what sample, which chart and its reference data,
    the room, the software; ``None`` without a record."""
    rec = report.record
    if rec is None:
        return None
    missing = "not recorded"
    layout = report.chart_layout
    chart = str(getattr(layout, "name", "") or "chart not named")
    rows = [
        ("Operator", rec.operator or missing),
        ("Sample ID", rec.sample_id or missing),
        ("Chart", f"{chart}, serial {rec.chart_serial or missing}"),
        ("Chart reference data", chart_reference(rec, layout)),
        (
            "Room temperature, light warm-up",
            f"{rec.temperature_c + ' °C' if rec.temperature_c else missing}, "
            f"{rec.warm_up_min + ' min' if rec.warm_up_min else missing}",
        ),
        (
            "Software",
            f"TuneSpec {tunespec_version()}; versions and settings under Provenance",
        ),
    ]
    if rec.notes:
        rows.append(("Notes", rec.notes))
    return _Table(
        "Measurement record",
        ("Item", "Value"),
        tuple(rows),
        "Filled by the operator: [provenance] of the run configuration, --operator, "
        "--sample-id ... on the command line, or Measurement record... in the GUI "
        "(record.json in the measurement folder).",
    )


def _instruments_table(report: ReportData) -> _Table | None:
    """Light source, spectroradiometer and camera with serials and calibration
    dates (the operator's, else the devices')."""
    if report.record is None:
        return None
    rows = tuple(
        (
            r["instrument"],
            r["model"],
            r["serial"] + (" (device)" if r["serial_source"] == "device" else ""),
            r["firmware"],
            r["calibration"],
        )
        for r in instrument_rows(report.record, report.devices)
    )
    return _Table(
        "Instruments",
        ("Instrument", "Model", "Serial", "Firmware", "Calibrated"),
        rows,
        "(device): the serial the device reported; the others the operator's.",
    )


def _side_by_side(
    pairs: Sequence[tuple[str, str]], per_row: int = 3, *, down: bool = True
) -> tuple[tuple[str, ...], ...]:
    """(name, value) pairs in ``per_row`` column pairs, read down, then across
    (``down``), or across, then down."""
    n_rows = math.ceil(len(pairs) / per_row)
    rows = []
    for r in range(n_rows):
        cells: list[str] = []
        for c in range(per_row):
            k = c * n_rows + r if down else r * per_row + c
            cells += list(pairs[k]) if k < len(pairs) else ["", ""]
        rows.append(tuple(cells))
    return tuple(rows)


def _table1(
    stats: PredictionStats | Mapping[str, Any], title: str, *, paper: bool
) -> _Table:
    d = _as_dict(stats)
    header = ("Channel", "Mean", "Maximum", "95th percentile")
    if paper:
        header += ("Paper mean", "Paper max.", "Paper 95th")
    rows = []
    for row in ("Red", "Green", "Blue", "RGB"):
        cells = [row, *(f"{d[row][k]:.4f}" for k in ("mean", "max", "p95"))]
        if paper:
            cells += [f"{v:.4f}" for v in PAPER_TABLE1[row]]
        rows.append(tuple(cells))
    note = (
        f"{d['n_stimuli']} stimuli (patch x LED); absolute error per channel and RMS "
        "over R, G, B, full-scale units."
    )
    if paper:
        note += " Paper: Table 1, 3080 stimuli."
    return _Table(title, header, tuple(rows), note)


def _lab_table(report: ReportData) -> _Table:
    """Each patch's CIELAB with its 95 % intervals and, where the estimate has
    them, how well its responses fit Eq. 1."""
    assert report.lab is not None and report.lab_std is not None
    assert report.reflectance is not None
    chi2 = report.chi2_per_response
    rows = tuple(
        (
            name,
            *(
                f"{report.lab[i, j]:.2f} ± {COVERAGE_FACTOR_95 * report.lab_std[i, j]:.2f}"
                for j in range(3)
            ),
            *(() if chi2 is None else (f"{chi2[i]:.2f}",)),
        )
        for i, name in enumerate(report.reflectance.names)
    )
    note = (
        "± is the expanded uncertainty (k = 1.96): sensor noise, the flat-field "
        "residual, the calibration (sensitivities and light-source corrections) and "
        "what the LEDs cannot resolve, propagated to first order."
    )
    if chi2 is not None:
        note += (
            " chi²: the patch's responses against Eq. 1 under that error model, per "
            f"response (about 1; above {MAX_CHI2_PER_RESPONSE:g} they fit no "
            "reflectance and the row does not hold)."
        )
    return _Table(
        "CIELAB (D50) with 95 % intervals",
        ("Patch", "L*", "a*", "b*", *(() if chi2 is None else ("chi² per response",))),
        rows,
        note=note,
    )


def _budget_table(budget: Mapping[str, Mapping[str, float]]) -> _Table:
    """The uncertainty budget: each term's share of u(L*)^2 and of u(reflectance)^2."""
    rows = tuple(
        (
            term,
            f"{100 * b['share_L']:.1f} %",
            f"{b['u_L_median']:.3f}",
            f"{100 * b['share_reflectance']:.1f} %",
        )
        for term, b in budget.items()
    )
    return _Table(
        "Uncertainty budget",
        (
            "Term",
            "Share of u(L*)²",
            "Median u(L*) alone (L* units)",
            "Share of u(reflectance)²",
        ),
        rows,
        note="Variances add: each share is the term's part of the summed variance "
        "over the sample's patches (and wavelengths). Prior mismatch: what the LEDs "
        "and the camera cannot resolve; systematic: the responses' errors beyond the "
        "noise that the calibration's residuals showed (stray light, cross-talk, "
        "non-linearity), part of them shared by a patch's responses under all LEDs.",
    )


def _table2(stats: ReflectanceStats | Mapping[str, Any]) -> _Table:
    d = _as_dict(stats)
    rows = [
        (name, f"{v['delta_e00']:.2f}", f"{v['spectral_rms']:.4f}")
        for name, v in d["patches"].items()
    ]
    rows.append(
        (
            "average",
            f"{d['average']['delta_e00']:.2f}",
            f"{d['average']['spectral_rms']:.4f}",
        )
    )
    rows.append(
        ("max", f"{d['max']['delta_e00']:.2f}", f"{d['max']['spectral_rms']:.4f}")
    )
    de, rms = PAPER_TABLE2_AVERAGE
    rows.append(("paper average", f"{de:.2f}", f"{rms:.4f}"))
    return _Table(
        "Table 2: reflectance accuracy",
        ("Patch", "CIEDE2000 [D50]", "Spectral RMS (reflectance factor)"),
        tuple(rows),
        "CIE 1931 2° observer, CIE D50, ASTM E308, ICC D50 white. Paper: Table 2, "
        "eight Neugebauer primaries of a 3D printer.",
    )


def _self_check_table(report: ReportData) -> _Table | None:
    """The calibration's self-check: each check, its value, its limit, its outcome."""
    checked = _self_check(report)
    if checked is None:
        return None
    rows: list[tuple[str, str, str, str]] = []

    def chi_row(label: str, chi: Mapping[str, Any]) -> tuple[str, str, str, str]:
        values = ", ".join(f"{c} {v:.2f}" for c, v in chi["reduced"].items())
        flagged = chi.get("flagged", [])
        return (
            label,
            f"{values} (1 ± {chi['spread']:.2f}, {chi['n_stimuli']} stimuli)",
            f"{chi['limit']:.2f}",
            f"over: {', '.join(flagged)}" if flagged else "ok",
        )

    rows.append(
        chi_row("Residuals / error model (fitted)", checked["residual_chi_square"])
    )
    held = checked.get("held_out")
    if held is not None:
        p, t = held["prediction"]["RGB"], held["training"]["RGB"]
        limit = report.threshold_rgb_mean
        rows.append(
            (
                f"Left-out patches (1 in {held['every']}, {len(held['patches'])}): "
                "RGB mean / max",
                f"{p['mean']:.4f} / {p['max']:.4f} (fitted {t['mean']:.4f} / "
                f"{t['max']:.4f})",
                "-" if limit is None else f"{limit:.4f}",
                "-" if limit is None else ("ok" if p["mean"] <= limit else "over"),
            )
        )
        rows.append(chi_row("Residuals / error model (left out)", held["chi_square"]))
    limits = checked.get("limits", {})
    if "systematic_relative" in limits:
        large = checked.get("large_systematic_terms", [])
        rows.append(
            (
                "Systematic errors fitted to the residuals",
                ", ".join(large) if large else "all within the limits",
                f"{100 * limits['systematic_relative']:.1f} %, gamma "
                f"{limits['nonlinearity']}",
                "over" if large else "ok",
            )
        )
    gamma = float(checked.get("linearity_gamma", 0.0))
    if gamma:
        rows.append(
            (
                "Sensor non-linearity, undone in every response",
                f"response^(1 + gamma), gamma {gamma:+.4f}",
                "-",
                "ok",
            )
        )
    noise = checked.get("meter_noise_fraction", {})
    if noise:
        name, worst = max(noise.items(), key=lambda kv: kv[1])
        lim = float(limits.get("meter_noise_fraction", float("nan")))
        rows.append(
            (
                "Light's reading noise (of the peak)",
                f"{100 * worst:.2f} % ({name})",
                f"{100 * lim:.1f} %",
                "ok" if worst <= lim else "over",
            )
        )
    leds = checked.get("implausible_leds", [])
    if "gain" in limits:
        rows.append(
            (
                "LED corrections (gain, offset)",
                f"implausible: {', '.join(leds)}" if leds else "all plausible",
                f"±{100 * limits['gain']:.0f} %, ±{limits['shift_nm']:.0f} nm",
                "over" if leds else "ok",
            )
        )
    return _Table(
        "Self-check of the calibration",
        ("Check", "Value", "Limit", "Outcome"),
        tuple(rows),
        note="Reduced chi-square: squared residuals over the variance the noise "
        "model predicts (ROI noise, flat-field residual; for left-out patches also "
        "the calibration's own), per degree of freedom; 1 if the model is right. "
        "Left out: a second calibration without those patches predicts them.",
    )


def _result_tables(report: ReportData) -> list[_Table]:
    tables = []
    fitted, held = _table1_parts(report)
    if fitted is not None:
        title = "Table 1: response prediction (fitted patches)"
        tables.append(_table1(fitted, title, paper=True))
    if held is not None:
        title = "Response prediction (held-aside patches)"
        tables.append(_table1(held, title, paper=False))
    tables += [
        t
        for t in (
            _self_check_table(report),
            _worst_patches_table(report),
            _table1_patch_table(report),
        )
        if t is not None
    ]
    if report.table2 is not None:
        tables.append(_table2(report.table2))
    if (
        report.lab is not None
        and report.lab_std is not None
        and report.reflectance is not None
    ):
        tables.append(_lab_table(report))
    if report.uncertainty_budget:
        tables.append(_budget_table(report.uncertainty_budget))
    corr = report.led_correction
    if corr is not None and corr.gain_std:
        rows = tuple(
            (
                name,
                f"{corr.gain[j]:.4f} ± {corr.gain_std[j]:.4f}",
                f"{corr.shift_nm[j]:+.2f} ± {corr.shift_std_nm[j]:.2f}",
            )
            for j, name in enumerate(corr.names)
        )
        tables.append(
            _Table(
                "Light source self-calibration (per LED)",
                ("LED", "Gain (true / reported)", "Wavelength offset (nm)"),
                rows,
                note="Fitted with the sensitivities, the chart's reflectances as the "
                "reference; applied to the sample's spectra. ± is one standard "
                f"uncertainty; common offset {corr.common_shift_nm:+.2f} nm.",
            )
        )
    if report.chart_choice is not None:  # the method's background: last
        tables.append(_chart_choice_table(report.chart_choice))
    return tables


def _chart_choice_table(choice: Mapping[str, Any]) -> _Table:
    """The chart comparison of :mod:`tunespec.app.pipeline.chart_choice`, side by side."""
    rows = tuple(
        (
            str(s["chart"]),
            str(s["n_patches"]),
            f"{s['table1_rgb_mean']:.5f}",
            f"{s['sensitivity_rms']:.4f}",
            f"{s['de00_mean']:.3f}",
            f"{s['de00_max']:.3f}",
            f"{s['spectral_rms_mean']:.4f}",
        )
        for s in choice["scores"]
    )
    return _Table(
        "Chart choice: calibrating on each chart (simulated bench)",
        (
            "Chart",
            "Patches",
            "Table 1 RGB mean",
            "Sensitivity RMS",
            "Mean ΔE00",
            "Max ΔE00",
            "Spectral RMS",
        ),
        rows,
        note="Each chart captured and calibrated on the same simulated bench (seed "
        f"{choice.get('seed', 0)}); Table 1 on the chart itself, sensitivity RMS "
        "against the bench's true curves (peak-normalised), Table 2 (D50) on "
        f"{choice.get('n_held_out', '?')} held-out reflectances no chart carries "
        f"({choice.get('held_out', '')}). {_chart_choice_reading(choice['scores'])} "
        "Made by app.pipeline.chart_choice (tunespec demo, benchmarks/chart_choice.py); "
        "one seed is one draw of noise and metering error, run the benchmark with "
        "several --seed values for the spread.",
    )


def _chart_choice_reading(scores: Sequence[Mapping[str, Any]]) -> str:
    """One sentence saying what the chart comparison shows, from its numbers."""
    if len(scores) < 2:
        return ""

    def span(key: str, fmt: str) -> str:
        lo = min(scores, key=lambda s: s[key])
        hi = max(scores, key=lambda s: s[key])
        return (
            f"{format(lo[key], fmt)} ({lo['chart']}) to {format(hi[key], fmt)} "
            f"({hi['chart']})"
        )

    return (
        f"Held-out mean ΔE00 ranges from {span('de00_mean', '.3f')}; the "
        f"sensitivity RMS from {span('sensitivity_rms', '.4f')}."
    )


#: What ``benchmarks/generalisation.py`` (seed 0) measured for the default calibration,
#: stated in every report that uses it; rerun the benchmark after changing the method.
VALIDATED_ACCURACY = (
    (
        "Cameras",
        "90 never tuned on (leave-one-source-out over rawtoaces-data, NPL, "
        "36 synthetic), 2 LED sets, per-LED metering error +-1 nm / 1 %",
    ),
    ("Test reflectances", "318, neither the chart nor the prior"),
    ("Mean CIEDE2000 (D50)", "0.067 (families 0.059-0.105; worst camera 0.19)"),
    ("Sensitivity RMS (median)", "0.009 of the peak"),
    (
        "95 % interval coverage",
        "reflectance 0.98, L* 0.92, a* 0.95, b* 0.95 (L* 0.88-0.95 per family)",
    ),
)


def _provenance_tables(report: ReportData) -> list[_Table]:
    tables = []
    if report.sensitivity_method == "bayes":
        tables.append(
            _Table(
                "Validated accuracy of the calibration method",
                ("Item", "Value"),
                VALIDATED_ACCURACY,
                note="python benchmarks/generalisation.py; docs/validation.md, 'Validated accuracy'.",
            )
        )
    summary = [("Created", _created_text(report.created))]
    if report.session_id:
        summary.append(("Session", report.session_id))
    summary.append(("TuneSpec", tunespec_version()))
    summary += [(str(k), str(v)) for k, v in report.provenance.items()]
    tables.append(_Table("Measurement", ("Item", "Value"), tuple(summary)))
    if report.exposures_s:
        tables.append(
            _Table(
                "Exposure per LED (s)",
                ("LED", "Exposure") * 3,
                _side_by_side([(k, f"{v:.2f}") for k, v in report.exposures_s.items()]),
                "Metered on the white board (or as set); the sample reuses the chart's.",
            )
        )
    if report.input_files:
        tables.append(
            _Table(
                "Input files",
                ("File", "SHA-256"),
                tuple((str(f), str(h)) for f, h in report.input_files),
                "A session manifest lists the SHA-256 of each of its raw frames.",
            )
        )
    if report.devices:
        rows = tuple(
            (role, key, str(value))
            for role, ident in report.devices.items()
            for key, value in ident.items()
        )
        tables.append(_Table("Devices", ("Device", "Property", "Value"), rows))
    if report.settings:
        rows = tuple((str(k), str(v)) for k, v in report.settings.items())
        tables.append(_Table("Settings", ("Setting", "Value"), rows))
    sw = tuple(software_versions().items())
    tables.append(_Table("Software", ("Component", "Version"), sw))
    datasets = report.datasets
    if datasets is None:
        datasets = [*shipped_datasets(), COLORIMETRY_DATA]
    if datasets:
        rows = tuple((d.name, d.description, d.licence) for d in datasets)
        tables.append(
            _Table("Data sets and licences", ("Data set", "What", "Licence"), rows)
        )
    if report.exports:
        rows = tuple((export_label(str(k)), str(v)) for k, v in report.exports.items())
        tables.append(_Table("Exported files", ("Export", "File"), rows))
    return tables
