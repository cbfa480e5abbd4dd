"""The report rendered: one self-contained HTML page and an A4 PDF
(:func:`write_report`), from :mod:`.data`, :mod:`.tables` and :mod:`.figures`."""

from __future__ import annotations

import base64
import html
import io
import re
import textwrap
from collections.abc import Iterator, Sequence
from dataclasses import replace
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path
from typing import Any

from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from tunespec.app.report.data import (
    Flag,
    ReportData,
    _created_text,
    led_radiance,
    quality_flags,
    verdict,
)
from tunespec.app.report.figures import _A4_PORTRAIT_IN, _page, report_figures
from tunespec.app.report.tables import (
    _instruments_table,
    _key_numbers,
    _provenance_tables,
    _record_table,
    _result_tables,
    _Table,
)
from tunespec.core.io.export import tunespec_version


def _verdict_colours(outcome: str) -> tuple[str, str, str]:
    """(background, edge, text) colours of a verdict."""
    if outcome == "PASS":
        return "#e8f4ea", "#3c9a4f", "#2d7a3d"
    if outcome == "FAIL":
        return "#fde8e8", "#c00000", "#c00000"
    return "#fff3cd", "#e0a800", "#8a5a00"


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
    record = [x for x in (_record_table(report), _instruments_table(report)) if x]
    if record:
        parts.append("<h2>Measurement record</h2>")  # the first table's heading
        parts += [
            _html_table(replace(record[0], title="")),
            *map(_html_table, record[1:]),
        ]
    parts += _html_summary(report, flags)
    captions = {
        "light_camera": "LED spectra as the light source's spectroradiometer "
        "measured them"
        + (
            " (spectral radiance)"
            if report.illuminants is not None and led_radiance(report)[1]
            else ""
        )
        + ", and the estimated camera sensitivities"
        + (
            f" (solid) with {report.sensitivity_reference_label} (dashed)"
            if report.sensitivity_reference is not None
            else ""
        )
        + ", normalised to their peak.",
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
#: A table of at least this many lines may start on a page with room left and go
#: on on the next.
_SPLIT_LINES = 30


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
    """Page 1: the measurement record (who, what, with which instruments), the
    verdict, the key numbers, the warnings; lines to sign when there is a record."""
    fig = _page(report.title)
    meta = f"Created {_created_text(report.created)} · TuneSpec {tunespec_version()}"
    if report.session_id:
        meta += f" · session {report.session_id}"
    fig.text(0.08, 0.935, meta, fontsize=8.5, color="0.3", va="top")
    y = 0.905
    signed = report.record is not None
    for t, xs, wrap in (
        (_record_table(report), (0.08, 0.36), (34, 78)),
        (
            _instruments_table(report),
            (0.08, 0.24, 0.56, 0.70, 0.80),
            (20, 40, 17, 11, 26),
        ),
    ):
        if t is not None:
            y = _draw_table(fig, y, t, xs, wrap, size=8.0, step=0.0145)
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
    y = _draw_table(fig, y, _key_numbers(report), (0.08, 0.62, 0.80), (70, 24, 16))
    if report.notes:
        notes = textwrap.wrap(report.notes, 100)
        fig.text(0.08, y, "\n".join(notes), fontsize=8.5, va="top")
        y -= 0.014 * len(notes) + 0.01
    fig.text(0.08, y, "Warnings and checks", fontsize=11, weight="bold", va="top")
    y -= 0.025
    bottom = 0.085 if signed else 0.04
    for f in quality_flags(report):
        wrapped = textwrap.wrap(f.text, 105)
        if y - 0.0135 * len(wrapped) < bottom:
            fig.text(0.08, y, "… (all in the HTML report)", fontsize=8, va="top")
            break
        mark = "⚠" if f.level == "warning" else "✓"
        colour = "#8a5a00" if f.level == "warning" else "#2d7a3d"
        fig.text(0.08, y, mark, fontsize=9, va="top", color=colour)
        fig.text(0.105, y, "\n".join(wrapped), fontsize=8, va="top")
        y -= 0.0135 * len(wrapped) + 0.006
    if signed:  # the record is signed on paper
        for x, label in ((0.08, "Operator: signature, date"), (0.52, "Reviewed by")):
            fig.add_artist(Line2D([x, x + 0.38], [0.05, 0.05], color="0.3", lw=0.6))
            fig.text(x, 0.043, label, fontsize=7.5, color="0.35", va="top")
    return fig


def _draw_table(
    fig: Figure,
    y: float,
    t: _Table,
    xs: Sequence[float],
    wrap: Sequence[int],
    *,
    size: float = 9.0,
    step: float = 0.017,
) -> float:
    """A table in the page's font, columns at ``xs`` (figure units), each cell
    wrapped at ``wrap`` characters; returns the y below it."""
    fig.text(0.08, y, t.title, fontsize=size + 2, weight="bold", va="top")
    y -= 0.026
    for x, h in zip(xs, t.header, strict=True):
        fig.text(x, y, h, fontsize=size, weight="bold", va="top", ha="left")
    y -= step
    fig.add_artist(Line2D([0.08, 0.92], [y + 0.004, y + 0.004], color="0.6", lw=0.6))
    for row in t.rows:
        cells = [textwrap.wrap(c, w) or [""] for c, w in zip(row, wrap, strict=True)]
        for x, lines in zip(xs, cells, strict=True):
            fig.text(x, y - 0.003, "\n".join(lines), fontsize=size, va="top")
        y -= step * max(len(c) for c in cells)
    note = textwrap.wrap(t.note, 120)
    fig.text(0.08, y - 0.005, "\n".join(note), fontsize=7, color="0.35", va="top")
    return y - 0.012 * len(note) - 0.022


def _flow_pages(title: str, tables: Sequence[_Table]) -> Iterator[Figure]:
    """Tables flowed onto A4 pages: a short table that fits on a page is not split;
    a long one (:data:`_SPLIT_LINES`) that does not fit the rest of a page with
    room left, or one longer than a page, is split between rows, its header
    repeated (no page left half empty before a long table)."""
    pages: list[list[str]] = [[]]
    for t in tables:
        lines = _text_table(t)
        lines[0] = _TITLE_MARK + lines[0]  # drawn as a heading
        room = _LINES_PER_PAGE - len(pages[-1])
        split = len(lines) > _LINES_PER_PAGE or (
            len(lines) > room and len(lines) >= _SPLIT_LINES and room >= 20
        )
        if len(lines) > room and not split:
            pages.append([])
        elif split:
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
