"""CGATS files in the ArgyllCMS ``.ti3`` style: write tables other tools read, read theirs.

A CGATS file (ANSI CGATS.5 / CGATS.17, ISO 28178) is a whitespace-separated text table
with a header of keywords::

    CTI3

    DESCRIPTOR "TuneSpec estimated reflectances"
    ORIGINATOR "TuneSpec 0.1.0"
    CREATED "2026-11-22T10:00:00+00:00"
    KEYWORD "DEVICE_CLASS"
    DEVICE_CLASS "INPUT"
    ...
    KEYWORD "SAMPLE_NAME"
    KEYWORD "SPEC_380"
    NUMBER_OF_FIELDS 77
    BEGIN_DATA_FORMAT
    SAMPLE_ID SAMPLE_NAME RGB_R RGB_G RGB_B XYZ_X XYZ_Y XYZ_Z LAB_L LAB_A LAB_B SPEC_380 ...
    END_DATA_FORMAT

    NUMBER_OF_SETS 140
    BEGIN_DATA
    A1 "A1" 12.5 ...
    END_DATA

What ArgyllCMS needs (its ``doc/ti3_format.html``, ``cgats/cgats.c`` and
``spectro/spec2cie.c``, checked by running ArgyllCMS 2.3.1 on our files):

- the file identifier ``CTI3`` and a ``DEVICE_CLASS`` keyword (``"INPUT"`` for camera
  characterisation data); ``COLOR_REP`` names the PCS first and the device space second
  for an input device (``"XYZ_RGB"``). ``spec2cie`` rejects a ``COLOR_REP`` whose device
  space has no device fields, so a file without RGB carries no ``COLOR_REP``;
- spectral bands named ``SPEC_nnn`` (nearest integer nm) with ``SPECTRAL_BANDS``,
  ``SPECTRAL_START_NM`` and ``SPECTRAL_END_NM``; spectral values in percent
  (``spec2cie`` sets the spectrum's norm to 100);
- device values (``RGB_R`` ...) in percent, XYZ scaled to Y = 100, L*a*b* as is;
- every number of a real-valued field written with a decimal point: Argyll types a column
  whose values are all integers as integer and then refuses it ("Field SPEC_400 is wrong
  type - expect float"), which even happens to Argyll's own output for integral spectra;
- ``KEYWORD "NAME"`` declares a keyword or field that CGATS does not define; Argyll
  writes these lines and ignores them on reading.

Numbers are written with :func:`repr` (shortest text that reads back to the same
double); percent values are written by moving the decimal point of that text, so
``0..1`` spectra and full-scale RGB round-trip exactly through the percent scale.

The reader accepts files with or without ``KEYWORD`` lines, tabs or spaces, comments
(``#``), quoted strings with doubled quotes, and the usual spectral field names
(``SPEC_380``, ``SPECTRAL_NM_380``, ``SPECTRAL_NM380``, ``nm380``, ``NM_380``,
``R_380``). Only the first table of a multi-table file (e.g. the calibration table of a
display ``.ti3``) is read.

References
----------
ArgyllCMS documentation, "Description of the .ti3 format" (``doc/ti3_format.html``) and
the CGATS parser ``cgats/cgats.c`` (Graeme W. Gill).
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from decimal import Decimal
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.atomic import atomic_write_text
from tunespec.core.errors import InputError
from tunespec.core.limits import MAX_COLUMNS, MAX_ROWS, MAX_VALUE, read_bytes, shown
from tunespec.core.spectra import Spectra

__all__ = [
    "ARGYLL_STANDARD_KEYWORDS",
    "CgatsTable",
    "format_cgats",
    "parse_cgats",
    "read_cgats",
    "spectral_field_wavelength",
    "ti3_field_name",
    "ti3_table",
    "write_cgats",
]

#: Keywords CGATS defines, which need no ``KEYWORD`` declaration (``cgats.c``
#: ``standard_kword``).
ARGYLL_STANDARD_KEYWORDS = frozenset(
    {
        "ORIGINATOR",
        "DESCRIPTOR",
        "CREATED",
        "MANUFACTURER",
        "PROD_DATE",
        "SERIAL",
        "MATERIAL",
        "INSTRUMENTATION",
        "MEASUREMENT_SOURCE",
        "PRINT_CONDITIONS",
    }
)

#: Words the writer generates; they can be neither keywords nor field names.
_RESERVED = frozenset(
    {
        "NUMBER_OF_FIELDS",
        "BEGIN_DATA_FORMAT",
        "END_DATA_FORMAT",
        "NUMBER_OF_SETS",
        "BEGIN_DATA",
        "END_DATA",
        "KEYWORD",
    }
)

#: Fields that are always text, whatever their values look like.
_TEXT_FIELDS = frozenset({"SAMPLE_ID", "SAMPLE_NAME", "SAMPLE_LOC", "STRING"})

#: A field name CGATS defines (``cgats.c`` ``standard_field``); anything else gets a
#: ``KEYWORD`` declaration.
_STANDARD_FIELD = re.compile(
    r"^(SAMPLE_ID|STRING|CMYK_[CMYK]|CMY_[CMY]|D_(RED|GREEN|BLUE|VIS)|RGB_[RGB]"
    r"|SPECTRAL_(NM|PCT)|XYZ_[XYZ]|XYY_(X|Y|CAPY)|LAB_([LABCH]|DE)|STDEV_([XYZLAB]|DE))$"
)

#: Fields that must hold numbers: a non-number there is an error, not a text column.
_NUMERIC_FIELD = re.compile(
    r"^(CMYK_[CMYK]|CMY_[CMY]|RGB_[RGB]|XYZ_[XYZ]|XYY_(X|Y|CAPY)|LAB_([LABCH]|DE)"
    r"|STDEV_([XYZLAB]|DE))$"
)

#: Spectral field names: SPEC_380, SPECTRAL_NM_380, SPECTRAL_NM380, SPECTRAL_380,
#: nm380, NM_380, R_380, R380 (case-insensitive), wavelength in nm.
_SPECTRAL_FIELD = re.compile(
    r"^(?:SPEC_?|SPECTRAL_NM_?|SPECTRAL_|NM_?|R_?)(\d{3,4}(?:\.\d+)?)$", re.IGNORECASE
)

_NUMBER = re.compile(r"^[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?$")
_BARE_TOKEN = re.compile(r'^[^\s"#]+$')


def spectral_field_wavelength(name: str) -> float | None:
    """The wavelength in nm a spectral field name stands for, or ``None``.

    Examples
    --------
    >>> [spectral_field_wavelength(n) for n in ("SPEC_380", "nm400", "R_730", "RGB_R")]
    [380.0, 400.0, 730.0, None]
    """
    m = _SPECTRAL_FIELD.match(name)
    return float(m.group(1)) if m else None


def ti3_field_name(wavelength_nm: float) -> str:
    """Argyll's name for a spectral band: ``SPEC_`` and the nearest integer nm.

    ``spec2cie`` builds the names as ``(int)(wl + 0.5)`` with three digits at least.

    Examples
    --------
    >>> ti3_field_name(380.0), ti3_field_name(382.5), ti3_field_name(1000.0)
    ('SPEC_380', 'SPEC_383', 'SPEC_1000')
    """
    return f"SPEC_{math.floor(wavelength_nm + 0.5):03d}"


def _float_text(value: float) -> str:
    """Shortest round-tripping text for ``value``, always with a decimal point.

    Raises
    ------
    ValueError
        For NaN and infinities, which CGATS cannot hold.
    """
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"cannot write the non-finite value {v} to a CGATS file")
    text = repr(v)
    if "." in text:
        return text
    if "e" in text:
        mant, exp = text.split("e")
        return f"{mant}.0e{exp}"
    return text + ".0"  # pragma: no cover - repr of a finite float has '.' or 'e'


def _decimal_text(d: Decimal) -> str:
    """Plain decimal text with a decimal point and no superfluous trailing zeros."""

    def tidy(mant: str) -> str:
        if "." not in mant:
            return mant + ".0"
        mant = mant.rstrip("0")
        return mant + "0" if mant.endswith(".") else mant

    if -24 <= d.adjusted() <= 24:
        return tidy(format(d, "f"))
    mant, exp = format(d, "e").split("e")
    return f"{tidy(mant)}e{exp}"


def _percent_text(value: float) -> str:
    """``100 * value`` as exact decimal text: the decimal point of ``repr`` moved.

    Reading it back with :func:`_from_percent` gives ``value`` exactly, which
    ``float(repr(100 * value)) / 100`` does not always do.
    """
    return _decimal_text(Decimal(_float_text(value)).scaleb(2))


def _from_percent(text: str) -> float:
    return float(Decimal(text).scaleb(-2))


def _quote(text: str) -> str:
    return '"' + text.replace('"', '""') + '"'


def _tokenize(line: str, *, path: str | None, lineno: int) -> list[tuple[str, bool]]:
    """Split a line into ``(token, quoted)`` pairs; ``#`` outside quotes ends it."""
    tokens: list[tuple[str, bool]] = []
    i, n = 0, len(line)
    while i < n:
        c = line[i]
        if c in " \t\r\n\f\v":
            i += 1
        elif c == "#":
            break
        elif c == '"':
            j, buf = i + 1, []
            while True:
                if j >= n:
                    raise InputError(
                        "unterminated quoted string", path=path, line=lineno
                    )
                if line[j] == '"':
                    if j + 1 < n and line[j + 1] == '"':
                        buf.append('"')
                        j += 2
                        continue
                    break
                buf.append(line[j])
                j += 1
            tokens.append(("".join(buf), True))
            i = j + 1
        else:
            j = i
            while j < n and line[j] not in ' \t\r\n\f\v"#':
                j += 1
            tokens.append((line[i:j], False))
            i = j
    return tokens


@dataclass(frozen=True, eq=False)
class CgatsTable:
    """One CGATS table: file identifier, header keywords, fields and rows.

    Parameters
    ----------
    file_id
        The identifier on the first line: ``"CTI3"`` for an Argyll ``.ti3``,
        ``"CGATS.17"``, ``"IT8.7/2"`` ...
    keywords
        Header keywords in file order, values as text without quotes (the generated
        ``NUMBER_OF_FIELDS`` and ``NUMBER_OF_SETS`` are not among them).
    fields
        Field names in column order.
    rows : (n_sets, n_fields)
        Cell text without quotes. Numbers may also be given as ``float``; they are
        stored as their shortest round-tripping text with a decimal point.
    text_fields
        The fields holding text; ``None`` infers them: ``SAMPLE_ID``, ``SAMPLE_NAME``,
        ``SAMPLE_LOC``, ``STRING`` and every field with a value that is not a number.
    source
        Where the table was read from (for messages).

    Raises
    ------
    InputError
        Duplicate or malformed field names, reserved keywords, a row of the wrong
        length, or a non-finite number.
    """

    file_id: str
    keywords: Mapping[str, str]
    fields: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    text_fields: frozenset[str] | None = None
    source: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        fields = tuple(str(f) for f in self.fields)
        if not _BARE_TOKEN.match(self.file_id or ""):
            raise InputError(f"bad CGATS file identifier {self.file_id!r}")
        for name in fields:
            if not _BARE_TOKEN.match(name) or name in _RESERVED:
                raise InputError(f"bad CGATS field name {name!r}", path=self.source)
        if len(set(fields)) != len(fields):
            dup = sorted({f for f in fields if fields.count(f) > 1})
            raise InputError(f"duplicate field(s) {', '.join(dup)}", path=self.source)
        keywords = {str(k): str(v) for k, v in self.keywords.items()}
        for k in keywords:
            if not _BARE_TOKEN.match(k) or k in _RESERVED:
                raise InputError(f"bad CGATS keyword {k!r}", path=self.source)
        rows = []
        for i, row in enumerate(self.rows):
            if len(row) != len(fields):
                raise InputError(
                    f"row {i + 1} has {len(row)} values, expected {len(fields)}",
                    path=self.source,
                )
            rows.append(tuple(c if isinstance(c, str) else _float_text(c) for c in row))
        text = self.text_fields
        if text is None:
            text = frozenset(
                f
                for j, f in enumerate(fields)
                if f in _TEXT_FIELDS or any(not _NUMBER.match(r[j]) for r in rows)
            )
        object.__setattr__(self, "fields", fields)
        object.__setattr__(self, "keywords", keywords)
        object.__setattr__(self, "rows", tuple(rows))
        object.__setattr__(self, "text_fields", frozenset(text))

    def __len__(self) -> int:
        return len(self.rows)

    def __repr__(self) -> str:
        return (
            f"CgatsTable({self.file_id}, {len(self.fields)} fields, "
            f"{len(self.rows)} sets)"
        )

    def has(self, name: str) -> bool:
        """Whether the table has field ``name``."""
        return name in self.fields

    def _index(self, name: str) -> int:
        try:
            return self.fields.index(name)
        except ValueError:
            raise InputError(
                f"no field {shown(name)}; fields: {' '.join(self.fields)[:200]}",
                path=self.source,
            ) from None

    def text_column(self, name: str) -> tuple[str, ...]:
        """The cells of field ``name`` as text."""
        j = self._index(name)
        return tuple(r[j] for r in self.rows)

    def column(self, name: str, *, percent: bool = False) -> NDArray[np.float64]:
        """The numbers of field ``name``, shape (n_sets,).

        Parameters
        ----------
        name
            The field.
        percent
            The field holds percent: return the values divided by 100, exactly (the
            decimal point of the text is moved), so ``RGB_R`` written from full-scale
            responses reads back bit for bit.

        Raises
        ------
        InputError
            If the field is missing or holds text.
        """
        j = self._index(name)
        if name in self.text_fields:
            raise InputError(f"field {name} holds text, not numbers", path=self.source)
        conv = _from_percent if percent else float
        return np.array([conv(r[j]) for r in self.rows], dtype=np.float64)

    def _triplet(self, prefix: str, suffixes: str) -> NDArray[np.float64] | None:
        names = [f"{prefix}_{s}" for s in suffixes]
        if not all(n in self.fields for n in names):
            return None
        return np.stack([self.column(n) for n in names], axis=1)

    @property
    def rgb(self) -> NDArray[np.float64] | None:
        """``RGB_R, RGB_G, RGB_B`` as in the file (percent in a ``.ti3``), (n, 3)."""
        return self._triplet("RGB", "RGB")

    @property
    def xyz(self) -> NDArray[np.float64] | None:
        """``XYZ_X, XYZ_Y, XYZ_Z`` (Y = 100 for the perfect diffuser), (n, 3)."""
        return self._triplet("XYZ", "XYZ")

    @property
    def lab(self) -> NDArray[np.float64] | None:
        """``LAB_L, LAB_A, LAB_B``, (n, 3)."""
        return self._triplet("LAB", "LAB")

    @property
    def sample_names(self) -> tuple[str, ...]:
        """One name per set: the first of ``SAMPLE_NAME``, ``SAMPLE_ID`` (unless it
        only counts 1, 2, ...), ``SAMPLE_LOC`` and ``SAMPLE_ID`` that names every
        set once, else 1..n.

        An Argyll ``txt2ti3`` file numbers its sets in ``SAMPLE_ID`` and names
        them by the chart's patch in ``SAMPLE_LOC`` (``A1`` ...): the patch names.
        """
        columns = {}
        for name in ("SAMPLE_NAME", "SAMPLE_ID", "SAMPLE_LOC"):
            if name in self.fields:
                values = self.text_column(name)
                if all(values) and len(set(values)) == len(values):
                    columns[name] = values
        counting = "SAMPLE_ID" in columns and all(
            v.isdigit() for v in columns["SAMPLE_ID"]
        )
        order = ["SAMPLE_NAME", "SAMPLE_LOC", "SAMPLE_ID"]
        if not counting:
            order = ["SAMPLE_NAME", "SAMPLE_ID", "SAMPLE_LOC"]
        for name in order:
            if name in columns:
                return columns[name]
        return tuple(str(i + 1) for i in range(len(self.rows)))

    def spectral_fields(self) -> list[tuple[str, float]]:
        """``(field, wavelength_nm)`` of the spectral fields, by wavelength.

        The wavelengths come from ``SPECTRAL_START_NM``, ``SPECTRAL_END_NM`` and
        ``SPECTRAL_BANDS`` when those agree with the field names (they keep the
        fraction that ``SPEC_nnn`` rounds away), else from the names.
        """
        found = [
            (f, wl)
            for f in self.fields
            if f not in self.text_fields
            and (wl := spectral_field_wavelength(f)) is not None
        ]
        found.sort(key=lambda p: p[1])
        try:
            n = int(self.keywords["SPECTRAL_BANDS"])
            start = float(self.keywords["SPECTRAL_START_NM"])
            end = float(self.keywords["SPECTRAL_END_NM"])
        except (KeyError, ValueError):
            return found
        if not (math.isfinite(start) and math.isfinite(end)):
            return found  # the names decide
        if n == len(found) and n > 1:
            exact = [start + j * (end - start) / (n - 1) for j in range(n)]
            if all(
                math.floor(x + 0.5) == math.floor(wl + 0.5)
                for x, (_, wl) in zip(exact, found, strict=True)
            ):
                return [(f, x) for x, (f, _) in zip(exact, found, strict=True)]
        return found

    def spectra(self, scale: float | None = None) -> Spectra | None:
        """The spectral fields as :class:`Spectra` in ``0..1``, or ``None`` if none.

        Parameters
        ----------
        scale
            What the file's values are divided by: 100 for percent, 1 for factors.
            ``None`` decides: Argyll's ``SPEC_nnn`` fields are percent (``spec2cie``
            normalises by 100), other names are percent when most spectra have
            their median above 1.5, so that one typo cannot decide the unit
            (:func:`tunespec.core.plausibility.percent_spectra`).
            Percent text is converted exactly (decimal point moved), so a spectrum
            written by :func:`ti3_table` reads back bit for bit.

        Raises
        ------
        InputError
            Duplicate wavelengths, or fewer than two bands.
        """
        spec = self.spectral_fields()
        if not spec:
            return None
        wl = np.array([w for _, w in spec])
        if len(spec) < 2 or np.any(np.diff(wl) <= 0):
            raise InputError(
                "spectral fields must name at least two distinct wavelengths "
                f"({', '.join(f for f, _ in spec)})",
                path=self.source,
            )
        idx = [self._index(f) for f, _ in spec]
        declared = False
        if scale is None:
            if all(f.upper().startswith("SPEC_") for f, _ in spec):
                scale, declared = 100.0, True
            else:
                from tunespec.core.plausibility import percent_spectra

                raw = [[float(r[j]) for j in idx] for r in self.rows]
                percent = bool(raw) and percent_spectra(np.array(raw))[0]
                scale = 100.0 if percent else 1.0
        if scale == 100.0:
            values = [[_from_percent(r[j]) for j in idx] for r in self.rows]
        else:
            values = [[float(r[j]) / scale for j in idx] for r in self.rows]
        meta = {"spectral_scale": f"{scale:g}", "cgats_id": self.file_id}
        if declared:
            meta["spectral_scale_declared"] = "1"
        if self.source is not None:
            meta["source"] = self.source
        arr = np.array(values, dtype=np.float64).reshape(len(self.rows), len(idx))
        return Spectra(wl, arr, self.sample_names, meta)


def format_cgats(table: CgatsTable) -> str:
    """The CGATS text of ``table`` (Argyll layout, ``KEYWORD`` lines included).

    Keyword values are always quoted; a text cell is quoted when it contains white
    space, a quote or ``#``, could be read as a number, or is empty (``SAMPLE_ID``
    stays bare where it can, as Argyll writes it).
    """
    out = [table.file_id, ""]
    for k, v in table.keywords.items():
        if k not in ARGYLL_STANDARD_KEYWORDS:
            out.append(f"KEYWORD {_quote(k)}")
        out.append(f"{k} {_quote(v)}")
    out.append("")
    for f in table.fields:
        if not _STANDARD_FIELD.match(f):
            out.append(f"KEYWORD {_quote(f)}")
    out += [
        f"NUMBER_OF_FIELDS {len(table.fields)}",
        "BEGIN_DATA_FORMAT",
        " ".join(table.fields),
        "END_DATA_FORMAT",
        "",
        f"NUMBER_OF_SETS {len(table.rows)}",
        "BEGIN_DATA",
    ]
    text_cols = [f in table.text_fields for f in table.fields]
    bare_ok = [f == "SAMPLE_ID" for f in table.fields]
    for row in table.rows:
        cells = []
        for cell, is_text, bare in zip(row, text_cols, bare_ok, strict=True):
            safe = (
                _BARE_TOKEN.match(cell)
                and (bare or not _NUMBER.match(cell))
                and cell not in _RESERVED
            )
            cells.append(cell if not is_text or safe else _quote(cell))
        out.append(" ".join(cells))
    out.append("END_DATA")
    return "\n".join(out) + "\n"


def write_cgats(table: CgatsTable, path: str | PathLike[str]) -> Path:
    """Write ``table`` to ``path`` (UTF-8, ``\\n`` line ends); returns the path."""
    path = Path(path)
    atomic_write_text(path, format_cgats(table))
    return path


def _count(tokens: list[tuple[str, bool]], *, path: str | None, lineno: int) -> int:
    t = tokens[1][0] if len(tokens) == 2 else ""
    if not (t.isascii() and t.isdigit() and len(t) <= len(str(MAX_ROWS))):
        raise InputError(
            f"{tokens[0][0]} needs one non-negative integer", path=path, line=lineno
        )
    return int(tokens[1][0])


def _take_fields(
    tokens: list[tuple[str, bool]], fields: list[str], *, path: str | None, lineno: int
) -> str:
    """Append the field names of a format line; the parser's next state."""
    for t, q in tokens:
        if t == "END_DATA_FORMAT" and not q:
            return "header"
        if t in _RESERVED and not q:
            raise InputError(
                f"{t} inside BEGIN_DATA_FORMAT ... END_DATA_FORMAT "
                "(END_DATA_FORMAT missing?)",
                path=path,
                line=lineno,
            )
        fields.append(t)
    return "fields"


def _check_fields(fields: list[str], *, path: str | None, lineno: int) -> None:
    """Field names as :class:`CgatsTable` needs them, or an error naming the line."""
    if len(fields) > MAX_COLUMNS:
        raise InputError(
            f"{len(fields)} fields, at most {MAX_COLUMNS}", path=path, line=lineno
        )
    for name in fields:
        if not _BARE_TOKEN.match(name) or name in _RESERVED or len(name) > 256:
            raise InputError(
                f"bad CGATS field name {shown(name)}", path=path, line=lineno
            )
    dup = sorted(f for f, k in Counter(fields).items() if k > 1)
    if dup:
        raise InputError(f"duplicate field(s) {', '.join(dup)}", path=path, line=lineno)


def _text_fields(
    fields: list[str],
    rows: list[tuple[str, ...]],
    row_lines: list[int],
    quoted: set[int],
    *,
    path: str | None,
) -> set[str]:
    """The fields holding text; numbers checked where a field must hold them."""
    text_fields = set()
    for j, name in enumerate(fields):
        if name in _TEXT_FIELDS or j in quoted:
            text_fields.add(name)
            continue
        must_be_number = bool(
            _NUMERIC_FIELD.match(name) or spectral_field_wavelength(name) is not None
        )
        for r, lineno in zip(rows, row_lines, strict=True):
            if not _NUMBER.match(r[j]):
                if must_be_number:
                    raise InputError(
                        f"{name}: not a number: {shown(r[j])}", path=path, line=lineno
                    )
                text_fields.add(name)
                break
            if not abs(float(r[j])) <= MAX_VALUE:
                raise InputError(
                    f"{name}: {shown(r[j])} is out of range (at most {MAX_VALUE:g} in "
                    "magnitude)",
                    path=path,
                    line=lineno,
                )
    return text_fields


def _check_end(
    state: str,
    rows: list,
    n_sets: int | None,
    lines: tuple[int, int, int, int],
    *,
    path: str | None,
) -> None:
    """Errors for a table cut short, empty, or with a wrong ``NUMBER_OF_SETS``."""
    last, fields_line, data_line, n_sets_line = lines
    if state == "id":
        raise InputError("empty file, expected a CGATS table", path=path)
    if state == "fields":
        raise InputError("END_DATA_FORMAT missing", path=path, line=fields_line or last)
    if state in ("header", "data"):
        raise InputError(
            "BEGIN_DATA ... END_DATA missing"
            if state == "header"
            else "END_DATA missing (file cut short?)",
            path=path,
            line=last,
        )
    if not rows:
        raise InputError(
            "no data sets between BEGIN_DATA and END_DATA", path=path, line=data_line
        )
    if n_sets is not None and n_sets != len(rows):
        raise InputError(
            f"NUMBER_OF_SETS is {n_sets} but {len(rows)} sets follow",
            path=path,
            line=n_sets_line,
        )


def parse_cgats(text: str, *, source: str | None = None) -> CgatsTable:
    """Parse CGATS text (the first table); see :func:`read_cgats`."""
    path = source
    lines = text.splitlines()
    file_id: str | None = None
    keywords: dict[str, str] = {}
    fields: list[str] = []
    rows: list[tuple[str, ...]] = []
    row_lines: list[int] = []
    quoted: set[int] = set()
    n_sets = None
    n_sets_line = data_line = 0
    state = "id"
    fields_line = 0
    for lineno, line in enumerate(lines, start=1):
        tokens = _tokenize(line, path=path, lineno=lineno)
        if not tokens:
            continue
        first = tokens[0][0]
        if state == "id":
            if len(tokens) != 1 or tokens[0][1] or first in _RESERVED:
                raise InputError(
                    f"expected a file identifier such as CTI3 or CGATS.17, found "
                    f"{line.strip()[:40]!r}",
                    path=path,
                    line=lineno,
                )
            file_id = first
            state = "header"
        elif state == "header":
            if first == "KEYWORD":
                continue  # declarations only; what follows defines the value
            if first == "NUMBER_OF_FIELDS":
                # Checked for form only: Argyll trusts the format list, and some of
                # its own reference files (ref/ColorChecker.ti2, ref/FograStrip3.ti1)
                # declare one field more than they list.
                _count(tokens, path=path, lineno=lineno)
            elif first == "NUMBER_OF_SETS":
                n_sets = _count(tokens, path=path, lineno=lineno)
                n_sets_line = lineno
            elif first == "BEGIN_DATA_FORMAT":
                if fields:
                    raise InputError("second BEGIN_DATA_FORMAT", path=path, line=lineno)
                fields_line = lineno
                state = _take_fields(tokens[1:], fields, path=path, lineno=lineno)
                if state == "header":
                    _check_fields(fields, path=path, lineno=fields_line)
            elif first == "BEGIN_DATA":
                if not fields:
                    raise InputError(
                        "BEGIN_DATA before BEGIN_DATA_FORMAT ... END_DATA_FORMAT",
                        path=path,
                        line=lineno,
                    )
                state = "data"
                data_line = lineno
            elif first in ("END_DATA", "END_DATA_FORMAT"):
                raise InputError(f"unexpected {first}", path=path, line=lineno)
            elif tokens[0][1]:
                raise InputError(
                    f"expected a keyword, found the string {shown(first)}",
                    path=path,
                    line=lineno,
                )
            else:
                keywords[first] = " ".join(t for t, _ in tokens[1:])
        elif state == "fields":
            state = _take_fields(tokens, fields, path=path, lineno=lineno)
            if state == "header":
                _check_fields(fields, path=path, lineno=fields_line)
        elif state == "data":
            if first == "END_DATA" and not tokens[0][1]:
                if len(tokens) > 1:
                    raise InputError("text after END_DATA", path=path, line=lineno)
                state = "done"
                break
            if len(tokens) != len(fields):
                raise InputError(
                    f"{len(tokens)} values, expected {len(fields)} (one per field: "
                    f"{' '.join(fields[:6])[:80]}{' ...' if len(fields) > 6 else ''})",
                    path=path,
                    line=lineno,
                )
            if len(rows) >= MAX_ROWS:
                raise InputError(
                    f"more than {MAX_ROWS} data sets", path=path, line=lineno
                )
            rows.append(tuple(t for t, _ in tokens))
            row_lines.append(lineno)
            quoted.update(j for j, (_, q) in enumerate(tokens) if q)
    _check_end(
        state,
        rows,
        n_sets,
        (len(lines), fields_line, data_line, n_sets_line),
        path=path,
    )
    text_fields = _text_fields(fields, rows, row_lines, quoted, path=path)
    assert file_id is not None
    return CgatsTable(
        file_id, keywords, tuple(fields), tuple(rows), frozenset(text_fields), source
    )


def read_cgats(path: str | PathLike[str]) -> CgatsTable:
    """Read the first table of a CGATS file (Argyll ``.ti3``, CGATS.17, IT8.7 ...).

    Returns
    -------
    CgatsTable
        Keywords, fields and rows; :meth:`CgatsTable.spectra` gives the spectral fields
        as :class:`~tunespec.core.spectra.Spectra` in ``0..1``.

    Raises
    ------
    InputError
        Naming the file and line: no identifier, an unterminated string, a row with the
        wrong number of values, a non-number in a numeric field (``RGB_*``, ``XYZ_*``,
        ``LAB_*``, spectral), duplicate field names, a ``NUMBER_OF_SETS`` that
        disagrees with the data, a missing ``END_DATA_FORMAT`` or ``END_DATA``.
        ``NUMBER_OF_FIELDS`` is not checked against the format list, as in Argyll
        (its own ``ref/ColorChecker.ti2`` declares 9 fields and lists 8).
    """
    path = Path(path)
    raw = read_bytes(path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        # Instrument software on Windows writes CGATS in the ANSI code page.
        text = raw.decode("latin-1")
    return parse_cgats(text, source=str(path))


def _triplet_columns(
    n: int, *, rgb: ArrayLike | None, xyz: ArrayLike | None, lab: ArrayLike | None
) -> dict[str, list[str]]:
    """``RGB_*`` (percent), ``XYZ_*`` and ``LAB_*`` columns of :func:`ti3_table`."""
    columns: dict[str, list[str]] = {}
    for what, arr, fields, percent in (
        ("rgb", rgb, ("RGB_R", "RGB_G", "RGB_B"), True),
        ("xyz", xyz, ("XYZ_X", "XYZ_Y", "XYZ_Z"), False),
        ("lab", lab, ("LAB_L", "LAB_A", "LAB_B"), False),
    ):
        if arr is None:
            continue
        a = np.asarray(arr, dtype=np.float64)
        if a.shape != (n, 3):
            raise InputError(f"{what} has shape {a.shape}, expected {(n, 3)}")
        if not np.all(np.isfinite(a)):
            raise InputError(f"{what} has non-finite values")
        conv = _percent_text if percent else _float_text
        for k, name in enumerate(fields):
            columns[name] = [conv(v) for v in a[:, k]]
    return columns


def _spectral_columns(
    names: list[str], reflectance: Spectra, kw: dict[str, str]
) -> dict[str, list[str]]:
    """``SPEC_nnn`` columns (percent); the ``SPECTRAL_*`` keywords go into ``kw``."""
    columns: dict[str, list[str]] = {}
    refl = reflectance.select(names)
    if not np.all(np.isfinite(refl.values)):
        raise InputError("reflectance has non-finite values")
    wl = refl.wavelength_nm
    if wl.size < 2:
        raise InputError("reflectance needs at least two wavelengths")
    refl.step_nm  # noqa: B018 - raises InputError for a non-equidistant grid
    spec_names = [ti3_field_name(w) for w in wl]
    if len(set(spec_names)) != len(spec_names):
        raise InputError(
            "wavelength step below 1 nm: Argyll's SPEC_nnn names would repeat"
        )
    kw["SPECTRAL_BANDS"] = str(wl.size)
    kw["SPECTRAL_START_NM"] = _float_text(wl[0])
    kw["SPECTRAL_END_NM"] = _float_text(wl[-1])
    for j, name in enumerate(spec_names):
        columns[name] = [_percent_text(v) for v in refl.values[:, j]]
    return columns


def ti3_table(
    names: Sequence[str],
    *,
    reflectance: Spectra | None = None,
    rgb: ArrayLike | None = None,
    xyz: ArrayLike | None = None,
    lab: ArrayLike | None = None,
    descriptor: str = "TuneSpec measurement",
    originator: str = "TuneSpec",
    created: datetime | str | None = None,
    device_class: str = "INPUT",
    keywords: Mapping[str, str] | None = None,
    extra_fields: Mapping[str, Iterable[str | float]] | None = None,
) -> CgatsTable:
    """An Argyll ``.ti3`` table of patches: names, camera RGB, XYZ, L*a*b*, spectra.

    Parameters
    ----------
    names : n names
        Patch names, written as ``SAMPLE_ID`` (matched by ``colverify``) and
        ``SAMPLE_NAME``; unique.
    reflectance : Spectra with n spectra, optional
        Reflectance factors ``0..1`` on an equidistant grid, taken in the order of
        ``names``; written as ``SPEC_nnn`` in percent.
    rgb : (n, 3), optional
        Camera responses in units of full scale (1.0 = saturation), written as
        ``RGB_R, RGB_G, RGB_B`` in percent (Argyll: "all device values shall be
        percentages"), with ``COLOR_REP "XYZ_RGB"`` (input device: PCS first).
    xyz : (n, 3), optional
        CIE XYZ with Y = 100 for the perfect diffuser.
    lab : (n, 3), optional
        CIE L*a*b*.
    descriptor, originator
        ``DESCRIPTOR`` and ``ORIGINATOR``.
    created
        ``CREATED`` (ISO 8601 for a datetime); ``None`` is now, in UTC.
    device_class
        ``DEVICE_CLASS``: ``"INPUT"`` for camera characterisation data.
    keywords
        More header keywords (declared with ``KEYWORD`` unless CGATS defines them).
    extra_fields
        More columns, name to n values (numbers, or text).

    Returns
    -------
    CgatsTable
        Write it with :func:`write_cgats`.

    Raises
    ------
    InputError
        Missing spectra, shapes that do not match ``names``, a non-equidistant grid,
        non-finite values.

    Examples
    --------
    >>> import numpy as np
    >>> s = Spectra(np.array([400.0, 410.0]), np.array([[0.5, 0.07]]), ("A1",))
    >>> t = ti3_table(["A1"], reflectance=s, rgb=[[0.25, 0.5, 1.0]], created="today")
    >>> print(format_cgats(t).split("BEGIN_DATA\\n")[1].splitlines()[0])
    A1 A1 25.0 50.0 100.0 50.0 7.0
    >>> read = parse_cgats(format_cgats(t)).spectra()
    >>> read.values.tolist() == s.values.tolist(), read.names
    (True, ('A1',))
    """
    names = [str(n) for n in names]
    n = len(names)
    if n == 0:
        raise InputError("no patches to write")
    if len(set(names)) != n:
        dup = sorted({x for x in names if names.count(x) > 1})
        raise InputError(f"duplicate patch names: {', '.join(dup)}")
    if created is None:
        created = datetime.now(UTC).replace(microsecond=0)
    kw: dict[str, str] = {
        "DESCRIPTOR": descriptor,
        "ORIGINATOR": originator,
        "CREATED": created.isoformat() if isinstance(created, datetime) else created,
        "DEVICE_CLASS": device_class,
    }
    if rgb is not None:
        kw["COLOR_REP"] = "XYZ_RGB"
    columns: dict[str, list[str]] = {"SAMPLE_ID": names, "SAMPLE_NAME": names}
    columns.update(_triplet_columns(n, rgb=rgb, xyz=xyz, lab=lab))
    if reflectance is not None:
        columns.update(_spectral_columns(names, reflectance, kw))
    for key, value in (keywords or {}).items():
        kw[str(key)] = str(value)
    text = {"SAMPLE_ID", "SAMPLE_NAME"}
    for name, values in (extra_fields or {}).items():
        vals = list(values)
        if len(vals) != n:
            raise InputError(f"extra field {name} has {len(vals)} values, expected {n}")
        if name in columns:
            raise InputError(f"extra field {name} is already written")
        if any(isinstance(v, str) for v in vals):
            text.add(name)
        columns[name] = [v if isinstance(v, str) else _float_text(v) for v in vals]
    fields = tuple(columns)
    rows = tuple(tuple(columns[f][i] for f in fields) for i in range(n))
    return CgatsTable("CTI3", kw, fields, rows, frozenset(text))
