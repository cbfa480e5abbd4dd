"""Spectral CSV in and out: the project's own layout and the usual variants.

The project writes (and every command reads) a first column of wavelengths in nm
and one column per named spectrum::

    wavelength_nm,A1,A2
    380,0.108,0.0068
    390,0.200,0.0067

The reader also takes what instruments, spreadsheets and other libraries write:

- the wavelength column headed ``wavelength``, ``wavelength (nm)``, ``nm``,
  ``lambda``, ``λ`` or ``wl`` (any case); colour-science's
  ``colour.io.write_sds_to_csv_file`` writes ``wavelength`` and one column per spectrum;
- comma, semicolon or tab separated (detected from the header line); with ``;`` or
  tab a decimal comma (``0,52``) is read as a decimal point;
- one spectrum per *row*: a header such as ``SAMPLE_NAME,380,390,...`` or
  ``name,nm380,nm390,...`` (spectral columns named by their wavelength, as the CGATS
  field names of :func:`~tunespec.core.io.cgats.spectral_field_wavelength`); other
  columns (L*a*b*, an index) are ignored, the spectrum's name comes from a column
  called ``name``/``sample``/``id`` or the first non-spectral one;
- ``#`` comment lines anywhere, blank lines, a UTF-8 byte-order mark.

Every value is checked once here (finite, in range, non-negative unless allowed,
wavelengths strictly increasing); an error names the file, the line and what was
expected.
"""

from __future__ import annotations

import csv
import math
import re
from collections import Counter
from collections.abc import Sequence
from os import PathLike

import numpy as np

from tunespec.core.atomic import atomic_open
from tunespec.core.errors import InputError
from tunespec.core.io.raw import F_NUMBER_META
from tunespec.core.limits import (
    MAX_VALUE,
    MAX_WAVELENGTH_NM,
    csv_rows,
    shown,
    valid_name,
)
from tunespec.core.metering import READING_NOISE_META, READING_STEP_META
from tunespec.core.spectra import Spectra

__all__ = [
    "COMMENT_META",
    "comment_values",
    "is_wavelength_header",
    "numbered_rows",
    "parse_spectra_csv",
    "write_spectra_csv",
]

#: First-column headers that name the wavelength axis.
#: Values within this of zero read as zero (float round-off, not a negative value).
ZERO_TOLERANCE = 1e-12

_WAVELENGTH_HEADER = re.compile(
    r"^\s*(wavelengths?|wave_?length_?nm|lambda|λ|wl|nm)\b.*$|.*wavelength.*",
    re.IGNORECASE,
)
_NAME_HEADER = re.compile(r"(name|sample|patch|label|^id$)", re.IGNORECASE)


def is_wavelength_header(text: str) -> bool:
    """Whether a column header names wavelengths in nm.

    Examples
    --------
    >>> [is_wavelength_header(h) for h in ("wavelength_nm", "nm", "Lambda", "R")]
    [True, True, True, False]
    """
    return bool(_WAVELENGTH_HEADER.match(text.strip()))


def _delimiter(line: str) -> str:
    """The separator of a header line: ``;`` or tab where present, else ``,``."""
    counts = {d: line.count(d) for d in (";", "\t", ",")}
    if counts[";"] and counts[";"] >= counts["\t"]:
        return ";"
    if counts["\t"]:
        return "\t"
    return ","


def _number(cell: str, decimal_comma: bool) -> float:
    text = cell.strip()
    if decimal_comma and "," in text and "." not in text:
        text = text.replace(",", ".")
    return float(text)


def _column_wavelength(header: str) -> float | None:
    """The wavelength a row-layout column header stands for (``380``, ``nm380``)."""
    from tunespec.core.io.cgats import spectral_field_wavelength

    text = header.strip()
    try:
        value = float(text)
    except ValueError:
        return spectral_field_wavelength(text)
    return value if 100.0 <= value <= 100_000.0 else None


def parse_spectra_csv(
    text: str,
    *,
    source: str | PathLike[str] | None = None,
    allow_negative: bool = False,
    max_value: float = MAX_VALUE,
) -> Spectra:
    """Spectra from spectral CSV text (either layout); see the module docstring.

    Raises
    ------
    InputError
        With the file, the line and what was expected.
    """
    path = None if source is None else str(source)
    numbered, delim = _numbered(text, path)
    if not numbered:
        raise InputError("empty file, expected a spectral CSV", path=path)
    line0, header = numbered[0]
    header = [h.strip().lstrip("\ufeff") for h in header]
    while header and not header[-1] and all(not r[-1].strip() for _, r in numbered):
        header.pop()  # a trailing separator on every line
    # a trailing separator is dropped; an extra value is a row too long (_data_rows)
    numbered = [
        (n, r if any(c.strip() for c in r[len(header) :]) else r[: len(header)])
        for n, r in numbered
    ]
    opts = (delim != ",", allow_negative, max_value, path)
    if not header[0] or is_wavelength_header(header[0]):
        return _by_columns(header, numbered, line0, opts)
    spectral = [_column_wavelength(h) for h in header]
    if sum(w is not None for w in spectral) >= 2:
        return _by_rows(header, spectral, numbered, line0, opts)
    raise InputError(
        # the line itself is not echoed: the file may be anything (a path typo)
        "not a spectral CSV header: expected a first column naming the wavelengths "
        "(wavelength_nm, nm, lambda) or a header of wavelengths (name,380,390,...)",
        path=path,
        line=line0,
    )


def _numbered(text: str, path: str | None) -> tuple[list[tuple[int, list[str]]], str]:
    """The rows of ``text`` with their line numbers (comments blanked), and the
    separator."""
    lines = [ln if not ln.lstrip().startswith("#") else "" for ln in text.splitlines()]
    first = next((ln for ln in lines if ln.strip()), "")
    delim = _delimiter(first)
    return csv_rows("\n".join(lines), path=path, delimiter=delim), delim


def numbered_rows(text: str) -> list[tuple[int, list[str]]]:
    """``(line number, cells)`` of each row of spectral CSV text, as
    :func:`parse_spectra_csv` reads them (for messages naming a value's line)."""
    return _numbered(text, None)[0]


def _check_value(
    v: float, col: str, lineno: int, opts: tuple, *, wavelength: bool = False
) -> None:
    _, allow_negative, max_value, path = opts
    if not math.isfinite(v):
        raise InputError(f"{col}: value {v} is not finite", path=path, line=lineno)
    if v < 0 and not allow_negative and not wavelength:
        raise InputError(f"{col}: negative value {v}", path=path, line=lineno)
    limit = MAX_WAVELENGTH_NM if wavelength else max_value
    if abs(v) > limit:
        raise InputError(
            f"{shown(col)}: value {v:g} out of range (at most {limit:g} in magnitude)",
            path=path,
            line=lineno,
        )


def _numbers(row: list[str], cols: list[str], lineno: int, opts: tuple) -> list[float]:
    decimal_comma, path = opts[0], opts[3]
    out = []
    for cell, col in zip(row, cols, strict=True):
        try:
            v = _number(cell, decimal_comma)
        except ValueError:
            raise InputError(
                f"{shown(col)}: not a number: {shown(cell)}", path=path, line=lineno
            ) from None
        # round-off of another tool's arithmetic (colour-science writes -2e-19)
        out.append(0.0 if abs(v) <= ZERO_TOLERANCE else v)
    return out


def _check_names(names: list[str], lineno: int, path: str | None, what: str) -> None:
    if not names or any(not n for n in names):
        raise InputError(f"expected named spectra ({what})", path=path, line=lineno)
    for n in names:
        valid_name(n, "spectrum name", path=path, line=lineno)
    dup = sorted(n for n, k in Counter(names).items() if k > 1)
    if dup:
        raise InputError(
            f"duplicate spectrum names: {', '.join(dup[:8])}", path=path, line=lineno
        )


def _check_wavelengths(wl: list[float], lines: list[int], path: str | None) -> None:
    for k in range(1, len(wl)):
        if wl[k] <= wl[k - 1]:
            raise InputError(
                f"wavelength {wl[k]:g} nm is not above the previous {wl[k - 1]:g} nm",
                path=path,
                line=lines[k],
            )
    if len(wl) < 2:
        raise InputError("expected at least two wavelengths", path=path)


def _data_rows(
    numbered: list[tuple[int, list[str]]], n_fields: int, path: str | None
) -> list[tuple[int, list[str]]]:
    """The rows after the header, each checked to have the header's field count."""
    for lineno, row in numbered[1:]:
        if len(row) != n_fields:
            raise InputError(
                f"{len(row)} fields, expected {n_fields} as in the header",
                path=path,
                line=lineno,
            )
    return numbered[1:]


def _by_columns(
    header: list[str], numbered: list[tuple[int, list[str]]], line0: int, opts: tuple
) -> Spectra:
    """Wavelengths down the first column, one spectrum per further column."""
    path = opts[3]
    names = header[1:]
    _check_names(names, line0, path, "columns after the wavelength column")
    wl: list[float] = []
    wl_lines: list[int] = []
    data: list[list[float]] = []
    for lineno, row in _data_rows(numbered, len(header), path):
        nums = _numbers(row, header, lineno, opts)
        _check_value(nums[0], header[0], lineno, opts, wavelength=True)
        for col, v in zip(names, nums[1:], strict=True):
            _check_value(v, col, lineno, opts)
        wl.append(nums[0])
        wl_lines.append(lineno)
        data.append(nums[1:])
    _check_wavelengths(wl, wl_lines, path)
    meta = {"format": "spectral CSV (wavelengths down)"}
    return Spectra(np.array(wl), np.array(data).T, tuple(names), meta)


def _by_rows(
    header: list[str],
    spectral: list[float | None],
    numbered: list[tuple[int, list[str]]],
    line0: int,
    opts: tuple,
) -> Spectra:
    """One spectrum per row, spectral columns named by their wavelength."""
    path = opts[3]
    cols = [j for j, w in enumerate(spectral) if w is not None]
    wl = [float(spectral[j]) for j in cols]  # type: ignore[arg-type]
    order = np.argsort(wl)
    cols = [cols[k] for k in order]
    wl = [wl[k] for k in order]
    _check_wavelengths(wl, [line0] * len(wl), path)
    others = [j for j, w in enumerate(spectral) if w is None]
    name_col = next((j for j in others if _NAME_HEADER.search(header[j])), None)
    if name_col is None and others:
        name_col = others[0]
    names: list[str] = []
    data: list[list[float]] = []
    for lineno, row in _data_rows(numbered, len(header), path):
        cells = [row[j] for j in cols]
        nums = _numbers(cells, [header[j] for j in cols], lineno, opts)
        for j, v in zip(cols, nums, strict=True):
            _check_value(v, header[j], lineno, opts)
        names.append(
            row[name_col].strip() if name_col is not None else str(len(names) + 1)
        )
        data.append(nums)
    if not data:
        raise InputError("no data rows after the header", path=path, line=line0)
    _check_names(names, line0, path, "one name per row")
    meta = {"format": "spectral CSV (one spectrum per row)"}
    return Spectra(np.array(wl), np.array(data), tuple(names), meta)


def write_spectra_csv(
    spectra: Spectra, path: str | PathLike[str], *, header: str = "wavelength_nm"
) -> None:
    """Write ``spectra`` as a spectral CSV (full float precision, round-trips exactly).

    The light's readings keep their reading noise and step as the instrument reported
    them, and a processed session's illuminants the f-number of its frames (``meta``
    keys :data:`COMMENT_META`), in ``# key: value`` comment lines after the data
    (:func:`comment_values` reads them back): readers that take the first line as
    the header and skip comments (numpy's ``genfromtxt``, colour-science's
    ``read_sds_from_csv_file``, pandas with ``comment="#"``) read the file as before."""
    with atomic_open(path, newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow([header, *spectra.names])
        for i, wl in enumerate(spectra.wavelength_nm):
            w.writerow([f"{wl:g}", *(repr(float(v)) for v in spectra.values[:, i])])
        for key in COMMENT_META:
            if key in spectra.meta:
                fh.write(f"# {key}: {spectra.meta[key]}\n")


#: ``Spectra.meta`` keys a spectral CSV keeps in ``# key: value`` comment lines: the
#: light's reading noise and step as reported (:mod:`tunespec.core.metering`) and the
#: f-number of a processed session's frames (:data:`~tunespec.core.io.raw.F_NUMBER_META`).
COMMENT_META = (READING_NOISE_META, READING_STEP_META, F_NUMBER_META)


def comment_values(text: str, keys: Sequence[str]) -> dict[str, tuple[str, int]]:
    """``key -> (value, line number)`` of the ``# key: value`` comment lines of
    ``text`` whose key is one of ``keys`` (the first of each)."""
    out: dict[str, tuple[str, int]] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.lstrip("\ufeff \t")
        if not body.startswith("#"):
            continue
        key, sep, value = body[1:].partition(":")
        key = key.strip()
        if sep and key in keys and key not in out:
            out[key] = (value.strip(), lineno)
    return out
