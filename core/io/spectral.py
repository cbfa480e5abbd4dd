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
    percent by definition; anything else is percent when its largest value exceeds
    1.5, which no reflectance factor of a non-fluorescent surface does) and divided
    by 100, and ``meta["note"]`` says so for the command to report.
``sensitivity``
    channels ``R, G, B`` (also ``red, green, blue``, any case). A rawtoaces JSON
    that TuneSpec wrote is normalised to peak 1 with the absolute scale in its
    ``comments`` ("multiply by S for the absolute scale") and zeros where nothing was
    estimated ("set to 0 at 735-780 nm (not estimated)"): the scale is restored and
    those wavelengths dropped, so the JSON and the CSV of one calibration give the
    same estimates. A relative file without that scale has ``meta["relative"]``.
``illuminant``
    light-source spectra (resampled by band averaging, see
    :meth:`~tunespec.core.spectra.Spectra.resample`).
``spectra``
    anything else (basis functions with ``allow_negative``).

References
----------
ArgyllCMS ``doc/ti3_format.html``; X-Rite i1Profiler CGATS export (ISO 28178);
rawtoaces-data camera schema (``resources/cameras/SOURCE.md``); colour-science
``colour.io.tabular``.
"""

from __future__ import annotations

import re
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.core.errors import InputError
from tunespec.core.limits import MAX_REFLECTANCE, MAX_VALUE, loads_json, read_bytes
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "KINDS",
    "detect_format",
    "rawtoaces_spectra",
    "read_spectral",
    "to_reflectance_factor",
]

#: The kinds of spectral data :func:`read_spectral` checks.
KINDS = ("reflectance", "illuminant", "sensitivity", "spectra")

#: Largest value of a reflectance factor in 0..1 notation; above it a file is percent.
PERCENT_THRESHOLD = 1.5

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
        wl = np.array([float(k) for k in main])
        vals = np.array([main[k] for k in main], dtype=np.float64).T
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


def to_reflectance_factor(spectra: Spectra, *, source: str | None = None) -> Spectra:
    """Reflectances as factors 0..1: percent detected and divided by 100.

    A CGATS file says its scale (``meta["spectral_scale"]``); otherwise the data are
    percent when their largest value exceeds :data:`PERCENT_THRESHOLD`.
    ``meta["note"]`` reports a conversion.

    Raises
    ------
    InputError
        Negative values, or values above :data:`~tunespec.core.limits.MAX_REFLECTANCE`
        after the conversion.
    """
    meta = dict(spectra.meta)
    values = spectra.values
    peak = float(values.max(initial=0.0))
    if "spectral_scale" not in meta and peak > PERCENT_THRESHOLD:
        values = values / 100.0
        meta["spectral_scale"] = "100"
        meta["note"] = (
            f"reflectances in percent (largest value {peak:.4g}): divided by 100"
        )
    elif meta.get("spectral_scale") == "100":
        meta["note"] = "reflectances in percent (CGATS): divided by 100"
    if float(values.max(initial=0.0)) > MAX_REFLECTANCE:
        raise InputError(
            f"reflectance factor {float(values.max()):.4g} out of range (at most "
            f"{MAX_REFLECTANCE:g}, or {100 * MAX_REFLECTANCE:g} in percent)",
            path=source,
        )
    return Spectra(spectra.wavelength_nm, values, spectra.names, meta)


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
    spectra = _parse(text, detect_format(text), source, allow_negative, max_value)
    if kind == "reflectance":
        spectra = to_reflectance_factor(spectra, source=source)
    elif kind == "sensitivity":
        spectra = _as_sensitivity(spectra, source)
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
