"""A measurement report people want to look at: one self-contained HTML file and a PDF.

:func:`write_report` renders a :class:`ReportData` (every field optional, so a caller
fills what it has) into ``report.html`` (CSS inline, plots embedded as base64 PNG, no
external assets, opens offline in any browser) and ``report.pdf`` (the same content
made with matplotlib's ``PdfPages``, every page A4 portrait, TrueType fonts embedded).

Contents, each shown when its data are given:

- a summary first: the verdict (Table 1's RGB mean against the threshold), the key
  numbers beside the paper's, every warning;
- provenance: TuneSpec version, creation time, session id, the measurement and
  session folders, the frames' fingerprints, seed and resolution of a simulated
  bench, the exposure per LED, every input file with its SHA-256, devices and serial
  numbers, settings, software versions, the exports (named for the reader), the data
  sets used and their licences (by default the shipped ones, from
  ``resources/SOURCE.md``, and colour-science's CIE data);
- quality flags: saturated stimuli (from :class:`~tunespec.core.responses.Responses`
  ``saturated``), patches excluded from the sensitivity fit, clipped Wiener estimates,
  reflectances outside 0..1, and the caller's own flags;
- the LED spectral power distributions;
- the estimated camera sensitivities, with the reference (the truth in a simulation)
  when known, both normalised to peak 1;
- a response map (peak channel per patch and LED, saturated cells marked);
- Table 1 per patch: a map of the chart, a histogram, the worst patches and a table;
  Table 2's CIEDE2000 histogram;
- estimated against reference reflectance per patch, a grid of small plots like the
  paper's Figure 6, each titled with its CIEDE2000;
- Table 1 (response prediction) and Table 2 (reflectance accuracy), next to the
  paper's values.

Plots are drawn on :class:`matplotlib.figure.Figure` objects with the Agg canvas,
never through ``pyplot``, so the global backend (Qt in the GUI) is left alone; core
imports no Qt.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
Tables 1 and 2, Figures 2, 5 and 6.
"""

from __future__ import annotations

import base64
import html
import io
import math
import platform
import re
import textwrap
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure
from numpy.typing import NDArray

from tunespec.core.errors import InputError
from tunespec.core.io.export import tunespec_version
from tunespec.core.responses import Responses
from tunespec.core.spectra import Spectra

if TYPE_CHECKING:
    from tunespec.core.colorimetry import ReflectanceStats
    from tunespec.core.stats import CalibrationReport, PredictionStats

__all__ = [
    "COLORIMETRY_DATA",
    "PAPER_TABLE1",
    "PAPER_TABLE2_AVERAGE",
    "DatasetInfo",
    "Flag",
    "ReportData",
    "quality_flags",
    "render_html",
    "report_figures",
    "shipped_datasets",
    "write_report",
]

#: The paper's Table 1 (3080 stimuli): row -> (mean, max, p95), full-scale units.
PAPER_TABLE1: dict[str, tuple[float, float, float]] = {
    "Red": (0.0026, 0.0326, 0.0108),
    "Green": (0.0024, 0.0332, 0.0112),
    "Blue": (0.0021, 0.0252, 0.0097),
    "RGB": (0.0024, 0.0305, 0.0106),
}
#: The paper's Table 2 average over the eight Neugebauer primaries: (CIEDE2000 D50,
#: spectral RMS).
PAPER_TABLE2_AVERAGE: tuple[float, float] = (0.67, 0.0286)

#: Patches per page of the Figure 6 grid (4 columns x 6 rows on A4 portrait).
PATCHES_PER_FIGURE = 24
_GRID_COLS = 4
#: Saturated stimuli listed one by one in the flags (the rest are counted).
MAX_LISTED = 12

_A4_LANDSCAPE_IN = (11.69, 8.27)
_A4_PORTRAIT_IN = (8.27, 11.69)
_CHANNEL_COLOURS = {"R": "#d62728", "G": "#2ca02c", "B": "#1f77b4"}


@dataclass(frozen=True)
class DatasetInfo:
    """A data set used by the measurement and its licence.

    Parameters
    ----------
    name
        Short name or folder, e.g. ``"charts/"``.
    description
        What it is and where it comes from.
    licence
        Its licence, e.g. ``"MIT"``.
    """

    name: str
    description: str
    licence: str


#: Data every report uses that is not in ``tunespec.resources``: the colorimetry of
#: Table 2, the swatches and the ``.ti3`` XYZ/L*a*b*.
COLORIMETRY_DATA = DatasetInfo(
    "colour-science",
    "CIE 1931 2° colour-matching functions and CIE illuminant D50 (colorimetry)",
    "BSD-3-Clause",
)


@dataclass(frozen=True)
class Flag:
    """A quality flag: ``level`` is ``"warning"`` or ``"info"``."""

    level: str
    text: str


@dataclass(frozen=True, kw_only=True)
class ReportData:
    """Everything a report can show; every field is optional.

    Parameters
    ----------
    title
        Heading of the report.
    created
        When the measurement was made; ``None`` is the time of writing (UTC).
    session_id
        The session's identifier (``core.io.session``).
    devices
        Device role to identity, e.g. ``{"camera": {"model": "Canon EOS 5D Mark III",
        "serial": "0123"}, "light source": {...}}``.
    settings
        Free-form settings shown as a table (grid, method, exposure ...).
    illuminants : Spectra (n_i, n_wl)
        LED spectral power distributions.
    sensitivity : Spectra R, G, B
        Estimated camera sensitivities.
    sensitivity_reference : Spectra R, G, B
        Reference sensitivities (the truth of a simulation, or a database curve).
    sensitivity_reference_label
        Legend label of the reference.
    sensitivity_method
        Name of the estimation method.
    reflectance : Spectra (n, n_wl)
        Estimated reflectances.
    reflectance_reference : Spectra
        Reference reflectances (e.g. spectroradiometer), matched by name.
    table1 : PredictionStats
        Response prediction statistics (Table 1).
    table1_held_out : PredictionStats
        The same on patches held aside from the fit.
    table2 : ReflectanceStats
        Reflectance accuracy (Table 2).
    responses : Responses
        Camera responses: the response map and the saturation flags.
    excluded_patches
        Patches the sensitivity fit left out (saturated).
    clipped_patches
        Patches whose Wiener estimate was clipped to 0..1.
    flags
        More flags, as text (warnings) or :class:`Flag`.
    datasets
        Data sets and licences; ``None`` lists the shipped ones and
        :data:`COLORIMETRY_DATA`.
    exports
        Export kind to file; relative paths are linked from the HTML.
    notes
        Free text shown under the summary.
    sensitivity_std : (3, n_wl)
        Standard uncertainty of ``sensitivity`` (same units); drawn as a 95 % band.
    reflectance_std : (n, n_wl)
        Standard uncertainty of ``reflectance``; drawn as a 95 % band.
    lab, lab_std : (n, 3)
        CIELAB (D50) of ``reflectance`` and its standard uncertainty (a table).
    led_correction
        :class:`tunespec.core.sensitivity_bayes.LedCorrection`: the light source's
        per-LED corrections found by the calibration (a table).
    uncertainty_budget
        :func:`tunespec.core.uncertainty.budget_summary`: each term's share of the
        variance of L* and of the reflectances (a table).
    threshold_rgb_mean
        Pass/fail limit on Table 1's RGB mean (full scale): the summary's verdict.
    self_check
        The calibration's self-check (:class:`tunespec.core.selfcheck.SelfCheck` or
        its ``as_dict()``): the verdict's further conditions and a table.
    table1_patches
        Table 1's RGB error per fitted patch (mean over the LEDs): the map of the
        chart, the histogram, the worst patches and the per-patch table.
    chart_choice
        :meth:`~tunespec.app.pipeline.chart_choice.ChartComparison.to_dict` (or its
        ``chart_choice.json``): the "Chart choice" section, charts side by side.
    chart_layout
        The chart's :class:`~tunespec.core.layout.TargetLayout` (for the map).
    provenance
        More provenance, label -> text (seed, resolution, folders, sessions).
    exposures_s
        Exposure per LED (s).
    input_files
        (file, SHA-256) of every file the measurement read.
    """

    title: str = "TuneSpec measurement report"
    created: datetime | str | None = None
    session_id: str | None = None
    devices: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    settings: Mapping[str, str] = field(default_factory=dict)
    illuminants: Spectra | None = None
    sensitivity: Spectra | None = None
    sensitivity_reference: Spectra | None = None
    sensitivity_std: NDArray[np.float64] | None = None
    reflectance_std: NDArray[np.float64] | None = None
    lab: NDArray[np.float64] | None = None
    lab_std: NDArray[np.float64] | None = None
    led_correction: Any = None
    uncertainty_budget: Mapping[str, Mapping[str, float]] | None = None
    sensitivity_reference_label: str = "reference"
    sensitivity_method: str | None = None
    reflectance: Spectra | None = None
    reflectance_reference: Spectra | None = None
    table1: PredictionStats | CalibrationReport | Mapping[str, Any] | None = None
    table1_held_out: PredictionStats | Mapping[str, Any] | None = None
    table2: ReflectanceStats | Mapping[str, Any] | None = None
    responses: Responses | None = None
    excluded_patches: Sequence[str] = ()
    clipped_patches: Sequence[str] = ()
    flags: Sequence[str | Flag] = ()
    datasets: Sequence[DatasetInfo] | None = None
    exports: Mapping[str, str | PathLike[str]] = field(default_factory=dict)
    notes: str = ""
    threshold_rgb_mean: float | None = None
    self_check: Any = None
    table1_patches: Mapping[str, float] | None = None
    chart_layout: Any = None
    chart_choice: Mapping[str, Any] | None = None
    provenance: Mapping[str, str] = field(default_factory=dict)
    exposures_s: Mapping[str, float] = field(default_factory=dict)
    input_files: Sequence[tuple[str, str]] = ()


def shipped_datasets() -> list[DatasetInfo]:
    """The data sets shipped in ``tunespec.resources``, from its ``SOURCE.md`` table.

    Returns
    -------
    list of DatasetInfo
        One per table row (folder, what, licence); empty if the file is missing.
    """
    from tunespec.core.datasets import resource_path

    try:
        text = resource_path("SOURCE.md").read_text(encoding="utf-8")
    except (InputError, OSError):
        return []
    out = []
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or not line.lstrip().startswith("|"):
            continue
        if cells[0] in ("folder", "") or set(cells[0]) <= set("-: "):
            continue
        # Markdown emphasis and code marks are for the file, not the report.
        name, what, licence = (re.sub(r"[`*]", "", c) for c in cells)
        out.append(DatasetInfo(name, what, licence))
    return out


def _software_versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"TuneSpec": tunespec_version(), "Python": platform.python_version()}
    for dist, label in (
        ("numpy", "NumPy"),
        ("scipy", "SciPy"),
        ("colour-science", "colour-science"),
        ("matplotlib", "Matplotlib"),
    ):
        try:
            out[label] = version(dist)
        except PackageNotFoundError:
            out[label] = "not installed"
    out["Platform"] = platform.platform(terse=True)
    return out


def _created_text(created: datetime | str | None) -> str:
    if created is None:
        created = datetime.now(UTC).replace(microsecond=0)
    if isinstance(created, datetime):
        return created.isoformat()
    return str(created)


def quality_flags(report: ReportData) -> list[Flag]:
    """The flags the report shows, warnings first.

    Parameters
    ----------
    report
        The report data.

    Returns
    -------
    list of Flag
        Saturation (each stimulus with clipped ROI pixels, the first
        :data:`MAX_LISTED` by name, then a count), excluded and clipped patches,
        reflectances outside 0..1, the caller's flags; an ``info`` flag saying so when
        nothing is saturated.

    Examples
    --------
    >>> import numpy as np
    >>> r = Responses(("A1",), ("LED450",), np.zeros((1, 1, 3)),
    ...               saturated=np.array([[0.25]]))
    >>> [f.text for f in quality_flags(ReportData(responses=r))]
    ['1 of 1 stimuli have saturated pixels (max 25.0 % of the ROI): A1 under LED450 (25.0 %)']
    """
    flags: list[Flag] = []
    r = report.responses
    if r is not None and r.saturated is not None:
        sat = np.nan_to_num(r.saturated, nan=0.0)
        hits = np.argwhere(sat > 0)
        if hits.size:
            order = sorted(hits.tolist(), key=lambda pi: -sat[pi[0], pi[1]])
            listed = ", ".join(
                f"{r.patches[p]} under {r.illuminants[i]} ({100 * sat[p, i]:.1f} %)"
                for p, i in order[:MAX_LISTED]
            )
            more = len(order) - MAX_LISTED
            flags.append(
                Flag(
                    "warning",
                    f"{len(order)} of {sat.size} stimuli have saturated pixels (max "
                    f"{100 * sat.max():.1f} % of the ROI): {listed}"
                    + (f" and {more} more" if more > 0 else ""),
                )
            )
        else:
            flags.append(Flag("info", f"no saturated pixels in {sat.size} stimuli"))
    if report.excluded_patches:
        flags.append(
            Flag(
                "warning",
                f"{len(report.excluded_patches)} patch(es) excluded from the "
                f"sensitivity fit (saturated): {', '.join(report.excluded_patches)}",
            )
        )
    if report.clipped_patches:
        flags.append(
            Flag(
                "warning",
                f"{len(report.clipped_patches)} reflectance estimate(s) clipped to "
                f"0..1: {', '.join(report.clipped_patches)}",
            )
        )
    if report.reflectance is not None:
        v = report.reflectance.values
        bad = [
            n
            for n, row in zip(report.reflectance.names, v, strict=True)
            if np.any(row < 0) or np.any(row > 1)
        ]
        if bad:
            flags.append(
                Flag(
                    "warning",
                    f"{len(bad)} estimated reflectance(s) outside 0..1 "
                    f"(min {v.min():.3f}, max {v.max():.3f}): {', '.join(bad[:20])}",
                )
            )
    for f in report.flags:
        flags.append(f if isinstance(f, Flag) else Flag("warning", str(f)))
    flags.sort(key=lambda f: f.level != "warning")
    return flags


def _as_dict(stats: Any) -> dict[str, Any]:
    """``stats.as_dict()``, or ``stats`` itself if it is already a mapping."""
    return dict(stats) if isinstance(stats, Mapping) else stats.as_dict()


#: What each export is, in the reader's words (the report shows no internal keys).
EXPORT_LABELS: dict[str, str] = {
    "chart_responses_csv": "Chart: camera responses under every LED",
    "chart_illuminants_csv": "Chart: LED spectra x exposure",
    "sensitivities_csv": "Camera sensitivities",
    "sensitivities_meta": "Sensitivities: covariance and LED corrections",
    "sensitivities_json": "Camera sensitivities (rawtoaces JSON)",
    "sensitivities_json_meta": "Sensitivities (rawtoaces JSON): covariance, LED fit",
    "reflectances_csv": "Estimated reflectances",
    "reflectances_ti3": "Estimated reflectances (ArgyllCMS .ti3)",
    "reflectances_uncertainty_csv": "Standard uncertainty of the reflectances",
    "colorimetry_csv": "CIE XYZ and CIELAB (D50) with uncertainties",
    "reference_csv": "Reference reflectances",
    "reference_ti3": "Reference reflectances (ArgyllCMS .ti3)",
    "responses_csv": "Sample: camera responses",
    "illuminants_csv": "Sample: LED spectra x exposure",
    "table1_csv": "Table 1: response prediction",
    "table2_csv": "Table 2: reflectance accuracy",
    "chart_camera_ti3": "Chart: camera RGB and XYZ for ArgyllCMS colprof (.ti3)",
    "camera_transforms_json": "Camera transforms: ACES IDT and CCMs (JSON)",
    "camera_transforms_csv": "Camera transforms: ACES IDT and CCMs (CSV)",
    "summary_json": "Summary of the numbers (JSON)",
    "report_html": "This report (HTML)",
    "report_pdf": "This report (PDF)",
}


def export_label(key: str) -> str:
    """The reader's name of an export kind (a key the table does not know is
    turned into words)."""
    if key in EXPORT_LABELS:
        return EXPORT_LABELS[key]
    words = key.replace("_", " ").strip()
    for ext in ("csv", "json", "ti3", "pdf", "html"):
        if words.endswith(f" {ext}"):
            words = f"{words[: -len(ext) - 1]} ({ext.upper()})"
    return words[:1].upper() + words[1:]


def _self_check(report: ReportData) -> dict[str, Any] | None:
    """The self-check's ``as_dict()`` form, or ``None`` (also for a document that
    lacks its residual check: a ``calibration.json`` edited by hand)."""
    c = report.self_check
    if c is None:
        return None
    d = dict(c) if isinstance(c, Mapping) else c.as_dict()
    return d if isinstance(d.get("residual_chi_square"), Mapping) else None


def _self_check_findings(checked: Mapping[str, Any]) -> list[str]:
    """Each check that flagged, in a few words (the warnings say more)."""

    def chi(d: Mapping[str, Any]) -> str:
        values = ", ".join(f"{c} {d['reduced'][c]:.1f}" for c in d["flagged"])
        return f"reduced chi-square {values} over {d['limit']:.1f}"

    out = []
    fitted = checked["residual_chi_square"]
    if fitted.get("flagged"):
        out.append(f"calibration residuals beyond the noise model ({chi(fitted)})")
    held = checked.get("held_out")
    if held is None:
        out.append("no prediction of left-out patches was made")
    elif held["chi_square"].get("flagged"):
        out.append(
            f"left-out patches' residuals beyond the noise model ({chi(held['chi_square'])})"
        )
    if checked.get("implausible_leds"):
        out.append(
            f"implausible LED corrections ({', '.join(checked['implausible_leds'])})"
        )
    limit = checked.get("limits", {}).get("meter_noise_fraction")
    noise = checked.get("meter_noise_fraction", {})
    if limit is not None and noise and max(noise.values()) > limit:
        out.append(
            f"noisy light readings ({100 * max(noise.values()):.2f} % of the peak)"
        )
    named = len(out) - (held is None)  # the findings of the checks listed here
    if checked.get("warnings") and not named:
        out += [str(w) for w in checked["warnings"]]  # a check this list lacks
    return out


#: The verdict's three outcomes.
VERDICTS = ("PASS", "PASS with warnings", "FAIL")


def verdict(report: ReportData) -> tuple[str, str] | None:
    """``(outcome, why)``, ``outcome`` one of :data:`VERDICTS`, or ``None`` without
    Table 1 or the threshold.

    Without a self-check: ``PASS`` or ``FAIL`` from Table 1's RGB mean against the
    threshold. With one (:mod:`tunespec.core.selfcheck`), ``PASS`` needs Table 1
    *and* the prediction of the patches a second calibration left out within the
    threshold, *and* no finding of the self-check (residuals against the noise
    model, the LED corrections, the light's reading noise); a prediction over the
    threshold fails, a finding gives ``PASS with warnings``, naming each check.
    """
    fitted, _ = _table1_parts(report)
    if fitted is None or report.threshold_rgb_mean is None:
        return None
    limit = report.threshold_rgb_mean
    mean = float(_as_dict(fitted)["RGB"]["mean"])
    ok = mean <= limit
    checked = _self_check(report)
    if checked is None:
        why = (
            f"Table 1 RGB mean error {mean:.4f} of full scale is "
            f"{'within' if ok else 'over'} the threshold {limit:.4f}"
        )
        return ("PASS" if ok else "FAIL"), why
    over = [] if ok else [f"Table 1 RGB mean error {mean:.4f}"]
    within = [f"Table 1 RGB mean error {mean:.4f}"] if ok else []
    findings = _self_check_findings(checked)
    held = checked.get("held_out")
    if held is not None:
        held_mean = float(held["prediction"]["RGB"]["mean"])
        text = f"left-out patches' (1 in {held['every']}) RGB mean {held_mean:.4f}"
        (within if held_mean <= limit else over).append(text)
    if over:
        why = f"{' and '.join(over)} over the threshold {limit:.4f}"
        if findings:
            why += f"; self-check: {'; '.join(findings)}"
        return "FAIL", why
    why = f"{' and '.join(within)} within the threshold {limit:.4f}"
    if findings:
        return "PASS with warnings", f"{why}; but: {'; '.join(findings)}"
    chi = checked["residual_chi_square"]["reduced"]
    why += (
        "; residuals consistent with the noise model (reduced chi-square "
        + ", ".join(f"{c} {v:.2f}" for c, v in chi.items())
        + "), light-source corrections and readings plausible"
    )
    return "PASS", why


def _verdict_colours(outcome: str) -> tuple[str, str, str]:
    """(background, edge, text) colours of a verdict."""
    if outcome == "PASS":
        return "#e8f4ea", "#3c9a4f", "#2d7a3d"
    if outcome == "FAIL":
        return "#fde8e8", "#c00000", "#c00000"
    return "#fff3cd", "#e0a800", "#8a5a00"


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
                "Table 2 mean spectral RMS",
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
    paper = PAPER_TABLE1["RGB"][0]
    worst = sorted(errors.items(), key=lambda kv: -kv[1])[:n]
    rows = tuple((name, f"{e:.4f}", f"{e / paper:.1f}") for name, e in worst)
    return _Table(
        f"Table 1: the {len(worst)} worst patches",
        ("Patch", "RGB error (mean over LEDs)", "x paper mean"),
        rows,
        "Per patch: the mean over its LEDs of the RMS over R, G, B of measured minus "
        "predicted (Eq. 1); full-scale units.",
    )


def _table1_patch_table(report: ReportData) -> _Table | None:
    """Every fitted patch's Table 1 error, three patches a row."""
    errors = report.table1_patches
    if not errors:
        return None
    return _Table(
        "Table 1 per patch (RGB error, mean over the LEDs, full scale)",
        ("Patch", "Error") * 3,
        _side_by_side([(k, f"{v:.4f}") for k, v in errors.items()]),
    )


def _side_by_side(
    pairs: Sequence[tuple[str, str]], per_row: int = 3
) -> tuple[tuple[str, ...], ...]:
    """(name, value) pairs in ``per_row`` column pairs, read down, then across."""
    n_rows = math.ceil(len(pairs) / per_row)
    rows = []
    for r in range(n_rows):
        cells: list[str] = []
        for c in range(per_row):
            k = c * n_rows + r
            cells += list(pairs[k]) if k < len(pairs) else ["", ""]
        rows.append(tuple(cells))
    return tuple(rows)


# --------------------------------------------------------------------------- plots


def _new_figure(
    size_in: tuple[float, float],
    *,
    margins_in: tuple[float, float, float, float] | None,
) -> Figure:
    """An Agg-backed figure; ``margins_in`` = (left, right, bottom, top) in inches.

    Fixed margins instead of constrained layout, which costs about 0.1 s per axes
    and draw (the report draws every figure twice, PNG and PDF).
    """
    fig = Figure(figsize=size_in)
    FigureCanvasAgg(fig)
    if margins_in is not None:
        w, h = size_in
        left, right, bottom, top = margins_in
        fig.subplots_adjust(
            left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h
        )
    return fig


def _wavelength_colour(wavelength_nm: float) -> tuple[float, float, float]:
    """An approximate display colour for a narrowband peak (for plot lines)."""
    from matplotlib import colormaps

    t = (wavelength_nm - 400.0) / (700.0 - 400.0)
    r, g, b, _ = colormaps["nipy_spectral"](0.05 + 0.85 * min(1.0, max(0.0, t)))
    return (r, g, b)


def _page(title: str) -> Figure:
    """An A4 portrait page with its title: every page of the report has this size."""
    fig = _new_figure(_A4_PORTRAIT_IN, margins_in=None)
    fig.text(0.08, 0.965, title, fontsize=13, weight="bold", va="top")
    return fig


def _axes_in(fig: Figure, left: float, bottom: float, width: float, height: float):
    """Axes at a rectangle given in inches from the page's lower left corner."""
    w, h = fig.get_size_inches()
    return fig.add_axes((left / w, bottom / h, width / w, height / h))


def _draw_spd(ax: Any, illuminants: Spectra) -> None:
    wl = illuminants.wavelength_nm
    n_broad = 0
    for name, v in zip(illuminants.names, illuminants.values, strict=True):
        peak = float(wl[int(np.argmax(v))])
        total = float(np.sum(v))
        near = float(np.sum(v[np.abs(wl - peak) <= 30.0]))
        # Narrowband LEDs keep most of their power within 30 nm of the peak;
        # phosphor whites do not and are drawn grey, with a line style each.
        style = "-"
        if total > 0 and near > 0.7 * total:
            colour: Any = _wavelength_colour(peak)
        else:
            colour, style = "0.35", ("-", "--", ":", "-.")[n_broad % 4]
            n_broad += 1
        ax.plot(wl, v, color=colour, ls=style, lw=1.0, label=name)
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("relative spectral power")
    ax.set_title(f"LED spectral power distributions ({len(illuminants)} channels)")
    ax.set_xlim(wl[0], wl[-1])
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    # under the plot, inside the page: no curve is covered
    ax.legend(
        ncol=6,
        fontsize=6.5,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.13),
        frameon=False,
    )


def _peak_normalised(s: Spectra) -> NDArray[np.float64]:
    peak = float(np.max(s.values))
    return s.values / peak if peak > 0 else s.values


def _draw_sensitivity(ax: Any, report: ReportData) -> None:
    est = report.sensitivity
    assert est is not None
    ref = report.sensitivity_reference
    peak = float(np.max(est.values)) or 1.0
    for k, (name, v) in enumerate(zip(est.names, _peak_normalised(est), strict=True)):
        c = _CHANNEL_COLOURS.get(name)
        ax.plot(est.wavelength_nm, v, color=c, lw=1.6, label=f"{name} estimated")
        if report.sensitivity_std is not None:
            u = 1.96 * report.sensitivity_std[k] / peak
            ax.fill_between(est.wavelength_nm, v - u, v + u, color=c, alpha=0.25, lw=0)
    if ref is not None:
        for name, v in zip(ref.names, _peak_normalised(ref), strict=True):
            c = _CHANNEL_COLOURS.get(name)
            label = f"{name} {report.sensitivity_reference_label}"
            ax.plot(ref.wavelength_nm, v, color=c, lw=1.0, ls="--", label=label)
    method = f" ({report.sensitivity_method})" if report.sensitivity_method else ""
    band = ", 95 % bands" if report.sensitivity_std is not None else ""
    ax.set_title(f"Camera sensitivities{method}, normalised to peak 1{band}")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("relative sensitivity")
    ax.set_xlim(est.wavelength_nm[0], est.wavelength_nm[-1])
    ax.grid(alpha=0.3)
    ax.legend(
        ncol=3,
        fontsize=7,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.13),
        frameon=False,
    )


def _light_camera_figure(report: ReportData) -> Figure:
    """Page: the LED spectra above the camera sensitivities."""
    fig = _page("Light source and camera")
    if report.illuminants is not None:
        _draw_spd(_axes_in(fig, 0.9, 7.1, 6.9, 3.6), report.illuminants)
    if report.sensitivity is not None:
        _draw_sensitivity(_axes_in(fig, 0.9, 1.3, 6.9, 4.0), report)
    return fig


def _response_map_figure(responses: Responses) -> Figure:
    n_p, n_i = len(responses.patches), len(responses.illuminants)
    longest = max(len(n) for n in responses.illuminants)
    fig = _page("Camera responses")
    bottom = 0.8 + 0.07 * longest
    ax = _axes_in(fig, 0.9, bottom, 6.0, 10.3 - bottom)
    peak = responses.rgb.max(axis=2)
    title = "Largest channel response per patch and LED (full scale = 1)"
    vmax = max(1.0, float(peak.max()))
    im = ax.imshow(peak, aspect="auto", cmap="viridis", vmin=0.0, vmax=vmax)
    if responses.saturated is not None:
        pi = np.argwhere(np.nan_to_num(responses.saturated) > 0)
        if pi.size:
            ax.scatter(pi[:, 1], pi[:, 0], marker="x", color="red", s=18)
            title += "; x = saturated pixels"
    ax.set_xticks(range(n_i), responses.illuminants, rotation=90, fontsize=7)
    step = max(1, math.ceil(n_p / 70))
    ax.set_yticks(range(0, n_p, step), responses.patches[::step], fontsize=6)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("LED")
    ax.set_ylabel("patch")
    bar = fig.colorbar(im, cax=_axes_in(fig, 7.05, bottom, 0.18, 10.3 - bottom))
    bar.set_label("response (full scale = 1)")
    return fig


def _chart_map(
    ax: Any, fig: Figure, report: ReportData, errors: Mapping[str, float]
) -> bool:
    """Table 1's error of every patch where it sits on the chart; False if the
    layout does not name the patches."""
    layout = report.chart_layout
    names = tuple(getattr(layout, "patch_names", ()))
    if not names or not set(errors) & set(names):
        return False
    rows, cols = int(layout.rows), int(layout.cols)
    names = names[: rows * cols]  # the main grid (extra grids are other panels)
    grid = np.full((rows, cols), np.nan)
    for k, name in enumerate(names):
        if name in errors:
            grid[k // cols, k % cols] = errors[name]
    top = float(np.nanmax(grid)) or 1.0
    im = ax.imshow(grid, cmap="magma_r", vmin=0.0, vmax=top, aspect="equal")
    for k, name in enumerate(names):
        r, c = divmod(k, cols)
        dark = name in errors and errors[name] > 0.55 * top
        text = name if name in errors else f"{name}\nleft out"
        ax.text(
            c,
            r,
            text,
            ha="center",
            va="center",
            fontsize=5,
            color="white" if dark else "0.15",
        )
    ax.set_xticks([])  # the patches are named in their cells
    ax.set_yticks([])
    ax.set_title("Table 1 RGB error per patch, on the chart", fontsize=10)
    bar = fig.colorbar(im, ax=ax, shrink=0.85, pad=0.02)
    bar.set_label("RGB error (full scale)", fontsize=8)
    return True


def _histogram(
    ax: Any, values: Any, *, mean_label: str, paper: float, xlabel: str
) -> None:
    values = np.asarray(values, dtype=np.float64)
    bins = max(5, min(30, int(math.sqrt(values.size) * 2)))
    ax.hist(values, bins=bins, color="0.6", edgecolor="0.3", lw=0.5)
    ax.axvline(float(np.mean(values)), color="tab:blue", lw=1.5, label=mean_label)
    ax.axvline(paper, color="tab:red", lw=1.2, ls="--", label=f"paper mean {paper:g}")
    from matplotlib.ticker import MaxNLocator

    ax.set_xlabel(xlabel)
    ax.set_ylabel("patches")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")


def _patch_errors_figure(report: ReportData) -> Figure | None:
    """Page: Table 1 per patch (map of the chart, histogram), Table 2's CIEDE2000
    histogram."""
    errors = report.table1_patches or {}
    t2 = None if report.table2 is None else _as_dict(report.table2)
    if not errors and t2 is None:
        return None
    fig = _page("Errors per patch")
    if errors:
        _chart_map(_axes_in(fig, 0.8, 6.9, 6.6, 3.9), fig, report, errors)
        values = list(errors.values())
        _histogram(
            _axes_in(fig, 0.9, 4.0, 6.6, 2.2),
            values,
            mean_label=f"mean {np.mean(values):.4f}",
            paper=PAPER_TABLE1["RGB"][0],
            xlabel="Table 1 RGB error per patch (full scale)",
        )
    if t2 is not None:
        de = [v["delta_e00"] for v in t2["patches"].values()]
        _histogram(
            _axes_in(fig, 0.9, 0.8, 6.6, 2.2),
            de,
            mean_label=f"mean {np.mean(de):.2f}",
            paper=PAPER_TABLE2_AVERAGE[0],
            xlabel="Table 2 CIEDE2000 (D50) per patch",
        )
    return fig


def _display_colours(report: ReportData) -> dict[str, NDArray[np.float64]]:
    """sRGB display colour (D50 adapted to D65, clipped) per patch, reference first."""
    import colour

    from tunespec.core.colorimetry import ICC_D50_XY, xyz_d50

    out: dict[str, NDArray[np.float64]] = {}
    for spectra in (report.reflectance, report.reflectance_reference):
        if spectra is None:
            continue
        try:
            xyz = xyz_d50(spectra) / 100.0
        except InputError:  # a grid too short for colorimetry: no swatches
            continue
        with colour.utilities.domain_range_scale("reference"):
            rgb = colour.XYZ_to_sRGB(
                xyz, illuminant=ICC_D50_XY, chromatic_adaptation_transform="Bradford"
            )
        rgb = np.clip(np.nan_to_num(np.asarray(rgb, dtype=np.float64)), 0.0, 1.0)
        out.update(zip(spectra.names, rgb, strict=True))
    return out


@dataclass
class _Grid:
    """What the cells of the reflectance pages share, and what they collect."""

    report: ReportData
    de: dict[str, float]
    swatches: dict[str, NDArray[np.float64]]
    y_top: float
    est_lines: list[Any] = field(default_factory=list)
    ref_lines: list[Any] = field(default_factory=list)
    bands: list[Any] = field(default_factory=list)
    frames: list[Any] = field(default_factory=list)
    grid: list[Any] = field(default_factory=list)

    @property
    def wl(self) -> NDArray[np.float64]:
        assert self.report.reflectance is not None
        return self.report.reflectance.wavelength_nm

    @property
    def span(self) -> float:
        return float(self.wl[-1] - self.wl[0]) or 1.0


#: Cell gaps of the reflectance pages, in cell units (room for tick labels, titles).
_GAP_X, _GAP_Y = 0.30, 0.62


def _grid_cell(ax: Any, g: _Grid, i: int, x0: float, y0: float) -> None:
    """One patch: estimate, band, reference, frame, tick labels, title, swatch."""
    from matplotlib.patches import Rectangle

    est, ref, report = g.report.reflectance, g.report.reflectance_reference, g.report
    assert est is not None
    wl, span, y_top = g.wl, g.span, g.y_top
    name = est.names[i]
    x = x0 + (wl - wl[0]) / span
    g.est_lines.append(np.column_stack([x, y0 + est.values[i] / y_top]))
    if report.reflectance_std is not None:
        u = 1.96 * report.reflectance_std[i]
        lo = np.clip(est.values[i] - u, 0.0, y_top) / y_top
        hi = np.clip(est.values[i] + u, 0.0, y_top) / y_top
        g.bands.append(
            np.concatenate(
                [np.column_stack([x, y0 + lo]), np.column_stack([x, y0 + hi])[::-1]]
            )
        )
    if ref is not None and name in ref.names:
        xr = x0 + (ref.wavelength_nm - wl[0]) / span
        keep = (xr >= x0 - 1e-9) & (xr <= x0 + 1 + 1e-9)
        g.ref_lines.append(np.column_stack([xr[keep], y0 + ref[name][keep] / y_top]))
    g.frames.append([(x0, y0), (x0 + 1, y0), (x0 + 1, y0 + 1), (x0, y0 + 1), (x0, y0)])
    ticks_nm = [t for t in (400.0, 500.0, 600.0, 700.0) if wl[0] <= t <= wl[-1]]
    for t in ticks_nm:
        gx = x0 + (t - wl[0]) / span
        g.grid.append([(gx, y0), (gx, y0 + 1)])
        ax.text(gx, y0 - 0.03, f"{t:g}", fontsize=5, ha="center", va="top", color="0.3")
    for v in (0.0, 0.5, 1.0):
        if v <= y_top:
            g.grid.append([(x0, y0 + v / y_top), (x0 + 1, y0 + v / y_top)])
            ax.text(
                x0 - 0.03,
                y0 + v / y_top,
                f"{v:g}",
                fontsize=5,
                ha="right",
                va="center",
                color="0.3",
            )
    if name in g.swatches:
        ax.add_patch(
            Rectangle(
                (x0 + 0.82, y0 + 1.04),
                0.18,
                0.2,
                facecolor=tuple(g.swatches[name]),
                edgecolor="0.3",
                lw=0.4,
            )
        )
    title = name if name not in g.de else f"{name}   ΔE00 {g.de[name]:.2f}"
    ax.text(x0, y0 + 1.04, title, fontsize=6.5, va="bottom", ha="left")


def _grid_draw(ax: Any, g: _Grid) -> list[Any]:
    """The collected lines as collections; returns the legend's handles."""
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    ax.add_collection(LineCollection(g.grid, colors="0.88", linewidths=0.5))
    ax.add_collection(LineCollection(g.frames, colors="0.55", linewidths=0.6))
    handles: list[Any] = [Line2D([], [], color="black", lw=1.1, label="estimated")]
    if g.bands:
        ax.add_collection(
            PolyCollection(g.bands, facecolors="0.55", edgecolors="none", alpha=0.35)
        )
        handles.append(
            Rectangle((0, 0), 1, 1, facecolor="0.55", alpha=0.35, label="95 % interval")
        )
    ax.add_collection(LineCollection(g.est_lines, colors="black", linewidths=1.1))
    if g.ref_lines:
        ax.add_collection(
            LineCollection(
                g.ref_lines, colors="tab:red", linewidths=0.9, linestyles="--"
            )
        )
        handles.append(
            Line2D([], [], color="tab:red", lw=0.9, ls="--", label="reference")
        )
    return handles


def _patch_grid_figures(report: ReportData) -> Iterator[tuple[str, Figure]]:
    """Estimated vs. reference reflectance of every patch (paper's Figure 6), on A4
    portrait pages of :data:`PATCHES_PER_FIGURE`, each cell with its tick labels.

    All cells of a page are drawn on one axes in cell units with line collections:
    matplotlib needs about 25 ms per axes, so a 140-patch chart drawn as subplots
    took seconds per page; this takes a fraction of a second.
    """
    est = report.reflectance
    assert est is not None
    ref = report.reflectance_reference
    t2 = None if report.table2 is None else _as_dict(report.table2)
    y_top = max(1.0, float(np.max(est.values)))
    if ref is not None:
        y_top = max(y_top, float(np.max(ref.values)))
    g0 = _Grid(
        report,
        {} if t2 is None else {k: v["delta_e00"] for k, v in t2["patches"].items()},
        _display_colours(report),
        y_top,
    )
    names = est.names
    cols, rows = _GRID_COLS, PATCHES_PER_FIGURE // _GRID_COLS
    n_fig = math.ceil(len(names) / PATCHES_PER_FIGURE)
    what = (
        "Estimated vs. reference reflectance"
        if ref is not None
        else "Estimated reflectance"
    )
    for k in range(n_fig):
        g = replace(g0, est_lines=[], ref_lines=[], bands=[], frames=[], grid=[])
        part = f" ({k + 1}/{n_fig})" if n_fig > 1 else ""
        fig = _page(f"{what}{part}")
        ax = _axes_in(fig, 0.55, 0.85, 7.35, 9.85)
        ax.set_axis_off()
        first = k * PATCHES_PER_FIGURE
        for pos, i in enumerate(
            range(first, min(len(names), first + PATCHES_PER_FIGURE))
        ):
            r, c = divmod(pos, cols)
            _grid_cell(ax, g, i, c * (1 + _GAP_X), (rows - 1 - r) * (1 + _GAP_Y))
        handles = _grid_draw(ax, g)
        ax.set_xlim(-_GAP_X + 0.05, cols * (1 + _GAP_X) - _GAP_X + 0.02)
        ax.set_ylim(-0.25, rows * (1 + _GAP_Y) - _GAP_Y + 0.3)
        fig.legend(
            handles=handles,
            loc="upper right",
            bbox_to_anchor=(0.95, 0.975),
            fontsize=8,
            frameon=False,
            ncol=3,
        )
        wl = g.wl
        fig.text(
            0.08,
            0.035,
            f"Each cell: wavelength {wl[0]:g}-{wl[-1]:g} nm across, reflectance factor "
            f"0-{y_top:.2g} up. Swatch: sRGB of the estimate under D50. "
            "Compare the paper's Figure 6.",
            fontsize=7,
            color="0.3",
        )
        yield f"reflectance_grid_{k + 1}", fig


def report_figures(report: ReportData) -> list[tuple[str, Figure]]:
    """The report's figures (name, Agg-backed A4 portrait Figure), in report order."""
    figs: list[tuple[str, Figure]] = []
    if report.illuminants is not None or report.sensitivity is not None:
        figs.append(("light_camera", _light_camera_figure(report)))
    errors = _patch_errors_figure(report)
    if errors is not None:
        figs.append(("patch_errors", errors))
    if report.responses is not None:
        figs.append(("response_map", _response_map_figure(report.responses)))
    if report.reflectance is not None:
        figs.extend(_patch_grid_figures(report))
    return figs


# -------------------------------------------------------------------------- tables


@dataclass(frozen=True)
class _Table:
    title: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    note: str = ""


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
        ("Term", "Share of u(L*)²", "Median u(L*) alone", "Share of u(reflectance)²"),
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
        ("Patch", "CIEDE2000 [D50]", "Spectral RMS"),
        tuple(rows),
        "CIE 1931 2° observer, CIE D50, ASTM E308, ICC D50 white. Paper: Table 2, "
        "eight Neugebauer primaries of a 3D printer.",
    )


def _table1_parts(report: ReportData) -> tuple[Any, Any]:
    """(fitted, held-aside) Table 1 statistics; a ``CalibrationReport`` is unpacked."""
    t1, held = report.table1, report.table1_held_out
    d = t1 if isinstance(t1, Mapping) else None
    if d is not None and "training" in d:
        return d["training"], held if held is not None else d.get("held_out")
    if t1 is not None and hasattr(t1, "training"):  # core.stats.CalibrationReport
        return t1.training, held if held is not None else t1.held_out
    return t1, held


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
        chi_row("Residuals / noise model (fitted)", checked["residual_chi_square"])
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
        rows.append(chi_row("Residuals / noise model (left out)", held["chi_square"]))
    limits = checked.get("limits", {})
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
    if report.chart_choice is not None:
        tables.append(_chart_choice_table(report.chart_choice))
    if (
        report.lab is not None
        and report.lab_std is not None
        and report.reflectance is not None
    ):
        rows = tuple(
            (
                name,
                *(
                    f"{report.lab[i, j]:.2f} ± {1.96 * report.lab_std[i, j]:.2f}"
                    for j in range(3)
                ),
            )
            for i, name in enumerate(report.reflectance.names)
        )
        tables.append(
            _Table(
                "CIELAB (D50) with 95 % intervals",
                ("Patch", "L*", "a*", "b*"),
                rows,
                note="± is the expanded uncertainty (k = 1.96): sensor noise, the "
                "flat-field residual, the calibration (sensitivities and light-source "
                "corrections) and what the LEDs cannot resolve, propagated to first order.",
            )
        )
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
    sw = tuple(_software_versions().items())
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


# ---------------------------------------------------------------------------- HTML

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif;
       margin: 2em auto; max-width: 1100px; color: #222; line-height: 1.4; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; padding-bottom: 0.2em;
     margin-top: 2em; }
.meta { color: #555; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
th { background: #f2f2f2; }
tr.summary td { font-weight: 600; background: #fafafa; }
.flags { list-style: none; padding-left: 0; }
.flags li { margin: 0.3em 0; padding: 0.4em 0.7em; border-radius: 4px; }
.flags li.warning { background: #fff3cd; border-left: 4px solid #e0a800; }
.flags li.info { background: #e8f4ea; border-left: 4px solid #3c9a4f; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
.note { color: #555; font-size: 0.85em; }
footer { margin-top: 3em; color: #777; font-size: 0.8em; }
"""

#: Cells aligned right: decimal numbers (statistics), not serials or identifiers.
_NUMERIC_CELL = re.compile(r"^[+-]?\d*\.\d+$")


def _png_base64(fig: Figure, dpi: int = 110) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None})
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _html_table(t: _Table, *, summary_rows: Sequence[str] = ()) -> str:
    e = html.escape
    out = [f"<h3>{e(t.title)}</h3>" if t.title else "", "<table>", "<thead><tr>"]
    out += [f"<th>{e(h)}</th>" for h in t.header]
    out.append("</tr></thead><tbody>")
    for row in t.rows:
        cls = ' class="summary"' if row and row[0] in summary_rows else ""
        cells = "".join(
            f'<td class="num">{e(c)}</td>'
            if _NUMERIC_CELL.match(c)
            else f"<td>{e(c)}</td>"
            for c in row
        )
        out.append(f"<tr{cls}>{cells}</tr>")
    out.append("</tbody></table>")
    if t.note:
        out.append(f'<p class="note">{e(t.note)}</p>')
    return "\n".join(out)


def _html_summary(report: ReportData, flags: Sequence[Flag]) -> list[str]:
    """Verdict, key numbers against the paper's, the warnings and notes."""
    e = html.escape
    parts = ["<h2>Summary</h2>"]
    v = verdict(report)
    if v is not None:
        background, edge, _ = _verdict_colours(v[0])
        colour = f"{background}; border-left: 6px solid {edge}"
        parts.append(
            f'<p class="verdict" style="background: {colour}; padding: 0.6em 1em; '
            f'font-size: 1.15em"><b>{e(v[0])}</b>: {e(v[1])}.</p>'
        )
    parts.append(_html_table(_key_numbers(report)))
    if report.notes:
        parts.append(f"<p>{e(report.notes)}</p>")
    parts.append("<h3>Warnings and checks</h3>")
    if flags:
        parts.append('<ul class="flags">')
        parts += [f'<li class="{e(f.level)}">{e(f.text)}</li>' for f in flags]
        parts.append("</ul>")
    else:
        parts.append('<p class="note">No data to check (no responses given).</p>')
    return parts


def _html_link(path: str) -> str:
    e = html.escape
    if Path(path).is_absolute():
        return e(path)
    return f'<a href="{e(path, quote=True)}">{e(path)}</a>'


def render_html(
    report: ReportData, figures: Sequence[tuple[str, Figure]] | None = None
) -> str:
    """The report as one self-contained HTML page (figures as base64 PNG).

    Parameters
    ----------
    report
        What to show.
    figures
        Pre-rendered :func:`report_figures` (to share them with the PDF); ``None``
        renders them.
    """
    e = html.escape
    figs = report_figures(report) if figures is None else figures
    flags = quality_flags(report)
    created = _created_text(report.created)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f'<meta name="generator" content="TuneSpec {e(tunespec_version())}">',
        f"<title>{e(report.title)}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>{e(report.title)}</h1>",
        f'<p class="meta">{e(created)}'
        + (f" · session {e(report.session_id)}" if report.session_id else "")
        + f" · TuneSpec {e(tunespec_version())}</p>",
    ]
    parts += _html_summary(report, flags)
    captions = {
        "light_camera": "LED spectral power distributions (the light source's "
        "spectroradiometer) and the estimated camera sensitivities"
        + (
            f" (solid) with {report.sensitivity_reference_label} (dashed)"
            if report.sensitivity_reference is not None
            else ""
        )
        + ", each set normalised to its peak.",
        "patch_errors": "Table 1's RGB error of every fitted patch where it sits on "
        "the chart, its histogram, and Table 2's CIEDE2000 per patch.",
        "response_map": "Largest of the R, G, B responses per patch (rows) and LED "
        "(columns); crosses mark stimuli with saturated pixels.",
    }
    tables = _result_tables(report)
    sections = [
        ("Light source and camera", ["light_camera"]),
        ("Errors per patch", ["patch_errors"]),
        ("Camera responses", ["response_map"]),
    ]
    by_name = dict(figs)
    for heading, names in sections:
        present = [n for n in names if n in by_name]
        if not present:
            continue
        parts.append(f"<h2>{e(heading)}</h2>")
        for n in present:
            parts.append(
                f'<figure><img alt="{e(n)}" src="data:image/png;base64,'
                f'{_png_base64(by_name[n])}"><figcaption class="note">'
                f"{e(captions[n])}</figcaption></figure>"
            )
    if tables:
        parts.append("<h2>Results</h2>")
        for t in tables:
            parts.append(
                _html_table(t, summary_rows=("average", "max", "paper average"))
            )
    grids = [(n, f) for n, f in figs if n.startswith("reflectance_grid")]
    if grids:
        parts.append("<h2>Reflectances</h2>")
        for n, f in grids:
            parts.append(
                f'<figure><img alt="{e(n)}" src="data:image/png;base64,'
                f'{_png_base64(f)}"></figure>'
            )
        parts.append(
            '<p class="note">Solid: estimated (Wiener) with its 95 % interval; dashed: '
            "reference. Swatches: sRGB rendering under D50. Compare the paper's "
            "Figure 6.</p>"
        )
    parts.append("<h2>Provenance</h2>")
    for t in _provenance_tables(report):
        if t.title == "Exported files":
            rows = "".join(
                f"<tr><td>{e(k)}</td><td>{_html_link(v)}</td></tr>" for k, v in t.rows
            )
            parts.append(
                f"<h3>{e(t.title)}</h3><table><thead><tr><th>Export</th><th>File</th>"
                f"</tr></thead><tbody>{rows}</tbody></table>"
            )
        else:
            parts.append(_html_table(t))
    parts.append(
        f"<footer>Generated by TuneSpec {e(tunespec_version())}. Method: "
        "Trichromatic Reflectance Capture Using a Tunable Light Source.</footer>"
    )
    parts.append("</body></html>")
    return "\n".join(p for p in parts if p) + "\n"


# ----------------------------------------------------------------------------- PDF

_LINES_PER_PAGE = 84
#: Marks a table's title among the lines of a flowed page.
_TITLE_MARK = "\x00"
_WRAP = 110


def _text_table(t: _Table) -> list[str]:
    widths = [
        max(len(h), *(len(r[j]) for r in t.rows)) if t.rows else len(h)
        for j, h in enumerate(t.header)
    ]
    widths = [min(w, 48) for w in widths]

    def fmt(cells: Sequence[str]) -> list[str]:
        # A long cell (a data set's description, a path) wraps onto more lines
        # rather than losing its end: provenance must be complete on paper too.
        wrapped = [
            textwrap.wrap(c, w, break_on_hyphens=False) or [""]
            for c, w in zip(cells, widths, strict=True)
        ]
        out = []
        for k in range(max(len(c) for c in wrapped)):
            parts = []
            for c, w in zip(wrapped, widths, strict=True):
                c = c[k] if k < len(c) else ""
                parts.append(c.rjust(w) if _NUMERIC_CELL.match(c) else c.ljust(w))
            out.append("  ".join(parts).rstrip())
        return out

    lines = [t.title, "", *fmt(t.header), *fmt(["-" * w for w in widths])]
    for r in t.rows:
        lines += fmt(r)
    if t.note:
        lines += ["", *textwrap.wrap(t.note, _WRAP)]
    return [*lines, ""]


def _summary_page(report: ReportData) -> Figure:
    """Page 1: what was measured, the verdict, the key numbers, the warnings."""
    fig = _page(report.title)
    meta = f"Created {_created_text(report.created)} · TuneSpec {tunespec_version()}"
    if report.session_id:
        meta += f" · session {report.session_id}"
    fig.text(0.08, 0.935, meta, fontsize=8.5, color="0.3", va="top")
    y = 0.90
    v = verdict(report)
    if v is not None:
        from matplotlib.patches import FancyBboxPatch

        background, edge, ink = _verdict_colours(v[0])
        lines = textwrap.wrap(v[1] + ".", 80)
        height = max(0.045, 0.0135 * len(lines) + 0.012)
        fig.patches.append(
            FancyBboxPatch(
                (0.08, y - height),
                0.84,
                height,
                boxstyle="round,pad=0.004",
                transform=fig.transFigure,
                facecolor=background,
                edgecolor=edge,
                lw=1.2,
            )
        )
        fig.text(
            0.1,
            y - height / 2,
            "\n".join(textwrap.wrap(v[0], 10)),
            fontsize=16 if v[0] != "PASS with warnings" else 11,
            weight="bold",
            va="center",
            color=ink,
        )
        fig.text(0.22, y - height / 2, "\n".join(lines), fontsize=9, va="center")
        y -= height + 0.025
    y = _draw_key_numbers(fig, y, _key_numbers(report))
    if report.notes:
        notes = textwrap.wrap(report.notes, 100)
        fig.text(0.08, y, "\n".join(notes), fontsize=8.5, va="top")
        y -= 0.014 * len(notes) + 0.01
    fig.text(0.08, y, "Warnings and checks", fontsize=11, weight="bold", va="top")
    y -= 0.025
    for f in quality_flags(report):
        wrapped = textwrap.wrap(f.text, 105)
        if y - 0.0135 * len(wrapped) < 0.04:
            fig.text(0.08, y, "… (all in the HTML report)", fontsize=8, va="top")
            break
        mark = "⚠" if f.level == "warning" else "✓"
        colour = "#8a5a00" if f.level == "warning" else "#2d7a3d"
        fig.text(0.08, y, mark, fontsize=9, va="top", color=colour)
        fig.text(0.105, y, "\n".join(wrapped), fontsize=8, va="top")
        y -= 0.0135 * len(wrapped) + 0.006
    return fig


def _draw_key_numbers(fig: Figure, y: float, t: _Table) -> float:
    """The key numbers as a table in the page's font; returns the y below it."""
    from matplotlib.lines import Line2D

    fig.text(0.08, y, t.title, fontsize=11, weight="bold", va="top")
    y -= 0.028
    xs = (0.08, 0.62, 0.80)
    step = 0.019
    for j, h in enumerate(t.header):
        fig.text(xs[j], y, h, fontsize=9, weight="bold", va="top", ha="left")
    y -= step
    fig.add_artist(Line2D([0.08, 0.92], [y + 0.004, y + 0.004], color="0.6", lw=0.6))
    for row in t.rows:
        for j, cell in enumerate(row):
            fig.text(xs[j], y - 0.003, cell, fontsize=9, va="top")
        y -= step
    note = textwrap.wrap(t.note, 110)
    fig.text(0.08, y - 0.006, "\n".join(note), fontsize=7.5, color="0.35", va="top")
    return y - 0.013 * len(note) - 0.03


def _flow_pages(title: str, tables: Sequence[_Table]) -> Iterator[Figure]:
    """Tables flowed onto A4 pages: a table that fits on a page is not split, a
    longer one is split between rows, its header repeated."""
    pages: list[list[str]] = [[]]
    for t in tables:
        lines = _text_table(t)
        lines[0] = _TITLE_MARK + lines[0]  # drawn as a heading
        room = _LINES_PER_PAGE - len(pages[-1])
        if len(lines) > room and len(lines) <= _LINES_PER_PAGE:
            pages.append([])
        elif len(lines) > _LINES_PER_PAGE:
            head, body = lines[:4], lines[4:]
            while body:
                room = _LINES_PER_PAGE - len(pages[-1]) - len(head)
                if room < 8:
                    pages.append([])
                    continue
                pages[-1] += head + body[:room]
                body = body[room:]
                if body:
                    pages.append([])
            continue
        pages[-1] += lines
    pages = [p for p in pages if p]
    line_h = 7.2 * 1.18 / 72 / _A4_PORTRAIT_IN[1]  # figure units per line
    for k, lines in enumerate(pages):
        head = title if len(pages) <= 1 else f"{title} ({k + 1}/{len(pages)})"
        fig = _page(head)
        y, run = 0.93, []
        for line in [*lines, _TITLE_MARK]:  # the sentinel flushes the last run
            if not line.startswith(_TITLE_MARK):
                run.append(line)
                continue
            if run:
                fig.text(
                    0.08, y, "\n".join(run), fontsize=7.2, family="monospace", va="top"
                )
                y -= line_h * len(run)
                run = []
            if line != _TITLE_MARK:
                y -= 0.3 * line_h  # a little air above a heading
                fig.text(0.08, y, line[1:], fontsize=9, weight="bold", va="top")
                y -= line_h
        yield fig


def _write_pdf(
    path: Path, report: ReportData, figures: Sequence[tuple[str, Figure]]
) -> None:
    """Every page A4 portrait: summary, figures, results, provenance."""
    meta: dict[str, Any] = {
        "Title": report.title,
        "Creator": f"TuneSpec {tunespec_version()}",
    }
    if isinstance(report.created, datetime):
        meta["CreationDate"] = report.created
    from matplotlib import rc_context

    from tunespec.core.atomic import atomic_open

    # TrueType fonts embedded (not Type 3): sharp in print, text searchable
    with (
        atomic_open(path, "wb") as fh,
        rc_context({"pdf.fonttype": 42}),
        PdfPages(fh, metadata=meta) as pdf,
    ):
        pdf.savefig(_summary_page(report))
        for _, fig in figures:
            pdf.savefig(fig)
        for fig in _flow_pages("Results", _result_tables(report)):
            pdf.savefig(fig)
        for fig in _flow_pages("Provenance", _provenance_tables(report)):
            pdf.savefig(fig)


def write_report(
    out_dir: str | PathLike[str], report: ReportData, *, stem: str = "report"
) -> tuple[Path, Path]:
    """Write ``<stem>.html`` and ``<stem>.pdf`` of ``report`` into ``out_dir``.

    Parameters
    ----------
    out_dir
        Folder, created if needed. Relative export paths in ``report.exports`` are
        linked relative to it.
    report
        What to show; see :class:`ReportData`.
    stem
        File name without extension.

    Returns
    -------
    (html_path, pdf_path)

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     h, p = write_report(d, ReportData(title="Empty", created="2026-01-01"))
    ...     h.name, p.name, p.read_bytes()[:5], "data:" in h.read_text()
    ('report.html', 'report.pdf', b'%PDF-', False)
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if report.created is None:  # one timestamp for the HTML and the PDF
        report = replace(report, created=datetime.now(UTC).replace(microsecond=0))
    figures = report_figures(report)
    html_path = out / f"{stem}.html"
    pdf_path = out / f"{stem}.pdf"
    from tunespec.core.atomic import atomic_write_text

    atomic_write_text(html_path, render_html(report, figures))
    _write_pdf(pdf_path, report, figures)
    return html_path, pdf_path
