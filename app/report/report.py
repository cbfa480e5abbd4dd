"""A measurement report people want to look at: one self-contained HTML file and a PDF.

:func:`write_report` renders a :class:`ReportData` (every field optional, so a caller
fills what it has) into ``report.html`` (CSS inline, plots embedded as base64 PNG, no
external assets, opens offline in any browser) and ``report.pdf`` (a multi-page PDF of
the same content made with matplotlib's ``PdfPages``, no extra packages).

Contents, each shown when its data are given:

- summary and provenance: TuneSpec version, creation time, session id, devices and
  serial numbers, settings, software versions, the data sets used and their licences
  (by default the shipped ones, from ``resources/SOURCE.md``, and colour-science's CIE
  data);
- quality flags: saturated stimuli (from :class:`~tunespec.core.responses.Responses`
  ``saturated``), patches excluded from the sensitivity fit, clipped Wiener estimates,
  reflectances outside 0..1, and the caller's own flags;
- the LED spectral power distributions;
- the estimated camera sensitivities, with the reference (the truth in a simulation)
  when known, both normalised to peak 1;
- a response map (peak channel per patch and LED, saturated cells marked);
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

#: Patches per page of the Figure 6 grid.
PATCHES_PER_FIGURE = 70
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


def _spd_figure(illuminants: Spectra) -> Figure:
    fig = _new_figure((_A4_LANDSCAPE_IN[0], 5.0), margins_in=(0.8, 2.2, 0.6, 0.4))
    ax = fig.add_subplot()
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
        ax.plot(wl, v, color=colour, ls=style, lw=1.2, label=name)
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("relative spectral power")
    ax.set_title(f"LED spectral power distributions ({len(illuminants)} channels)")
    ax.set_xlim(wl[0], wl[-1])
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(
        ncol=2 if len(illuminants) > 12 else 1,
        fontsize=7,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        frameon=False,
    )
    return fig


def _peak_normalised(s: Spectra) -> NDArray[np.float64]:
    peak = float(np.max(s.values))
    return s.values / peak if peak > 0 else s.values


def _sensitivity_figure(report: ReportData) -> Figure:
    est = report.sensitivity
    assert est is not None
    fig = _new_figure((_A4_LANDSCAPE_IN[0], 5.0), margins_in=(0.8, 1.7, 0.6, 0.4))
    ax = fig.add_subplot()
    ref = report.sensitivity_reference
    peak = float(np.max(est.values)) or 1.0
    for k, (name, v) in enumerate(zip(est.names, _peak_normalised(est), strict=True)):
        c = _CHANNEL_COLOURS.get(name)
        ax.plot(est.wavelength_nm, v, color=c, lw=1.8, label=f"{name} estimated")
        if report.sensitivity_std is not None:
            u = 1.96 * report.sensitivity_std[k] / peak
            ax.fill_between(est.wavelength_nm, v - u, v + u, color=c, alpha=0.25, lw=0)
    if ref is not None:
        for name, v in zip(ref.names, _peak_normalised(ref), strict=True):
            c = _CHANNEL_COLOURS.get(name)
            label = f"{name} {report.sensitivity_reference_label}"
            ax.plot(ref.wavelength_nm, v, color=c, lw=1.2, ls="--", label=label)
    method = f" ({report.sensitivity_method})" if report.sensitivity_method else ""
    band = ", 95 % bands" if report.sensitivity_std is not None else ""
    ax.set_title(f"Estimated camera sensitivities{method}, normalised to peak 1{band}")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("relative sensitivity")
    ax.set_xlim(est.wavelength_nm[0], est.wavelength_nm[-1])
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    return fig


def _response_map_figure(responses: Responses) -> Figure:
    n_p, n_i = len(responses.patches), len(responses.illuminants)
    longest = max(len(n) for n in responses.illuminants)
    fig = _new_figure(
        (_A4_LANDSCAPE_IN[0], min(8.0, 2.5 + 0.06 * n_p)),
        margins_in=(0.9, 0.9, 0.6 + 0.07 * longest, 0.4),
    )
    ax = fig.add_subplot()
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
    step = max(1, math.ceil(n_p / 40))
    ax.set_yticks(range(0, n_p, step), responses.patches[::step], fontsize=7)
    ax.set_title(title)
    ax.set_xlabel("LED")
    ax.set_ylabel("patch")
    bar = fig.colorbar(im, ax=ax, shrink=0.8, pad=0.01)
    bar.set_label("response (full scale = 1)")
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


def _patch_grid_figures(report: ReportData) -> Iterator[tuple[str, Figure]]:
    """Small multiples of estimated vs. reference reflectance (paper's Figure 6).

    All cells of a page are drawn on one axes in cell units with line collections:
    matplotlib needs about 25 ms per axes, so a 140-patch chart drawn as subplots
    took seconds per page; this takes a fraction of a second.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle

    est = report.reflectance
    assert est is not None
    ref = report.reflectance_reference
    t2 = None if report.table2 is None else _as_dict(report.table2)
    de = {} if t2 is None else {k: v["delta_e00"] for k, v in t2["patches"].items()}
    swatches = _display_colours(report)
    names = est.names
    y_top = max(1.0, float(np.max(est.values)))
    if ref is not None:
        y_top = max(y_top, float(np.max(ref.values)))
    wl = est.wavelength_nm
    span = float(wl[-1] - wl[0]) or 1.0
    gap_x, gap_y = 0.10, 0.32
    n_fig = math.ceil(len(names) / PATCHES_PER_FIGURE)
    for k in range(n_fig):
        chunk = list(
            range(k * PATCHES_PER_FIGURE, min(len(names), (k + 1) * PATCHES_PER_FIGURE))
        )
        n = len(chunk)
        cols = min(10, max(2, math.ceil(math.sqrt(n * 1.6))))
        rows = math.ceil(n / cols)
        # Cells about 1.4 times as wide as high, the page at most A4 landscape.
        cell_w_in = 0.955 * _A4_LANDSCAPE_IN[0] / (cols * (1 + gap_x))
        height = min(_A4_LANDSCAPE_IN[1], 1.3 + rows * (1 + gap_y) * cell_w_in / 1.4)
        fig = _new_figure((_A4_LANDSCAPE_IN[0], height), margins_in=None)
        ax = fig.add_axes((0.035, 0.55 / height, 0.955, 1 - 1.15 / height))
        ax.set_axis_off()
        est_lines, ref_lines, frames, grid, bands = [], [], [], [], []
        for pos, i in enumerate(chunk):
            r, c = divmod(pos, cols)
            x0, y0 = c * (1 + gap_x), (rows - 1 - r) * (1 + gap_y)
            x = x0 + (wl - wl[0]) / span
            name = names[i]
            est_lines.append(np.column_stack([x, y0 + est.values[i] / y_top]))
            if report.reflectance_std is not None:
                u = 1.96 * report.reflectance_std[i]
                lo = np.clip(est.values[i] - u, 0.0, y_top) / y_top
                hi = np.clip(est.values[i] + u, 0.0, y_top) / y_top
                bands.append(
                    np.concatenate(
                        [
                            np.column_stack([x, y0 + lo]),
                            np.column_stack([x, y0 + hi])[::-1],
                        ]
                    )
                )
            if ref is not None and name in ref.names:
                xr = x0 + (ref.wavelength_nm - wl[0]) / span
                keep = (xr >= x0 - 1e-9) & (xr <= x0 + 1 + 1e-9)
                ref_lines.append(
                    np.column_stack([xr[keep], y0 + ref[name][keep] / y_top])
                )
            frames.append(
                [(x0, y0), (x0 + 1, y0), (x0 + 1, y0 + 1), (x0, y0 + 1), (x0, y0)]
            )
            grid.append([(x0, y0 + 0.5 / y_top), (x0 + 1, y0 + 0.5 / y_top)])
            for g in (500.0, 600.0):
                if wl[0] < g < wl[-1]:
                    gx = x0 + (g - wl[0]) / span
                    grid.append([(gx, y0), (gx, y0 + 1)])
            if name in swatches:
                ax.add_patch(
                    Rectangle(
                        (x0 + 0.86, y0 + 1.03),
                        0.14,
                        0.22,
                        facecolor=tuple(swatches[name]),
                        edgecolor="0.3",
                        lw=0.4,
                    )
                )
            title = name if name not in de else f"{name}  ΔE00 {de[name]:.2f}"
            ax.text(x0, y0 + 1.03, title, fontsize=6.5, va="bottom", ha="left")
        ax.add_collection(LineCollection(grid, colors="0.88", linewidths=0.5))
        ax.add_collection(LineCollection(frames, colors="0.55", linewidths=0.6))
        if bands:
            from matplotlib.collections import PolyCollection

            ax.add_collection(
                PolyCollection(bands, facecolors="0.55", edgecolors="none", alpha=0.35)
            )
        ax.add_collection(LineCollection(est_lines, colors="black", linewidths=1.1))
        if ref_lines:
            ax.add_collection(
                LineCollection(
                    ref_lines, colors="tab:red", linewidths=0.9, linestyles="--"
                )
            )
        ax.set_xlim(-0.02, cols * (1 + gap_x) - gap_x + 0.02)
        ax.set_ylim(-0.04, rows * (1 + gap_y) - gap_y + 0.22)
        handles = [Line2D([], [], color="black", lw=1.1, label="estimated")]
        if bands:
            handles.append(
                Rectangle(
                    (0, 0), 1, 1, facecolor="0.55", alpha=0.35, label="95 % interval"
                )
            )
        if ref_lines:
            handles.append(
                Line2D([], [], color="tab:red", lw=0.9, ls="--", label="reference")
            )
        fig.legend(
            handles=handles, loc="upper right", fontsize=7, frameon=False, ncol=2
        )
        part = f" ({k + 1}/{n_fig})" if n_fig > 1 else ""
        what = (
            "Estimated vs. reference reflectance"
            if ref_lines
            else "Estimated reflectance"
        )
        fig.text(0.035, 1 - 0.12 / height, f"{what}{part}", fontsize=10, va="top")
        fig.text(
            0.035,
            0.12 / height,
            f"Each cell: {wl[0]:g}-{wl[-1]:g} nm across, reflectance factor 0-{y_top:.2g} "
            "up; grey lines at 500 and 600 nm and at 0.5. Swatch: sRGB under D50.",
            fontsize=7,
            color="0.3",
            va="bottom",
        )
        yield f"reflectance_grid_{k + 1}", fig


def report_figures(report: ReportData) -> list[tuple[str, Figure]]:
    """The report's figures (name, Agg-backed Figure), in report order."""
    figs: list[tuple[str, Figure]] = []
    if report.illuminants is not None:
        figs.append(("led_spd", _spd_figure(report.illuminants)))
    if report.sensitivity is not None:
        figs.append(("sensitivities", _sensitivity_figure(report)))
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


def _result_tables(report: ReportData) -> list[_Table]:
    tables = []
    fitted, held = _table1_parts(report)
    if fitted is not None:
        title = "Table 1: response prediction (fitted patches)"
        tables.append(_table1(fitted, title, paper=True))
    if held is not None:
        title = "Response prediction (held-aside patches)"
        tables.append(_table1(held, title, paper=False))
    if report.table2 is not None:
        tables.append(_table2(report.table2))
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
        "reflectance 0.94, L* 0.89, a* 0.92, b* 0.92 (CIELAB about 1.3x too narrow "
        "for some families)",
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
                note="python benchmarks/generalisation.py; README, 'Validated accuracy'.",
            )
        )
    summary = [("Created", _created_text(report.created))]
    if report.session_id:
        summary.append(("Session", report.session_id))
    summary.append(("TuneSpec", tunespec_version()))
    tables.append(_Table("Measurement", ("Item", "Value"), tuple(summary)))
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
        rows = tuple((str(k), str(v)) for k, v in report.exports.items())
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
    if report.notes:
        parts.append(f"<p>{e(report.notes)}</p>")
    parts.append("<h2>Quality flags</h2>")
    if flags:
        parts.append('<ul class="flags">')
        parts += [f'<li class="{e(f.level)}">{e(f.text)}</li>' for f in flags]
        parts.append("</ul>")
    else:
        parts.append('<p class="note">No data to check (no responses given).</p>')
    captions = {
        "led_spd": "LED spectral power distributions (the light source's internal "
        "spectroradiometer).",
        "sensitivities": "Estimated camera sensitivities"
        + (
            f" (solid) and {report.sensitivity_reference_label} (dashed)"
            if report.sensitivity_reference is not None
            else ""
        )
        + ", each set normalised to its peak.",
        "response_map": "Largest of the R, G, B responses per patch (rows) and LED "
        "(columns); crosses mark stimuli with saturated pixels.",
    }
    tables = _result_tables(report)
    sections = [
        ("Light source", ["led_spd"]),
        ("Camera", ["sensitivities", "response_map"]),
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
            '<p class="note">Solid: estimated (Wiener); dashed: reference. Swatches: '
            "sRGB rendering under D50. Compare the paper's Figure 6.</p>"
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

_LINES_PER_PAGE = 80
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


def _text_pages(title: str, lines: Sequence[str]) -> Iterator[Figure]:
    chunks = [
        lines[i : i + _LINES_PER_PAGE] for i in range(0, len(lines), _LINES_PER_PAGE)
    ]
    for k, chunk in enumerate(chunks or [[]]):
        fig = _new_figure(_A4_PORTRAIT_IN, margins_in=None)
        head = title if len(chunks) <= 1 else f"{title} ({k + 1}/{len(chunks)})"
        fig.text(0.06, 0.965, head, fontsize=13, weight="bold", va="top")
        fig.text(
            0.06, 0.93, "\n".join(chunk), fontsize=7.2, family="monospace", va="top"
        )
        yield fig


def _summary_lines(report: ReportData) -> list[str]:
    lines = [
        f"Created: {_created_text(report.created)}",
        f"TuneSpec {tunespec_version()}"
        + (f", session {report.session_id}" if report.session_id else ""),
        "",
    ]
    if report.notes:
        lines += [*textwrap.wrap(report.notes, _WRAP), ""]
    lines.append("Quality flags")
    lines.append("")
    for f in quality_flags(report):
        wrapped = textwrap.wrap(f.text, _WRAP - 4)
        lines.append(f"[{f.level.upper()}] " + (wrapped[0] if wrapped else ""))
        lines += ["    " + w for w in wrapped[1:]]
    lines.append("")
    for t in _result_tables(report):
        lines += _text_table(t)
    return lines


def _write_pdf(
    path: Path, report: ReportData, figures: Sequence[tuple[str, Figure]]
) -> None:
    meta: dict[str, Any] = {
        "Title": report.title,
        "Creator": f"TuneSpec {tunespec_version()}",
    }
    if isinstance(report.created, datetime):
        meta["CreationDate"] = report.created
    with PdfPages(path, metadata=meta) as pdf:
        for fig in _text_pages(report.title, _summary_lines(report)):
            pdf.savefig(fig)
        for _, fig in figures:
            pdf.savefig(fig)
        lines: list[str] = []
        for t in _provenance_tables(report):
            lines += _text_table(t)
        for fig in _text_pages("Provenance", lines):
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
    html_path.write_text(render_html(report, figures), encoding="utf-8")
    _write_pdf(pdf_path, report, figures)
    return html_path, pdf_path
