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

This module is the entry point and keeps the names callers import; the work is in
:mod:`.data` (:class:`ReportData`, the flags and the verdict), :mod:`.tables`,
:mod:`.figures` and :mod:`.render` (HTML, PDF).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
Tables 1 and 2, Figures 2, 5 and 6.
"""

from tunespec.app.report.data import (
    COLORIMETRY_DATA,
    EXPORT_LABELS,
    MAX_LISTED,
    PAPER_TABLE1,
    PAPER_TABLE2_AVERAGE,
    DatasetInfo,
    Flag,
    ReportData,
    export_label,
    quality_flags,
    shipped_datasets,
    verdict,
)
from tunespec.app.report.figures import PATCHES_PER_FIGURE, report_figures
from tunespec.app.report.render import render_html, write_report
from tunespec.core.verdict import VERDICTS

__all__ = [
    "COLORIMETRY_DATA",
    "EXPORT_LABELS",
    "MAX_LISTED",
    "PAPER_TABLE1",
    "PAPER_TABLE2_AVERAGE",
    "PATCHES_PER_FIGURE",
    "VERDICTS",
    "DatasetInfo",
    "Flag",
    "ReportData",
    "export_label",
    "quality_flags",
    "render_html",
    "report_figures",
    "shipped_datasets",
    "verdict",
    "write_report",
]
