"""The report's figures: Agg-backed A4 portrait matplotlib pages (never
``pyplot``, so the GUI's backend is left alone), from a :class:`~.data.ReportData`."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from numpy.typing import NDArray

from tunespec.app.report.data import (
    PAPER_TABLE1,
    PAPER_TABLE2_AVERAGE,
    ReportData,
    _as_dict,
    led_radiance,
)
from tunespec.core.errors import InputError
from tunespec.core.intervals import COVERAGE_FACTOR_95
from tunespec.core.responses import Responses
from tunespec.core.spectra import Spectra

#: Patches per page of the Figure 6 grid (4 columns x 6 rows on A4 portrait).
PATCHES_PER_FIGURE = 24
_GRID_COLS = 4

_A4_LANDSCAPE_IN = (11.69, 8.27)
_A4_PORTRAIT_IN = (8.27, 11.69)
_CHANNEL_COLOURS = {"R": "#d62728", "G": "#2ca02c", "B": "#1f77b4"}


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


def _draw_spd(ax: Any, report: ReportData) -> None:
    illuminants, unit = led_radiance(report)
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
    ax.set_ylabel(
        f"spectral radiance ({unit})"
        if unit
        else "spectral power (units of the LED spectra's file)"
    )
    ax.set_title(
        f"LED spectra measured by the spectroradiometer ({len(illuminants)} channels)"
    )
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
            u = COVERAGE_FACTOR_95 * report.sensitivity_std[k] / peak
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
    ax.set_ylabel("sensitivity (peak = 1)")
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
        _draw_spd(_axes_in(fig, 0.9, 7.1, 6.9, 3.6), report)
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
        pi = np.argwhere(responses.clipped)
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
    """What the cells of the reflectance pages share, and what they collect.

    Drawn on one axes whose data units are inches from its lower left corner;
    ``cell_in`` is a cell's (width, height), ``fs`` the tick labels' font size.
    """

    report: ReportData
    de: dict[str, float]
    swatches: dict[str, NDArray[np.float64]]
    y_top: float
    cols: int = 4
    cell_in: tuple[float, float] = (1.4, 1.0)
    fs: float = 5.0
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

    @property
    def gaps_in(self) -> tuple[float, float]:
        """(left of a cell: tick labels and the reflectance label; below it: tick
        labels, the wavelength label and the next cell's title), inches."""
        pt = self.fs / 72.0
        return 0.12 + 4.2 * pt, 0.16 + 5.6 * pt


#: The reflectance pages' plot area (left, bottom, width, height), inches on A4.
_GRID_AREA_IN = (0.45, 0.85, 7.45, 9.85)


def _grid_shape(n: int) -> tuple[int, int, float]:
    """(columns, rows, font size) of a page of ``n`` patches: few patches get
    fewer columns and larger plots, so that a small set fills its page."""
    cols = 2 if n <= 8 else 3 if n <= 12 else _GRID_COLS
    rows = max(1, math.ceil(n / cols))
    return cols, rows, {2: 7.5, 3: 6.5}.get(cols, 5.0)


def _grid_cell(ax: Any, g: _Grid, i: int, x0: float, y0: float) -> None:
    """One patch at (x0, y0) inches: estimate, band, reference, frame, ticks with
    their labels, axis labels with units, title, swatch."""
    from matplotlib.patches import Rectangle

    est, ref, report = g.report.reflectance, g.report.reflectance_reference, g.report
    assert est is not None
    wl, span, y_top = g.wl, g.span, g.y_top
    w, h = g.cell_in
    name = est.names[i]
    pad, fs = 0.04, g.fs
    x = x0 + w * (wl - wl[0]) / span
    g.est_lines.append(np.column_stack([x, y0 + h * est.values[i] / y_top]))
    if report.reflectance_std is not None:
        u = COVERAGE_FACTOR_95 * report.reflectance_std[i]
        lo = y0 + h * np.clip(est.values[i] - u, 0.0, y_top) / y_top
        hi = y0 + h * np.clip(est.values[i] + u, 0.0, y_top) / y_top
        g.bands.append(
            np.concatenate([np.column_stack([x, lo]), np.column_stack([x, hi])[::-1]])
        )
    if ref is not None and name in ref.names:
        xr = x0 + w * (ref.wavelength_nm - wl[0]) / span
        keep = (xr >= x0 - 1e-9) & (xr <= x0 + w + 1e-9)
        g.ref_lines.append(
            np.column_stack([xr[keep], y0 + h * ref[name][keep] / y_top])
        )
    g.frames.append([(x0, y0), (x0 + w, y0), (x0 + w, y0 + h), (x0, y0 + h), (x0, y0)])
    step_nm = 50.0 if w > 2.5 else 100.0
    ticks_nm = np.arange(math.ceil(wl[0] / step_nm) * step_nm, wl[-1] + 1e-9, step_nm)
    grey = {"fontsize": fs, "color": "0.3"}
    for t in ticks_nm:
        gx = x0 + w * (t - wl[0]) / span
        g.grid.append([(gx, y0), (gx, y0 + h)])
        ax.text(gx, y0 - pad, f"{t:g}", ha="center", va="top", **grey)
    ax.text(
        x0 + w / 2, y0 - pad - 1.3 * fs / 72, "wavelength (nm)", ha="center", va="top",
        **grey,
    )  # fmt: skip
    for v in np.arange(0.0, y_top + 1e-9, 0.25 if h > 1.2 else 0.5):
        gy = y0 + h * v / y_top
        g.grid.append([(x0, gy), (x0 + w, gy)])
        ax.text(x0 - pad, gy, f"{v:g}", ha="right", va="center", **grey)
    ax.text(
        x0 - pad - 2.6 * fs / 72, y0 + h / 2, "reflectance factor", rotation=90,
        ha="right", va="center", **grey,
    )  # fmt: skip
    if name in g.swatches:
        ax.add_patch(
            Rectangle(
                (x0 + 0.82 * w, y0 + h + pad),
                0.18 * w,
                1.6 * fs / 72,
                facecolor=tuple(g.swatches[name]),
                edgecolor="0.3",
                lw=0.4,
            )
        )
    title = name if name not in g.de else f"{name}   ΔE00 {g.de[name]:.2f}"
    ax.text(x0, y0 + h + pad, title, fontsize=fs + 1.5, va="bottom", ha="left")


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
    portrait pages of at most :data:`PATCHES_PER_FIGURE`; a set of a few patches
    gets larger plots that fill its page (:func:`_grid_shape`). Each cell has its
    ticks and axis labels with units, and the 95 % band when the uncertainty is
    known.

    All cells of a page are drawn on one axes (in inches) with line collections:
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
    names = est.names
    n_fig = math.ceil(len(names) / PATCHES_PER_FIGURE)
    cols, rows, fs = _grid_shape(min(len(names), PATCHES_PER_FIGURE))
    g0 = _Grid(
        report,
        {} if t2 is None else {k: v["delta_e00"] for k, v in t2["patches"].items()},
        _display_colours(report),
        y_top,
        cols=cols,
        fs=fs,
    )
    left, bottom, width, height = _GRID_AREA_IN
    gap_x, gap_y = g0.gaps_in
    title_in = 0.06 + 1.6 * (fs + 1.5) / 72  # above a cell; the rest of gap_y below
    cell_w = (width - cols * gap_x) / cols
    cell_h = min((height - rows * gap_y) / rows, 0.75 * cell_w)
    what = (
        "Estimated vs. reference reflectance"
        if ref is not None
        else "Estimated reflectance"
    )
    for k in range(n_fig):
        g = replace(
            g0, cell_in=(cell_w, cell_h), est_lines=[], ref_lines=[], bands=[],
            frames=[], grid=[],
        )  # fmt: skip
        part = f" ({k + 1}/{n_fig})" if n_fig > 1 else ""
        fig = _page(f"{what}{part}")
        ax = _axes_in(fig, left, bottom, width, height)
        ax.set_axis_off()
        first = k * PATCHES_PER_FIGURE
        for pos, i in enumerate(
            range(first, min(len(names), first + PATCHES_PER_FIGURE))
        ):
            r, c = divmod(pos, cols)
            y0 = height - title_in - cell_h - r * (cell_h + gap_y)
            _grid_cell(ax, g, i, gap_x + c * (cell_w + gap_x), y0)
        handles = _grid_draw(ax, g)
        ax.set_xlim(0.0, width)
        ax.set_ylim(0.0, height)
        fig.legend(
            handles=handles,
            loc="upper right",
            bbox_to_anchor=(0.95, 0.975),
            fontsize=8,
            frameon=False,
            ncol=3,
        )
        fig.text(
            0.08,
            0.035,
            "Reflectance factor (1 = a perfect white diffuser) against wavelength. "
            + ("Grey band: 95 % interval of the estimate. " if g.bands else "")
            + "Swatch: sRGB of the estimate under D50"
            + ("; ΔE00: CIEDE2000 against the reference" if g0.de else "")
            + ". Compare the paper's Figure 6.",
            fontsize=7,
            color="0.3",
            wrap=True,
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
