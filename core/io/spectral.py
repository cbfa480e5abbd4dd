"""One reader for every spectral input: the format is found from the content.

:func:`read_spectral` takes any of

- **spectral CSV** (:mod:`.spectral_csv`: the project's own, colour-science's
  ``write_sds_to_csv``, spreadsheet exports with ``;`` or tabs, one spectrum per row);
- **CGATS** (:mod:`.cgats`): ArgyllCMS ``.ti3``/``.ti1``/``.cie``/``.sp`` with
  ``SPEC_nnn`` fields in percent, X-Rite i1Profiler / i1Pro exports with
  ``nm380``/``SPECTRAL_NM380`` fields, CGATS.17 and IT8.7 reference files;
- **rawtoaces-data JSON** (camera sensitivities, illuminants, training spectra);

whatever the file is called. Each *kind* of data then gets its own checks:

``reflectance``
    factors 0..1; a file in percent is detected (CGATS ``SPEC_nnn`` fields are
    percent by definition; anything else is percent when most of its spectra have
    their median above 1.5, which no reflectance factor of a non-fluorescent
    surface has) and divided by 100, and ``meta["note"]`` says so
    for the command to report. A value that breaks the unit (a typo such as 3.0 in
    a file of factors) or a spectrum in the other unit is refused with its line
    (:mod:`tunespec.core.plausibility`).
``sensitivity``
    channels ``R, G, B`` (also ``red, green, blue``, any case). A rawtoaces JSON
    that TuneSpec wrote is normalised to peak 1 with the absolute scale in its
    ``comments`` ("multiply by S for the absolute scale") and zeros where nothing was
    estimated ("set to 0 at 735-780 nm (not estimated)"): the scale is restored and
    those wavelengths dropped, so the JSON and the CSV of one calibration give the
    same estimates. A relative file without that scale has ``meta["relative"]``.
``illuminant``
    light-source spectra as a spectroradiometer reported them: the reading noise
    outside each spectrum's emission bands is set to zero at the file's own sampling
    (:func:`~tunespec.core.metering.suppress_meter_floor`), then they are resampled
    by band averaging (:meth:`~tunespec.core.spectra.Spectra.resample`).
``spectra``
    anything else (basis functions with ``allow_negative``).

References
----------
ArgyllCMS ``doc/ti3_format.html``; X-Rite i1Profiler CGATS export (ISO 28178);
rawtoaces-data camera schema (``resources/cameras/SOURCE.md``); colour-science
``colour.io.tabular``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.core.errors import InputError
from tunespec.core.limits import (
    MAX_REFLECTANCE,
    MAX_VALUE,
    loads_json,
    read_bytes,
    shown,
)
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "KINDS",
    "detect_format",
    "rawtoaces_spectra",
    "read_spectra_csv",
    "read_spectral",
    "to_reflectance_factor",
]

#: The kinds of spectral data :func:`read_spectral` checks.
KINDS = ("reflectance", "illuminant", "sensitivity", "spectra")

_CGATS_MARK = re.compile(r"^\s*BEGIN_DATA_FORMAT\b", re.MULTILINE)
_SCALE_NOTE = re.compile(r"multiply by ([0-9.eE+-]+) for the absolute scale")
_ZERO_NOTE = re.compile(
    r"set to 0 at ([0-9.]+(?:-[0-9.]+)?(?: and [0-9.]+(?:-[0-9.]+)?)?) nm"
)
_CHANNEL_ALIASES = {"r": "R", "g": "G", "b": "B", "red": "R", "green": "G", "blue": "B"}


def detect_format(text: str) -> str:
    """``"json"``, ``"cgats"`` or ``"csv"``, from the content.

    Examples
    --------
    >>> detect_format('{"header": {}}'), detect_format("CTI3\\nBEGIN_DATA_FORMAT\\n")
    ('json', 'cgats')
    >>> detect_format("wavelength_nm,A1\\n380,0.1\\n")
    'csv'
    """
    head = text.lstrip("\ufeff \t\r\n")
    if head.startswith("{"):
        return "json"
    if _CGATS_MARK.search(text):
        return "cgats"
    return "csv"


def _decode(raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        # Instrument software on Windows writes in the ANSI code page.
        return raw.decode("latin-1")


#: Largest value of a rawtoaces-data JSON (sensitivities normalised to peak 1, or
#: relative units near it).
MAX_RAWTOACES_VALUE = 1e6


def _bad_json_values(row: Any) -> str | None:
    """What is wrong with one wavelength's values in a rawtoaces JSON (or None):
    JSON ``true`` would read as 1, and sensitivities are never negative."""
    if not isinstance(row, list):
        return f"expected a list of numbers, got {shown(row)}"
    for v in row:
        if isinstance(v, bool) or not isinstance(v, int | float):
            return f"expected numbers, got {shown(v)}"
        if not (0 <= v <= MAX_RAWTOACES_VALUE):  # NaN fails too
            return (
                f"value {v:g} outside 0..{MAX_RAWTOACES_VALUE:g} (sensitivities are "
                "not negative; rawtoaces data are normalised to peak 1)"
            )
    return None


def rawtoaces_spectra(doc: Any, *, source: str | None = None) -> Spectra:
    """Spectra of a rawtoaces-data JSON document (``spectral_data.data.main``).

    ``meta`` holds ``manufacturer``, ``model``, ``units`` and, for a TuneSpec export,
    ``absolute_scale`` and ``not_estimated_nm`` (from the header's comments).

    Raises
    ------
    InputError
        Not that schema, non-numeric or non-finite values, ragged rows.
    """
    try:
        header = doc.get("header", {}) or {}
        spectral = doc["spectral_data"]
        main = spectral["data"]["main"]
        index = (spectral.get("index") or {}).get("main") or ["R", "G", "B"]
        for k, row in main.items():
            bad = _bad_json_values(row)
            if bad is not None:
                raise InputError(
                    f"spectral_data.data.main[{shown(k)}]: {bad}", path=source
                )
        wl = np.array([float(k) for k in main])
        vals = np.array([main[k] for k in main], dtype=np.float64).T
    except InputError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(
            f"not a rawtoaces-data JSON file (spectral_data.data.main: {exc})",
            path=source,
        ) from None
    if vals.ndim != 2 or vals.shape[0] != len(index) or wl.size < 2:
        raise InputError(
            f"spectral_data.data.main: expected {len(index)} values ({', '.join(map(str, index))}) "
            "per wavelength and at least two wavelengths",
            path=source,
        )
    if not (np.all(np.isfinite(vals)) and np.all(np.isfinite(wl))):
        raise InputError("non-finite values in spectral_data.data.main", path=source)
    if np.unique(wl).size != wl.size:
        raise InputError(
            "a wavelength appears twice in spectral_data.data.main", path=source
        )
    order = np.argsort(wl)
    comments = str(header.get("comments", "") or "")
    meta = {
        "format": "rawtoaces-data JSON",
        "manufacturer": str(header.get("manufacturer", "") or ""),
        "model": str(header.get("model", "") or ""),
        "units": str(spectral.get("units", "") or ""),
    }
    if m := _SCALE_NOTE.search(comments):
        try:
            scale = float(m.group(1))
        except ValueError:
            scale = math.nan
        if not 0 < scale <= MAX_VALUE:
            raise InputError(
                f"header.comments: absolute scale {shown(m.group(1))}, expected a "
                f"number in (0, {MAX_VALUE:g}]",
                path=source,
            )
        meta["absolute_scale"] = m.group(1)
    if m := _ZERO_NOTE.search(comments):
        meta["not_estimated_nm"] = m.group(1)
    return Spectra(wl[order], vals[:, order], tuple(str(c) for c in index), meta)


def _parse(
    text: str, fmt: str, source: str, allow_negative: bool, max_value: float
) -> Spectra:
    if fmt == "json":
        return rawtoaces_spectra(loads_json(text, path=source), source=source)
    if fmt == "cgats":
        from tunespec.core.io.cgats import parse_cgats

        table = parse_cgats(text, source=source)
        spectra = table.spectra()
        if spectra is None:
            raise InputError(
                "CGATS file without spectral fields (expected SPEC_380 ..., "
                "nm380 ... or SPECTRAL_NM380 ...)",
                path=source,
            )
        spectra.meta["format"] = f"CGATS ({table.file_id})"
        from tunespec.core.io.spectral_csv import ZERO_TOLERANCE

        tiny = np.abs(spectra.values) <= ZERO_TOLERANCE
        if tiny.any():
            spectra = spectra.with_values(np.where(tiny, 0.0, spectra.values))
        if not allow_negative and np.any(spectra.values < 0):
            raise InputError("negative spectral values", path=source)
        return spectra
    from tunespec.core.io.spectral_csv import parse_spectra_csv

    return parse_spectra_csv(
        text, source=source, allow_negative=allow_negative, max_value=max_value
    )


def to_reflectance_factor(
    spectra: Spectra,
    *,
    source: str | None = None,
    locate: Callable[[int, int], tuple[int | None, int | None]] | None = None,
) -> Spectra:
    """Reflectances as factors 0..1: percent detected and divided by 100.

    The unit comes from the bulk of the values, never from one maximum
    (:func:`tunespec.core.plausibility.reflectance_unit`): a CGATS file with
    ``SPEC_nnn`` fields declares percent and is checked against its values; a
    value that breaks the unit found (a typo) or a spectrum in the other unit is
    refused, named by line and column where ``locate(spectrum, wavelength_index)``
    can say. ``meta["note"]`` reports a conversion.

    Raises
    ------
    InputError
        Negative values, a value or a spectrum that breaks the file's unit, or
        values above :data:`~tunespec.core.limits.MAX_REFLECTANCE` after the
        conversion.
    """
    from tunespec.core.plausibility import reflectance_unit

    meta = dict(spectra.meta)
    given = float(meta.get("spectral_scale", "1") or 1)
    raw = spectra.values * given
    declared = True if meta.get("spectral_scale_declared") else None
    scale = reflectance_unit(
        raw,
        spectra.names,
        spectra.wavelength_nm,
        declared_percent=declared,
        source=source,
        locate=locate,
    )
    values = spectra.values if scale == given else raw / scale
    if scale == 100.0 and "spectral_scale" not in meta:
        bulk = float(np.percentile(raw, 90))
        meta["spectral_scale"] = "100"
        meta["note"] = (
            f"reflectances in percent (largest value {float(raw.max()):.4g}, 90 % of "
            f"the values up to {bulk:.4g}): divided by 100"
        )
    elif scale == 100.0:
        meta["spectral_scale"] = "100"
        meta["note"] = "reflectances in percent (CGATS): divided by 100"
    meta.pop("spectral_scale_declared", None)
    if float(values.max(initial=0.0)) > MAX_REFLECTANCE:
        raise InputError(
            f"reflectance factor {float(values.max()):.4g} out of range (at most "
            f"{MAX_REFLECTANCE:g}, or {100 * MAX_REFLECTANCE:g} in percent)",
            path=source,
        )
    return Spectra(spectra.wavelength_nm, values, spectra.names, meta)


def _locator(
    text: str, fmt: str, spectra: Spectra
) -> Callable[[int, int], tuple[int | None, int | None]]:
    """``(spectrum, wavelength index) -> (line, column)`` of a value in ``text``,
    for the messages of :func:`to_reflectance_factor` (best effort)."""

    def locate(k: int, j: int) -> tuple[int | None, int | None]:
        try:
            if fmt == "cgats":
                lines = text.splitlines()
                start = next(
                    n for n, ln in enumerate(lines) if ln.strip() == "BEGIN_DATA"
                )
                data = [
                    n + 1
                    for n in range(start + 1, len(lines))
                    if lines[n].strip() and not lines[n].lstrip().startswith("#")
                ]
                return data[k], None
            if fmt == "csv":
                from tunespec.core.io.spectral_csv import numbered_rows

                rows = numbered_rows(text)
                if spectra.meta.get("format", "").endswith("(wavelengths down)"):
                    return rows[1 + j][0], k + 2
                return rows[1 + k][0], None
        except (StopIteration, IndexError, InputError):
            pass
        return None, None

    return locate


def _as_sensitivity(spectra: Spectra, source: str) -> Spectra:
    """Channels ``R, G, B``; a TuneSpec rawtoaces JSON back on its absolute scale."""
    from tunespec.core.errors import check_names

    renamed = tuple(_CHANNEL_ALIASES.get(n.strip().lower(), n) for n in spectra.names)
    if len(set(renamed)) == len(renamed):
        spectra = Spectra(spectra.wavelength_nm, spectra.values, renamed, spectra.meta)
    check_names(
        ("R", "G", "B"),
        spectra.names,
        "missing channel(s) {names}; expected R, G, B",
        path=source,
    )
    s = spectra.select(["R", "G", "B"])
    meta = dict(s.meta)
    values, wl = s.values, s.wavelength_nm
    if "absolute_scale" in meta:
        values = values * float(meta["absolute_scale"])
        meta["units"] = "absolute"
    if "not_estimated_nm" in meta:
        keep = np.ones(wl.size, dtype=bool)
        for part in meta["not_estimated_nm"].split(" and "):
            lo, _, hi = part.partition("-")
            keep &= ~((wl >= float(lo) - 1e-6) & (wl <= float(hi or lo) + 1e-6))
        wl, values = wl[keep], values[:, keep]
    if meta.get("units") == "relative":
        meta["relative"] = "1"
    if meta.get("spectral_scale") == "100":
        meta["note"] = (
            "sensitivities in CGATS SPEC_ fields, percent by the format: divided by "
            "100 (estimate checks the result against the responses)"
        )
    return Spectra(wl, values, ("R", "G", "B"), meta)


def read_spectral(
    path: str | PathLike[str],
    grid: Grid | None = None,
    *,
    kind: str = "spectra",
    allow_negative: bool = False,
    max_value: float = MAX_VALUE,
    average: bool | None = None,
) -> Spectra:
    """Read spectral data of any supported format and check it as ``kind``.

    Parameters
    ----------
    path
        CSV, CGATS or rawtoaces JSON (detected from the content).
    grid
        Working grid to resample onto; ``None`` keeps the file's wavelengths.
    kind
        One of :data:`KINDS` (see the module docstring).
    allow_negative
        Accept negative values (signed basis functions).
    max_value
        Largest magnitude accepted in the file.
    average
        Band-average onto ``grid`` (default: for illuminants).

    Returns
    -------
    Spectra
        ``meta``: ``source``, ``format``, and what was converted (``note``).

    Raises
    ------
    InputError
        With the file, the line and what was expected.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, not {kind!r}")
    path = Path(path)
    source = str(path)
    text = _decode(read_bytes(path))
    fmt = detect_format(text)
    spectra = _parse(text, fmt, source, allow_negative, max_value)
    if fmt == "csv":
        spectra = _with_comment_meta(spectra, text, source, kind)
    if kind == "reflectance":
        spectra = to_reflectance_factor(
            spectra, source=source, locate=_locator(text, fmt, spectra)
        )
    elif kind == "sensitivity":
        spectra = _as_sensitivity(spectra, source)
    elif kind == "illuminant":
        # the reading noise goes at the instrument's own sampling, before anything
        # resamples it (core.metering); a file written resampled says what it was
        from tunespec.core.metering import suppress_meter_floor

        spectra = suppress_meter_floor(spectra)
    spectra = Spectra(
        spectra.wavelength_nm,
        spectra.values,
        spectra.names,
        {**spectra.meta, "source": source},
    )
    if grid is None:
        return spectra
    if average is None:
        average = kind == "illuminant"
    return spectra.resample(grid, source=source, average=average)


def _with_comment_meta(spectra: Spectra, text: str, source: str, kind: str) -> Spectra:
    """``spectra`` with what its CSV's comment lines state
    (:data:`~tunespec.core.io.spectral_csv.COMMENT_META`), checked: the f-number of
    a processed session's frames whatever the file is read as (the pipeline reads
    its own illuminants back as plain spectra, not to clean them twice), the
    reading noise and step of illuminants."""
    from tunespec.core.io.raw import F_NUMBER_META, F_NUMBER_RANGE
    from tunespec.core.io.spectral_csv import COMMENT_META, comment_values
    from tunespec.core.metering import parse_reading_meta

    keys = COMMENT_META if kind == "illuminant" else (F_NUMBER_META,)
    meta = dict(spectra.meta)
    for key, (value, lineno) in comment_values(text, keys).items():
        if key == F_NUMBER_META:
            try:
                f_number = float(value)
            except ValueError:
                f_number = math.nan  # refused below, as the text it is
            lo, hi = F_NUMBER_RANGE
            if not lo <= f_number <= hi:  # NaN too
                raise InputError(
                    f"{key}: expected an f-number in [{lo:g}, {hi:g}], got "
                    f"{shown(value)}",
                    path=source,
                    line=lineno,
                )
            meta[key] = f"{f_number:g}"
            continue
        try:
            meta |= parse_reading_meta({key: value}, spectra.names)
        except ValueError as exc:
            raise InputError(f"{key}: {exc}", path=source, line=lineno) from None
    return Spectra(spectra.wavelength_nm, spectra.values, spectra.names, meta)


def read_spectra_csv(
    path: str | PathLike[str],
    grid: Grid | None = None,
    *,
    allow_negative: bool = False,
    max_value: float = MAX_VALUE,
    average: bool = False,
) -> Spectra:
    """Read spectral data (CSV, CGATS or rawtoaces JSON) as ``kind="spectra"`` and
    optionally resample it (point sampling unless ``average``).

    The older name, used by the numerics' callers: :func:`read_spectral` with no
    kind-specific checks. (It lived in :mod:`tunespec.core.spectra`, which no longer
    imports its readers.)
    """
    return read_spectral(
        path, grid, allow_negative=allow_negative, max_value=max_value, average=average
    )
