"""The report's data: :class:`ReportData` (what a caller fills), the paper's
numbers, the quality flags and the verdict (:func:`verdict`).

Presentation-free: the
figures are in :mod:`.figures`, the tables in :mod:`.tables`, the HTML and PDF in
:mod:`.render`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from os import PathLike
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError
from tunespec.core.responses import Responses
from tunespec.core.spectra import Spectra
from tunespec.core.verdict import calibration_verdict, checked_self_check

if TYPE_CHECKING:
    from tunespec.core.colorimetry import ReflectanceStats
    from tunespec.core.stats import CalibrationReport, PredictionStats

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

#: The unit of the light source's spectra (the CAL1's, and the GUI's SPD plot).
RADIANCE_UNIT = "W sr⁻¹ m⁻² nm⁻¹"

#: Saturated stimuli listed one by one in the flags (the rest are counted).
MAX_LISTED = 12


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
    chi2_per_response : (n,)
        Each patch's responses against Eq. 1 (about 1; above
        :data:`tunespec.core.plausibility.MAX_CHI2_PER_RESPONSE` they fit no
        reflectance), a column of the CIELAB table.
    led_correction
        :class:`tunespec.core.led_correction.LedCorrection`: the light source's
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
    record
        The operator's :class:`~tunespec.app.pipeline.record.MeasurementRecord`
        (operator, sample ID, chart serial, instruments' serials and calibration
        dates): the first page's "Measurement record", with the ``devices``' serials
        where the operator gave none.
    illuminant_exposures_s
        The exposure (s) each of ``illuminants`` was measured for: given, the LED
        spectra are ``illuminants`` (radiance x exposure) over it, in
        :data:`RADIANCE_UNIT`; else ``illuminants`` as they are, in the units of
        their file.
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
    chi2_per_response: NDArray[np.float64] | None = None
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
    record: Any = None
    illuminant_exposures_s: Mapping[str, float] = field(default_factory=dict)


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
    """The report's self-check as the verdict reads it (:func:`checked_self_check`)."""
    return checked_self_check(report.self_check)


def verdict(report: ReportData) -> tuple[str, str] | None:
    """``(outcome, why)`` of :func:`tunespec.core.verdict.calibration_verdict` for
    the report's Table 1, threshold and self-check, or ``None`` without Table 1 or the
    threshold."""
    fitted, _ = _table1_parts(report)
    if fitted is None or report.threshold_rgb_mean is None:
        return None
    mean = float(_as_dict(fitted)["RGB"]["mean"])
    return calibration_verdict(mean, report.threshold_rgb_mean, report.self_check)


def _table1_parts(report: ReportData) -> tuple[Any, Any]:
    """(fitted, held-aside) Table 1 statistics; a ``CalibrationReport`` is unpacked."""
    t1, held = report.table1, report.table1_held_out
    d = t1 if isinstance(t1, Mapping) else None
    if d is not None and "training" in d:
        return d["training"], held if held is not None else d.get("held_out")
    if t1 is not None and hasattr(t1, "training"):  # core.stats.CalibrationReport
        return t1.training, held if held is not None else t1.held_out
    return t1, held


def led_radiance(report: ReportData) -> tuple[Spectra, str | None]:
    """The LED spectra as the report draws them, and their unit: spectral radiance
    (:data:`RADIANCE_UNIT`) when every LED's exposure is known
    (``illuminant_exposures_s``), else as given (unit ``None``)."""
    s = report.illuminants
    assert s is not None
    t = report.illuminant_exposures_s
    if not t or not all(t.get(n, 0.0) > 0 for n in s.names):
        return s, None
    per_s = np.array([1.0 / t[n] for n in s.names])
    return s.with_values(s.values * per_s[:, None]), RADIANCE_UNIT
