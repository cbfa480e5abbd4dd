"""Exports of a measurement that other tools read: CSV, rawtoaces JSON, Argyll ``.ti3``.

One measurement gives these files (:func:`export_measurement`), each readable by
TuneSpec again:

===============================  =====================================================
``sensitivities.csv``            estimated camera sensitivities, spectral CSV
                                 (``wavelength_nm,R,G,B``, absolute scale: Eq. 1 with
                                 them predicts the responses)
``sensitivities.csv.meta.json``  what the CSV cannot hold: the estimator and the
                                 fitted spectroradiometer shift (``spd_shift_nm``),
                                 which ``tunespec estimate`` undoes on the SPDs
``sensitivities.json``           the same in the rawtoaces-data camera schema (as
                                 ``resources/cameras/*.json``), normalised to peak 1,
                                 on 380-780 nm at 5 nm (all rawtoaces reads; 0 where
                                 not estimated); the absolute scale is in its
                                 comments, where TuneSpec's reader finds it
``sensitivities.json.meta.json`` the side file again, for the JSON
``reflectances.csv``             estimated reflectances, spectral CSV (0..1)
``reflectances.ti3``             ArgyllCMS CGATS: names, camera RGB (percent), XYZ and
                                 L*a*b* (D50, 2°), spectra (percent)
``reference_reflectances.csv``   the reference measurements compared with, if given
``reference_reflectances.ti3``   the same as ``.ti3``, on the estimate's grid (as
                                 Table 2 compares), so ``colverify`` of the two
                                 ``.ti3`` files reproduces Table 2's CIEDE2000
``responses.csv``                camera responses, long format (``core.responses``)
``illuminants.csv``              the LED spectra used, spectral CSV
``table1_prediction.csv``        Table 1: response prediction errors per channel
                                 (fitted and, if any, held-aside patches)
``table2_reflectance.csv``       Table 2: CIEDE2000 (D50) and spectral RMS per patch
===============================  =====================================================

Numbers are written with :func:`repr`, so every file reads back bit for bit. The
camera characterisation (``chart_camera.ti3``, ``camera_transforms.json/.csv``) is
written by :mod:`tunespec.core.io.camera_export`.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
Tables 1 and 2; rawtoaces-data camera schema (``resources/cameras/SOURCE.md``).
"""

from __future__ import annotations

import csv
import json
import uuid
from collections.abc import Mapping
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from numpy.typing import NDArray

from tunespec.core.atomic import atomic_open, atomic_write_text
from tunespec.core.colorimetry import lab_d50, xyz_d50
from tunespec.core.errors import InputError, check_names
from tunespec.core.io.cgats import CgatsTable, ti3_table, write_cgats
from tunespec.core.io.responses_csv import write_responses_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.limits import dumps_json, read_json, shown
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid, Spectra

if TYPE_CHECKING:
    from tunespec.core.colorimetry import ReflectanceStats


class TableStats(Protocol):
    """Table 1's statistics as the writers take them: ``core.stats``'
    ``PredictionStats`` or ``CalibrationReport`` (typed by what they offer, so this
    writer does not import the statistics, which import the calibration, which
    reads and writes through this module)."""

    def as_dict(self) -> dict[str, Any]: ...


__all__ = [
    "EXPORT_NAMES",
    "RAWTOACES_GRID",
    "curves_document",
    "document_curves",
    "export_measurement",
    "onto_grid",
    "parse_sensitivity_meta",
    "read_sensitivity_meta",
    "read_spd_shift",
    "reflectance_ti3",
    "sensitivity_meta_document",
    "sensitivity_meta_path",
    "sensitivity_rawtoaces_document",
    "tunespec_version",
    "write_colorimetry_csv",
    "write_prediction_stats_csv",
    "write_reflectance_stats_csv",
    "write_sensitivities_csv",
    "write_sensitivity_json",
    "write_sensitivity_meta",
]

#: File name of each export kind (the keys of :func:`export_measurement`'s result).
EXPORT_NAMES: dict[str, str] = {
    "sensitivities_csv": "sensitivities.csv",
    "sensitivities_meta": "sensitivities.csv.meta.json",
    "sensitivities_json": "sensitivities.json",
    "sensitivities_json_meta": "sensitivities.json.meta.json",
    "reflectances_csv": "reflectances.csv",
    "reflectances_ti3": "reflectances.ti3",
    "reference_csv": "reference_reflectances.csv",
    "reference_ti3": "reference_reflectances.ti3",
    "responses_csv": "responses.csv",
    "illuminants_csv": "illuminants.csv",
    "table1_csv": "table1_prediction.csv",
    "table2_csv": "table2_reflectance.csv",
}

_TABLE1_ROWS = ("Red", "Green", "Blue", "RGB")

#: The grid rawtoaces reads: ``Spst::loadSpst`` exits unless a camera file has exactly
#: 81 samples, 380-780 nm at 5 nm (rawtoaces 1.x ``lib/rta.cpp``).
RAWTOACES_GRID = Grid(380.0, 780.0, 5.0)


#: The calibration's records a side file keeps as they are (JSON in
#: ``Spectra.meta``): the per-LED corrections, the responses' systematic errors, the
#: readings' replicates and the chart session's white background.
_META_KEYS = (
    "led_correction",
    "excess_variance",
    "reading_replicates",
    "white_background",
)
#: What a calibration found about itself, kept beside its curves for every estimate
#: to repeat (lists of one-line findings): the plausibility checks accepted with
#: ``--force`` and its warnings (a poor fit, the self-check's).
NOTE_KEYS = ("forced", "warnings")
#: Most findings a side file may hold, and their longest line.
_MAX_NOTES, _MAX_NOTE_CHARS = 100, 2000


def sensitivity_meta_path(sensitivity_csv: str | PathLike[str]) -> Path:
    """``SENSITIVITIES.csv.meta.json``: what a sensitivities CSV cannot hold."""
    p = Path(sensitivity_csv)
    return p.with_name(p.name + ".meta.json")


def write_sensitivities_csv(
    path: str | PathLike[str],
    sensitivity: Spectra,
    covariance: NDArray[np.float64] | None = None,
) -> Path:
    """Write calibrated sensitivities: the spectral CSV and its ``.meta.json``.

    The one writer of a calibration's result (``tunespec calibrate``, the exports and
    the wizard's ``calibration/`` folder): the CSV holds the curves, the side file the
    estimator, the fitted SPD shift or LED corrections and, if given, the covariance
    (:func:`write_sensitivity_meta`), which ``estimate`` and the report need.
    """
    write_spectra_csv(sensitivity, path)
    write_sensitivity_meta(path, sensitivity, covariance)
    return Path(path)


def write_sensitivity_meta(
    sensitivity_csv: str | PathLike[str],
    sensitivity: Spectra,
    covariance: NDArray[np.float64] | None = None,
    *,
    curves: bool = False,
) -> Path:
    """Write the estimator and the fitted SPD shift beside a sensitivities CSV.

    ``sensitivity.meta`` as :func:`~tunespec.core.sensitivity.estimate_camera_sensitivity`
    fills it (``source``, ``spd_shift_nm``). ``curves``: the sensitivities too, for
    a file that holds them resampled (:func:`sensitivity_meta_document`).
    """
    path = sensitivity_meta_path(sensitivity_csv)
    doc = sensitivity_meta_document(sensitivity, covariance, curves=curves)
    atomic_write_text(path, dumps_json(doc))
    return path


def curves_document(sensitivity: Spectra) -> dict[str, Any]:
    """Sensitivities as a calibration JSON and a side file hold them, every digit:
    ``{"wavelength_nm": [...], "sensitivity": {"R": [...], ...}}``
    (:func:`document_curves` reads them)."""
    return {
        "wavelength_nm": [float(x) for x in sensitivity.wavelength_nm],
        "sensitivity": {
            n: [float(v) for v in row]
            for n, row in zip(sensitivity.names, sensitivity.values, strict=True)
        },
    }


def document_curves(doc: Mapping[str, Any], path: str | PathLike[str]) -> Spectra:
    """The sensitivities a calibration JSON or a side file holds
    (:func:`curves_document`).

    Raises
    ------
    InputError
        Naming ``path``: the keys missing or malformed, non-finite values.
    """
    try:
        wl = np.asarray(doc["wavelength_nm"], dtype=np.float64)
        curves = doc["sensitivity"]
        values = np.asarray([curves[c] for c in ("R", "G", "B")], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise InputError(
            "expected 'wavelength_nm': [...] and 'sensitivity': {'R': [...], "
            "'G': [...], 'B': [...]} of equal lengths",
            path=path,
        ) from None
    if values.ndim != 2 or values.shape[1] != wl.size or wl.size < 2:
        raise InputError(
            f"sensitivity curves of {values.shape[-1]} samples for "
            f"{wl.size} wavelengths",
            path=path,
        )
    if not np.all(np.isfinite(values)) or not np.all(np.isfinite(wl)):
        raise InputError("sensitivity holds non-finite values", path=path)
    return Spectra(wl, values, ("R", "G", "B"), {"source": str(path)})


def sensitivity_meta_document(
    sensitivity: Spectra,
    covariance: NDArray[np.float64] | None = None,
    *,
    curves: bool = False,
) -> dict[str, Any]:
    """What :func:`write_sensitivity_meta` writes, as a dict.

    ``curves`` adds the sensitivities themselves at full precision
    (``wavelength_nm``, ``sensitivity``: ``{"R": [...], ...}``), as a calibration
    JSON holds them beside the same keys. The side file of a rawtoaces JSON carries
    them: that schema's 5 nm samples lose what Eq. 1 and the covariance need from
    the calibration's 2 nm curves, and ``core.calibration.calibration_curves``
    takes them back from here.
    """
    wl = sensitivity.wavelength_nm
    doc: dict[str, Any] = {
        "estimated_by": sensitivity.meta.get("source", ""),
        "grid": f"{wl[0]:g}:{wl[-1]:g}:{sensitivity.step_nm:g}",
        "spd_shift_nm": float(sensitivity.meta.get("spd_shift_nm", 0.0)),
    }
    if curves:
        doc |= curves_document(sensitivity)
    for key in (*_META_KEYS, *NOTE_KEYS):
        if key in sensitivity.meta:
            doc[key] = json.loads(sensitivity.meta[key])
    if covariance is not None:
        doc["covariance"] = {
            "parameters": "s_R, s_G, s_B at wavelength_nm, then log gain and "
            "shift_nm of each LED in led_correction order",
            "wavelength_nm": [float(x) for x in wl],
            # every digit: the estimate weighs the responses by it (Eq. 5's K_e), so
            # a calibration read back gives the numbers the one in memory gave
            "values": [[float(v) for v in row] for row in covariance],
        }
    return doc


#: Columns of the colorimetry CSV written beside estimated reflectances.
COLORIMETRY_COLUMNS = (
    "patch",
    "X",
    "Y",
    "Z",
    "L",
    "a",
    "b",
    "u_X",
    "u_Y",
    "u_Z",
    "u_L",
    "u_a",
    "u_b",
)


def write_colorimetry_csv(
    path: str | PathLike[str], names: tuple[str, ...], unc: Any
) -> Path:
    """CIE XYZ and CIELAB (D50) with their standard uncertainties, one row per patch.

    Columns :data:`COLORIMETRY_COLUMNS`: ``X, Y, Z`` (0-100), ``L, a, b`` and ``u_*``
    the standard uncertainty of each (k = 1; a 95 % interval is +-1.96 u).
    ``unc`` is a :class:`tunespec.core.uncertainty.ReflectanceUncertainty`.
    """
    path = Path(path)
    rows = [COLORIMETRY_COLUMNS]
    for j, name in enumerate(names):
        vals = [*unc.xyz[j], *unc.lab[j], *unc.xyz_std[j], *unc.lab_std[j]]
        rows.append((name, *(f"{float(v):.6g}" for v in vals)))
    with atomic_open(path, newline="") as fh:
        csv.writer(fh).writerows(rows)
    return path


def read_sensitivity_meta(sensitivity_csv: str | PathLike[str]) -> dict[str, Any]:
    """The side file of a sensitivities CSV as a dict (``{}`` when there is none).

    Keys: ``spd_shift_nm``, ``excess_variance`` (the responses' systematic errors,
    :class:`~tunespec.core.excess.ExcessVariance` as a dict), and from a ``"bayes"``
    calibration ``led_correction`` and ``covariance`` (an array); ``curves`` (a
    :class:`Spectra`) where the side file holds the calibration's own curves
    (:func:`sensitivity_meta_document`); ``meta_path`` names the file for messages.
    """
    path = sensitivity_meta_path(sensitivity_csv)
    if not path.exists():
        return {}
    return parse_sensitivity_meta(read_json(path), path)


def parse_sensitivity_meta(doc: Any, path: str | PathLike[str]) -> dict[str, Any]:
    """:func:`read_sensitivity_meta` of a document already read (``path`` names it
    in messages and as ``meta_path``)."""
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object", path=path)
    try:
        spd_shift_nm = float(doc.get("spd_shift_nm", 0.0))
    except (TypeError, ValueError):
        raise InputError(
            "expected a JSON object with a number spd_shift_nm", path=path
        ) from None
    out: dict[str, Any] = {"meta_path": str(path), "spd_shift_nm": spd_shift_nm}
    for key in _META_KEYS:
        if key in doc:
            out[key] = doc[key]
    for key in NOTE_KEYS:
        if key in doc:
            out[key] = _notes(doc[key], key, path)
    if "sensitivity" in doc:
        out["curves"] = document_curves(doc, path)
    cov = doc.get("covariance")
    if cov is not None:
        try:
            values = np.asarray(cov["values"], dtype=np.float64)
            wl = np.asarray(cov["wavelength_nm"], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            raise InputError(
                "covariance: expected {'wavelength_nm': [...], 'values': [[...]]}",
                path=path,
            ) from None
        if (
            values.ndim != 2
            or values.shape[0] != values.shape[1]
            or not np.all(np.isfinite(values))
        ):
            raise InputError("covariance: expected a finite square matrix", path=path)
        problem = covariance_problem(cov["values"], values)
        if problem:
            raise InputError(f"covariance: {problem}", path=path)
        out["covariance"] = values
        out["covariance_wavelength_nm"] = wl
    return out


def _notes(value: Any, key: str, path: str | PathLike[str]) -> list[str]:
    """A side file's list of findings (:data:`NOTE_KEYS`), checked."""
    if (
        not isinstance(value, list)
        or len(value) > _MAX_NOTES
        or not all(isinstance(v, str) and len(v) <= _MAX_NOTE_CHARS for v in value)
    ):
        raise InputError(
            f"{key}: expected a list of at most {_MAX_NOTES} lines of text",
            path=path,
        )
    return value


#: Largest magnitude of a calibration covariance entry (sensitivities of peak ~1-10
#: and log gains: variances far below 1).
MAX_COVARIANCE = 1e6


def covariance_problem(raw: Any, values: NDArray[np.float64]) -> str:
    """What makes a covariance matrix read from a file impossible ("" if nothing):
    booleans (JSON ``true`` reads as 1), entries beyond :data:`MAX_COVARIANCE`, a
    negative variance, asymmetry, or a negative eigenvalue beyond rounding (not
    positive semi-definite: a sign flipped)."""
    if any(isinstance(v, bool) for row in raw for v in row):
        return "expected numbers, found true/false"
    if values.size == 0:
        return "empty matrix"
    big = float(np.max(np.abs(values)))
    if big > MAX_COVARIANCE:
        return f"entry {big:g} beyond any calibration's (at most {MAX_COVARIANCE:g})"
    diag = np.diag(values)
    if np.any(diag < 0):
        k = int(np.argmin(diag))
        return f"negative variance {diag[k]:g} at row {k + 1}"
    tol = 1e-6 * max(big, 1e-300)
    if float(np.max(np.abs(values - values.T))) > tol:
        return "not symmetric"
    lowest = float(np.linalg.eigvalsh(values)[0])
    if lowest < -tol:
        return f"not positive semi-definite (eigenvalue {lowest:.3g}): not a covariance"
    return ""


def read_spd_shift(sensitivity_csv: str | PathLike[str]) -> float:
    """The SPD shift stored beside a sensitivities CSV (0 when there is none).

    Raises
    ------
    InputError
        The side file exists but is not a JSON object with a number ``spd_shift_nm``.
    """
    path = sensitivity_meta_path(sensitivity_csv)
    if not path.exists():
        return 0.0
    doc = read_json(path)
    try:
        return float(doc.get("spd_shift_nm", 0.0))
    except (AttributeError, TypeError, ValueError):
        raise InputError(
            "expected a JSON object with a number spd_shift_nm", path=path
        ) from None


def tunespec_version() -> str:
    """The installed TuneSpec version (``importlib.metadata``), or ``"unknown"``."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("tunespec")
    except PackageNotFoundError:
        return "unknown"


def _now() -> datetime:
    return datetime.now(UTC).replace(microsecond=0)


def _iso(created: datetime | str | None) -> str:
    if created is None:
        created = _now()
    if isinstance(created, str):
        return created
    return created.isoformat().replace("+00:00", "Z")


def sensitivity_rawtoaces_document(
    sensitivity: Spectra,
    *,
    manufacturer: str = "",
    model: str = "",
    normalize: bool = True,
    description: str = "camera spectral sensitivity data",
    document_creator: str = "TuneSpec",
    laboratory: str = "",
    measurement_equipment: str | None = None,
    comments: str = "",
    license: str = "CC-BY-4.0",
    unique_identifier: str | None = None,
    created: datetime | str | None = None,
    grid: Grid | None = RAWTOACES_GRID,
) -> dict[str, Any]:
    """Camera sensitivities as a rawtoaces-data JSON document (schema 1.0.0).

    Parameters
    ----------
    sensitivity : Spectra R, G, B
        Sensitivities on any grid.
    manufacturer, model
        The camera, e.g. ``"Canon"``, ``"EOS 5D Mark III"``.
    normalize
        Scale to peak 1 (rawtoaces' "relative" units, like the shipped files); the
        factor that restores the absolute scale goes into ``comments``.
    description, document_creator, laboratory, measurement_equipment, comments, license
        Header fields of the schema. ``license`` (required by the schema: "usage
        license of the document") defaults to CC-BY-4.0, the licence under which
        rawtoaces-data and most published sensitivity sets are shared; it is the
        data's, not the software's (Apache-2.0), and ``export-rawtoaces --license``
        sets another.
    unique_identifier
        A UUID; ``None`` makes a random one.
    created
        ``document_creation_date``; ``None`` is now (UTC).
    grid
        Wavelengths written (the keys, ``"380"``, ``"382.5"``): by default
        :data:`RAWTOACES_GRID`, the only one rawtoaces accepts. The sensitivities are
        interpolated linearly onto it and set to 0 where they were not estimated
        (e.g. 735-780 nm from a 380-730 nm estimate), which ``comments`` says.
        ``None`` writes the sensitivities' own wavelengths.

    Returns
    -------
    dict
        ``{"header": {...}, "spectral_data": {"units": "relative", "index": {"main":
        ["R", "G", "B"]}, "data": {"main": {"380": [r, g, b], ...}}}}``.

    Raises
    ------
    InputError
        If the spectra are not ``R, G, B`` or hold non-finite values.
    """
    try:
        rgb = sensitivity.select(["R", "G", "B"])
    except InputError:
        raise InputError(
            f"sensitivities must be named R, G, B, not {', '.join(sensitivity.names)}",
            path=sensitivity.meta.get("source"),
        ) from None
    values = rgb.values
    if not np.all(np.isfinite(values)):
        raise InputError("sensitivities hold non-finite values")
    note = comments
    wavelength_nm = rgb.wavelength_nm
    if grid is not None:
        values, padded = onto_grid(wavelength_nm, values, grid.wavelength_nm)
        wavelength_nm = grid.wavelength_nm
        if padded:
            zero = f"set to 0 at {padded} nm (not estimated)"
            note = f"{note}; {zero}" if note else zero
    if normalize:
        peak = float(values.max())
        if peak <= 0:
            raise InputError("sensitivities are all zero or negative")
        values = values / peak
        scale = f"normalised to peak 1; multiply by {peak!r} for the absolute scale"
        note = f"{note}; {scale}" if note else scale
    data = {
        f"{wl:g}": [float(v) for v in values[:, j]]
        for j, wl in enumerate(wavelength_nm)
    }
    return {
        "header": {
            "schema_version": "1.0.0",
            "manufacturer": manufacturer,
            "model": model,
            "description": description,
            "document_creator": document_creator,
            "unique_identifier": unique_identifier or str(uuid.uuid4()),
            "measurement_equipment": measurement_equipment,
            "laboratory": laboratory,
            "document_creation_date": _iso(created),
            "comments": note,
            "license": license or "CC-BY-4.0",
        },
        "spectral_data": {
            "units": "relative",
            "reflection_geometry": None,
            "transmission_geometry": None,
            "bandwidth_FWHM": None,
            "bandwidth_corrected": None,
            "index": {"main": ["R", "G", "B"]},
            "data": {"main": data},
        },
    }


def onto_grid(
    wavelength_nm: np.ndarray, values: np.ndarray, target: np.ndarray
) -> tuple[np.ndarray, str]:
    """``values`` (3, n_wl) linearly onto the wavelengths ``target``, 0 outside the
    data's range: the rawtoaces JSON's samples of a calibration's curves.

    Returns the values (3, target.size) and the zero-filled ranges as text ("" if
    none).
    """
    out = np.stack(
        [np.interp(target, wavelength_nm, v, left=0.0, right=0.0) for v in values]
    )
    tol = 1e-6
    outside = (target < wavelength_nm[0] - tol) | (target > wavelength_nm[-1] + tol)
    ranges = []
    for side in (
        target[outside & (target < wavelength_nm[0])],
        target[outside & (target > wavelength_nm[-1])],
    ):
        if side.size:
            ranges.append(
                f"{side[0]:g}-{side[-1]:g}" if side.size > 1 else f"{side[0]:g}"
            )
    return out, " and ".join(ranges)


def write_sensitivity_json(
    sensitivity: Spectra, path: str | PathLike[str], **header: Any
) -> Path:
    """Write :func:`sensitivity_rawtoaces_document` to ``path``; returns the path.

    ``tunespec.core.datasets.read_rawtoaces_json`` reads it back (values bit for bit
    when ``normalize=False``). colour-science 0.4.7 has no reader for this schema.
    """
    doc = sensitivity_rawtoaces_document(sensitivity, **header)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, dumps_json(doc, indent=4))
    return path


def _write_rows(path: Path, header: list[str], rows: list[list[str]]) -> Path:
    with atomic_open(path, newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        w.writerows(rows)
    return path


def write_prediction_stats_csv(
    stats: TableStats | Mapping[str, Any],
    path: str | PathLike[str],
) -> Path:
    """Table 1 as CSV: ``patches,channel,mean,max,p95,n_stimuli``.

    Rows Red, Green, Blue, RGB of the ``fitted`` patches, then, for a calibration
    report with held-aside patches, the same rows for ``held_out``.

    Parameters
    ----------
    stats
        A :class:`~tunespec.core.stats.PredictionStats` (its rows are ``fitted``), a
        :class:`~tunespec.core.stats.CalibrationReport`, or the ``as_dict()`` of either.
    path
        Output file.
    """
    d = stats if isinstance(stats, Mapping) else stats.as_dict()
    parts = [("fitted", d.get("training", d))]
    if d.get("held_out") is not None:
        parts.append(("held_out", d["held_out"]))
    rows = []
    try:
        for label, t in parts:
            n = str(int(t["n_stimuli"]))
            rows += [
                [
                    label,
                    row,
                    *(repr(float(t[row][k])) for k in ("mean", "max", "p95")),
                    n,
                ]
                for row in _TABLE1_ROWS
            ]
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"not Table 1 statistics (missing {exc})") from None
    header = ["patches", "channel", "mean", "max", "p95", "n_stimuli"]
    return _write_rows(Path(path), header, rows)


def write_reflectance_stats_csv(
    stats: ReflectanceStats | Mapping[str, Any], path: str | PathLike[str]
) -> Path:
    """Table 2 as CSV: ``patch,delta_e00_d50,spectral_rms``, then ``average`` and ``max``.

    Parameters
    ----------
    stats
        A :class:`~tunespec.core.colorimetry.ReflectanceStats` or its ``as_dict()``.
    path
        Output file.
    """
    d = stats if isinstance(stats, Mapping) else stats.as_dict()
    try:
        rows = [
            [str(name), repr(float(v["delta_e00"])), repr(float(v["spectral_rms"]))]
            for name, v in d["patches"].items()
        ]
        for label in ("average", "max"):
            rows.append(
                [
                    label,
                    repr(float(d[label]["delta_e00"])),
                    repr(float(d[label]["spectral_rms"])),
                ]
            )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"not Table 2 statistics (missing {exc})") from None
    return _write_rows(Path(path), ["patch", "delta_e00_d50", "spectral_rms"], rows)


def _responses_rgb(
    responses: Responses, names: tuple[str, ...], illuminant: str | None
) -> tuple[np.ndarray, str]:
    if illuminant is None:
        if len(responses.illuminants) != 1:
            raise InputError(
                "the responses hold several illuminants; name the one whose RGB goes "
                f"into the .ti3 (--illuminant): {', '.join(responses.illuminants)}"
            )
        illuminant = responses.illuminants[0]
    if illuminant not in responses.illuminants:
        raise InputError(
            f"illuminant {shown(illuminant)} not in the responses "
            f"({', '.join(responses.illuminants)})"
        )
    check_names(names, responses.patches, "{n} patch(es) have no responses: {names}")
    sub = responses.subset(list(names), [illuminant])
    return sub.rgb[:, 0, :], illuminant


def reflectance_ti3(
    reflectance: Spectra,
    *,
    responses: Responses | None = None,
    illuminant: str | None = None,
    descriptor: str = "TuneSpec estimated reflectances",
    created: datetime | str | None = None,
    keywords: Mapping[str, str] | None = None,
    spectra: bool = True,
    uncertainty: Any = None,
) -> CgatsTable:
    """An Argyll ``.ti3`` of reflectances with XYZ and L*a*b* (D50, CIE 1931 2°).

    Parameters
    ----------
    reflectance : Spectra (n, n_wl)
        Reflectance factors 0..1 on an equidistant grid covering 400-700 nm.
    responses
        Camera responses; the RGB under ``illuminant`` of each patch is written as
        ``RGB_R/G/B`` in percent of full scale (device values of an ``INPUT``
        device), e.g. for ``colprof``. Values outside 0..100 % are clipped (Argyll
        refuses them) and the patches listed in ``TUNESPEC_RGB_CLIPPED``.
    illuminant
        Which illuminant's RGB to write; may be omitted if there is only one.
    descriptor
        ``DESCRIPTOR``.
    created
        ``CREATED``; ``None`` is now (UTC).
    keywords
        More header keywords.
    spectra
        Write the ``SPEC_nnn`` fields (percent).
    uncertainty
        A :class:`tunespec.core.uncertainty.ReflectanceUncertainty` of
        ``reflectance``: adds the fields :data:`TI3_UNCERTAINTY_FIELDS`, the standard
        uncertainties (k = 1) of ``XYZ_X ... LAB_B`` (declared with ``KEYWORD``;
        ArgyllCMS's tools read past them).

    Returns
    -------
    CgatsTable
        XYZ from :func:`~tunespec.core.colorimetry.xyz_d50` (Y = 100), L*a*b* from
        :func:`~tunespec.core.colorimetry.lab_d50` (ICC D50 white), as ArgyllCMS's
        ``spec2cie -i D50 -o 1931_2`` computes them.

    Raises
    ------
    InputError
        Patches without responses, an ambiguous or unknown illuminant, a grid that
        does not cover 400-700 nm.
    """
    names = reflectance.names
    # ISO 28178 (CGATS.17) keywords as X-Rite writes them; Argyll ignores both.
    kw: dict[str, str] = {"ILLUMINATION_NAME": "D50", "OBSERVER_ANGLE": "2"}
    rgb = None
    if responses is not None:
        rgb, used = _responses_rgb(responses, names, illuminant)
        kw["TUNESPEC_RGB_ILLUMINANT"] = used
        # ArgyllCMS refuses device values outside 0..100 % ("field exceeds 100.0");
        # a flat-fielded response can pass full scale a little, a dark one dip below 0.
        out = np.any((rgb < 0.0) | (rgb > 1.0), axis=1)
        if np.any(out):
            rgb = np.clip(rgb, 0.0, 1.0)
            kw["TUNESPEC_RGB_CLIPPED"] = " ".join(
                n for n, o in zip(names, out, strict=True) if o
            )
    kw.update(keywords or {})
    extra = None
    if uncertainty is not None:
        u = np.hstack([uncertainty.xyz_std, uncertainty.lab_std])
        extra = {f: u[:, j] for j, f in enumerate(TI3_UNCERTAINTY_FIELDS)}
        kw["TUNESPEC_UNCERTAINTY"] = (
            "fields *_U: standard uncertainty (k = 1) of XYZ and L*a*b*; "
            "95 % interval = value +- 1.96 u"
        )
    return ti3_table(
        names,
        reflectance=reflectance if spectra else None,
        rgb=rgb,
        xyz=xyz_d50(reflectance),
        lab=lab_d50(reflectance),
        descriptor=descriptor,
        originator=f"TuneSpec {tunespec_version()}",
        created=created,
        keywords=kw,
        extra_fields=extra,
    )


#: Uncertainty fields of :func:`reflectance_ti3` (standard uncertainties, k = 1).
TI3_UNCERTAINTY_FIELDS = (
    "XYZ_X_U",
    "XYZ_Y_U",
    "XYZ_Z_U",
    "LAB_L_U",
    "LAB_A_U",
    "LAB_B_U",
)


def _reference_ti3(
    reference: Spectra, estimated: Spectra | None, created: datetime | str | None
) -> CgatsTable:
    """The reference ``.ti3``, on the estimate's grid when it covers it.

    Table 2 compares on the estimated grid (``reflectance_stats`` resamples the
    reference); writing the reference on that grid makes ``colverify reference.ti3
    reflectances.ti3`` reproduce Table 2's CIEDE2000.
    """
    keywords = {}
    if estimated is not None:
        try:
            grid = estimated.grid
            resampled = reference.resample(grid)
        except InputError:  # not equidistant, or not covered: keep it as it is
            pass
        else:
            if not np.array_equal(resampled.wavelength_nm, reference.wavelength_nm):
                keywords["TUNESPEC_RESAMPLED"] = (
                    f"linear, onto the estimate's {grid} nm"
                )
            reference = resampled
    return reflectance_ti3(
        reference,
        descriptor="Reference reflectances",
        created=created,
        keywords=keywords,
    )


def export_measurement(
    out_dir: str | PathLike[str],
    *,
    sensitivity: Spectra | None = None,
    reflectance: Spectra | None = None,
    responses: Responses | None = None,
    table1: TableStats | Mapping[str, Any] | None = None,
    table2: ReflectanceStats | Mapping[str, Any] | None = None,
    reference: Spectra | None = None,
    illuminants: Spectra | None = None,
    ti3_illuminant: str | None = None,
    manufacturer: str = "",
    model: str = "",
    created: datetime | str | None = None,
    uncertainty: Any = None,
    sensitivity_covariance: NDArray[np.float64] | None = None,
) -> dict[str, Path]:
    """Write every export of a measurement into ``out_dir`` (see the module table).

    Each argument is optional; only the files for what is given are written.

    Parameters
    ----------
    out_dir
        Folder, created if needed; existing files of the same names are replaced.
    sensitivity : Spectra R, G, B
        Estimated sensitivities (CSV absolute, JSON normalised to peak 1).
    reflectance : Spectra
        Estimated reflectances (CSV and ``.ti3``).
    responses
        Camera responses (CSV). The ``.ti3`` gets the RGB under ``ti3_illuminant``
        (or the only illuminant); with several illuminants and none chosen it gets
        no RGB.
    table1, table2
        Table 1 (:class:`~tunespec.core.stats.PredictionStats` or
        :class:`~tunespec.core.stats.CalibrationReport`) and Table 2
        (:class:`~tunespec.core.colorimetry.ReflectanceStats`), or their
        ``as_dict()``.
    reference : Spectra
        Reference reflectances: CSV as given; ``.ti3`` resampled onto the estimate's
        grid when it covers it, as Table 2 compares (e.g. for ``colverify``).
    illuminants : Spectra
        The LED spectra (CSV).
    ti3_illuminant
        See ``responses``.
    manufacturer, model
        The camera, for the rawtoaces JSON header.
    created
        Timestamp written into the headers; ``None`` is now (UTC).
    uncertainty
        The reflectances' :class:`~tunespec.core.uncertainty.ReflectanceUncertainty`:
        its fields go into ``reflectances.ti3`` (:data:`TI3_UNCERTAINTY_FIELDS`).

    Returns
    -------
    dict
        Export kind (the keys of :data:`EXPORT_NAMES`) to path, in writing order.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    created = created if created is not None else _now()
    paths: dict[str, Path] = {}

    def target(kind: str) -> Path:
        paths[kind] = out / EXPORT_NAMES[kind]
        return paths[kind]

    if sensitivity is not None:
        write_sensitivities_csv(
            target("sensitivities_csv"), sensitivity, sensitivity_covariance
        )
        paths["sensitivities_meta"] = sensitivity_meta_path(paths["sensitivities_csv"])
        write_sensitivity_json(
            sensitivity,
            target("sensitivities_json"),
            manufacturer=manufacturer,
            model=model,
            measurement_equipment=f"TuneSpec {tunespec_version()}",
            comments="estimated with TuneSpec from a chart under a tunable LED source",
            created=created,
        )
        # beside the JSON its LED corrections, covariance and own (2 nm) curves:
        # 'estimate --sensitivities X.json' gives what it gives from the CSV
        write_sensitivity_meta(
            paths["sensitivities_json"],
            sensitivity,
            sensitivity_covariance,
            curves=True,
        )
        target("sensitivities_json_meta")
    ti3_rgb = responses
    if responses is not None and ti3_illuminant is None:
        ti3_rgb = responses if len(responses.illuminants) == 1 else None
    if reflectance is not None:
        write_spectra_csv(reflectance, target("reflectances_csv"))
        write_cgats(
            reflectance_ti3(
                reflectance,
                responses=ti3_rgb,
                illuminant=ti3_illuminant,
                created=created,
                uncertainty=uncertainty,
            ),
            target("reflectances_ti3"),
        )
    if reference is not None:
        write_spectra_csv(reference, target("reference_csv"))
        write_cgats(
            _reference_ti3(reference, reflectance, created),
            target("reference_ti3"),
        )
    if responses is not None:
        write_responses_csv(responses, target("responses_csv"))
    if illuminants is not None:
        write_spectra_csv(illuminants, target("illuminants_csv"))
    if table1 is not None:
        write_prediction_stats_csv(table1, target("table1_csv"))
    if table2 is not None:
        write_reflectance_stats_csv(table2, target("table2_csv"))
    return paths
