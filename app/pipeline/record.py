"""The measurement record: who measured what, with which instruments.

What a lab signs besides the numbers: the operator, the sample's identifier, the
chart's serial and where its reference data come from, the instruments with their
serial numbers and calibration dates, the room and the light's warm-up. The operator
fills these fields (``[provenance]`` of a ``tunespec run`` configuration, the
``--operator``/``--sample-id``/... options of ``run``, ``demo`` and ``report``, or
the GUI's *Measurement record* dialog); they are kept in the measurement folder as
``record.json`` (:func:`read_record`, :func:`update_record`) and shown on the
report's first page and in ``summary.json`` (:func:`record_summary`).

Serial numbers and firmware the devices report (a session's ``devices``) fill the
instrument rows the operator left empty (:func:`instrument_rows`).
"""

from __future__ import annotations

import platform
import re
from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from datetime import date
from os import PathLike
from pathlib import Path
from typing import Any

from tunespec.core.errors import InputError
from tunespec.core.limits import dumps_json, read_json, shown

__all__ = [
    "RECORD_FIELDS",
    "RECORD_FILE",
    "MeasurementRecord",
    "chart_reference",
    "instrument_rows",
    "light_status_items",
    "read_record",
    "record_from_mapping",
    "record_summary",
    "software_versions",
    "update_record",
    "write_record",
]

#: The record's file in a measurement folder.
RECORD_FILE = "record.json"
#: Longest text of one field (a note may be a sentence or two).
MAX_FIELD_CHARS = 500

#: key -> (label, what it holds), in the report's order. The key is the name in
#: ``[provenance]``, in ``record.json`` and in ``summary.json``; the command-line
#: option is ``--`` + the key with dashes (``--sample-id``).
RECORD_FIELDS: dict[str, tuple[str, str]] = {
    "operator": ("Operator", "who took the measurement"),
    "sample_id": ("Sample ID", "the sample's identifier"),
    "chart_serial": ("Chart serial", "serial or lot of the calibration chart"),
    "chart_reference": (
        "Chart reference data",
        "where the chart's reference reflectances come from (instrument, date)",
    ),
    "light_source_serial": ("Light source serial", "if the device reports none"),
    "light_source_calibration": (
        "Light source calibration",
        "date of its last calibration, YYYY-MM-DD",
    ),
    "spectroradiometer": (
        "Spectroradiometer",
        "model (default: the light source's internal one)",
    ),
    "spectroradiometer_serial": ("Spectroradiometer serial", ""),
    "spectroradiometer_calibration": (
        "Spectroradiometer calibration",
        "date of its last calibration, YYYY-MM-DD",
    ),
    "camera_serial": ("Camera serial", "if the camera reports none"),
    "temperature_c": ("Room temperature (°C)", "a number"),
    "warm_up_min": ("Light source warm-up (min)", "a number"),
    "notes": ("Notes", "free text"),
}
_DATES = ("light_source_calibration", "spectroradiometer_calibration")
#: Numeric fields and their plausible ranges.
_NUMBERS = {"temperature_c": (-40.0, 80.0), "warm_up_min": (0.0, 1440.0)}
_DATE = re.compile(r"\d{4}-\d{2}-\d{2}")


@dataclass(frozen=True)
class MeasurementRecord:
    """The operator's fields (:data:`RECORD_FIELDS`); ``""`` is not recorded."""

    operator: str = ""
    sample_id: str = ""
    chart_serial: str = ""
    chart_reference: str = ""
    light_source_serial: str = ""
    light_source_calibration: str = ""
    spectroradiometer: str = ""
    spectroradiometer_serial: str = ""
    spectroradiometer_calibration: str = ""
    camera_serial: str = ""
    temperature_c: str = ""
    warm_up_min: str = ""
    notes: str = ""

    def as_dict(self) -> dict[str, str]:
        return asdict(self)

    def filled(self) -> dict[str, str]:
        """The fields given (non-empty)."""
        return {k: v for k, v in asdict(self).items() if v}

    def updated(self, other: MeasurementRecord) -> MeasurementRecord:
        """This record with ``other``'s non-empty fields."""
        return replace(self, **other.filled())


def _check_value(key: str, value: Any, where: str, path: Any) -> str:
    """One field as text, checked (one-line error naming ``where``)."""
    if key in _NUMBERS:
        lo, hi = _NUMBERS[key]
        if isinstance(value, str):
            try:
                value = float(value) if value.strip() else ""
            except ValueError:
                raise InputError(
                    f"{where}: expected a number, got {shown(value)}", path=path
                ) from None
        if value == "":
            return ""
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(
                f"{where}: expected a number, got {shown(value)}", path=path
            )
        if not lo <= value <= hi:
            raise InputError(
                f"{where}: {value:g} is outside {lo:g} to {hi:g}", path=path
            )
        return f"{value:g}"
    if not isinstance(value, str):
        raise InputError(f"{where}: expected text, got {shown(value)}", path=path)
    text = " ".join(value.split())  # one line: no tabs, newlines or control marks
    if len(text) > MAX_FIELD_CHARS:
        raise InputError(
            f"{where}: at most {MAX_FIELD_CHARS} characters, got {len(text)}", path=path
        )
    if key in _DATES and text:
        try:
            if not _DATE.fullmatch(text):
                raise ValueError
            date.fromisoformat(text)
        except ValueError:
            raise InputError(
                f"{where}: expected a date YYYY-MM-DD, got {shown(text)}", path=path
            ) from None
    return text


def record_from_mapping(
    values: Mapping[str, Any],
    *,
    section: str = "provenance",
    path: str | PathLike[str] | None = None,
    option_names: bool = False,
) -> MeasurementRecord:
    """A record from ``[provenance]`` (or ``record.json``, or the command line).

    ``None`` values are left out. ``option_names``: errors name the command-line
    option (``--sample-id``) instead of ``section.key``.

    Raises
    ------
    InputError
        An unknown key, a value that is not text (a number for ``temperature_c``,
        ``warm_up_min``), too long, out of range, or a date not YYYY-MM-DD.
    """
    if not isinstance(values, Mapping):
        raise InputError(f"{section}: expected a table/object", path=path)
    unknown = sorted(set(values) - set(RECORD_FIELDS))
    if unknown:
        raise InputError(
            f"{section}: unknown key(s) {', '.join(map(shown, unknown[:8]))} (known: "
            f"{', '.join(RECORD_FIELDS)})",
            path=path,
        )
    out = {}
    for key, value in values.items():
        if value is None:
            continue
        where = f"--{key.replace('_', '-')}" if option_names else f"{section}.{key}"
        out[key] = _check_value(key, value, where, path)
    return MeasurementRecord(**out)


def read_record(folder: str | PathLike[str]) -> MeasurementRecord:
    """The record kept in a measurement folder (an empty one if there is none).

    Raises
    ------
    InputError
        A damaged ``record.json`` (naming it and the key).
    """
    path = Path(folder) / RECORD_FILE
    if not path.is_file():
        return MeasurementRecord()
    return record_from_mapping(read_json(path), section="record", path=path)


def write_record(folder: str | PathLike[str], record: MeasurementRecord) -> Path:
    """Write ``record.json`` into the measurement folder (atomically)."""
    from tunespec.core.atomic import atomic_write_text

    path = Path(folder) / RECORD_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, dumps_json(record.as_dict()))
    return path


def update_record(
    folder: str | PathLike[str], record: MeasurementRecord
) -> MeasurementRecord:
    """The folder's record with ``record``'s given fields, written back; fields not
    given (the GUI's, an earlier run's) are kept."""
    kept = read_record(folder)
    merged = kept.updated(record)
    if merged != kept or not (Path(folder) / RECORD_FILE).is_file():
        write_record(folder, merged)
    return merged


def software_versions() -> dict[str, str]:
    """TuneSpec, Python, the numerics' libraries and the platform."""
    from importlib.metadata import PackageNotFoundError, version

    from tunespec.core.io.export import tunespec_version

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


#: Device roles of a session's ``devices`` per instrument.
_LIGHT_ROLES = ("light", "light source")
_CAMERA_ROLES = ("camera",)


def _device(devices: Mapping[str, Mapping[str, str]], roles: tuple[str, ...]) -> dict:
    for role in roles:
        if role in devices:
            return dict(devices[role])
    return {}


def instrument_rows(
    record: MeasurementRecord, devices: Mapping[str, Mapping[str, str]]
) -> list[dict[str, str]]:
    """Light source, spectroradiometer and camera: model, serial, firmware and
    calibration date, each with where it comes from.

    A serial the operator gave wins over the device's; an empty value is
    ``"not recorded"``. The spectroradiometer defaults to the light source's own
    (the CAL1's is internal), with the light's serial.
    """
    light = _device(devices, _LIGHT_ROLES)
    camera = _device(devices, _CAMERA_ROLES)

    def serial(given: str, reported: str | None) -> tuple[str, str]:
        if given:
            return given, "operator"
        if reported:
            return str(reported), "device"
        return "not recorded", ""

    rows = []
    s, src = serial(record.light_source_serial, light.get("serial"))
    rows.append(
        {
            "instrument": "Light source",
            "model": str(light.get("model", "not recorded")),
            "serial": s,
            "serial_source": src,
            "firmware": str(light.get("firmware", "-")),
            "calibration": record.light_source_calibration or "not recorded",
        }
    )
    internal = not record.spectroradiometer
    s, src = serial(
        record.spectroradiometer_serial, light.get("serial") if internal else None
    )
    rows.append(
        {
            "instrument": "Spectroradiometer",
            "model": record.spectroradiometer
            or f"internal to the light source ({light.get('model', 'model unknown')})",
            "serial": s,
            "serial_source": src,
            "firmware": str(light.get("firmware", "-")) if internal else "-",
            "calibration": record.spectroradiometer_calibration or "not recorded",
        }
    )
    s, src = serial(record.camera_serial, camera.get("serial"))
    rows.append(
        {
            "instrument": "Camera",
            "model": str(camera.get("model", "not recorded")),
            "serial": s,
            "serial_source": src,
            "firmware": str(camera.get("firmware", "-")),
            "calibration": "this run (Table 1)",
        }
    )
    return rows


def light_status_items(light: Any) -> dict[str, str]:
    """What the light source says of itself now (its case temperature, how long it
    has been on: the warm-up), for the report's provenance; ``{}`` if it cannot
    say (no ``status``, or the query failed: the record is not worth a failed run).
    """
    import math

    from tunespec.core.errors import TuneSpecError
    from tunespec.devices.protocols import DeviceError

    try:
        status = light.status()
    except (AttributeError, NotImplementedError, OSError, DeviceError, TuneSpecError):
        return {}
    out = {}
    temperature = float(getattr(status, "temperature_c", float("nan")))
    if math.isfinite(temperature):
        out["light source case temperature at the run's start (°C)"] = (
            f"{temperature:.1f}"
        )
    on_s = float(getattr(status, "on_time_s", float("nan")))
    if math.isfinite(on_s):
        out["light source on for, at the run's start (min)"] = f"{on_s / 60:.1f}"
    return out


def chart_reference(record: MeasurementRecord, layout: Any = None) -> str:
    """The source of the chart's reference data: the operator's, else the file the
    chart's layout names (shipped data are typical values, not this chart's own)."""
    if record.chart_reference:
        return record.chart_reference
    meta = getattr(layout, "meta", None) or {}
    ref = meta.get("reflectances") if isinstance(meta, Mapping) else None
    if not ref:
        return "not recorded"
    return (
        f"{ref}, named by the chart's layout (shipped data are the typical values "
        "of the chart type, not this chart's own measurement)"
    )


def record_summary(
    record: MeasurementRecord,
    devices: Mapping[str, Mapping[str, str]],
    *,
    chart_layout: Any = None,
    settings: Mapping[str, str] | None = None,
) -> dict[str, Any]:
    """``summary.json``'s ``provenance``: the operator's fields (every key, ``""``
    where not recorded; ``chart_reference`` as :func:`chart_reference` says), the
    chart's name, the instruments, software and settings."""
    return {
        **record.as_dict(),
        "chart_reference": chart_reference(record, chart_layout),
        "chart": str(getattr(chart_layout, "name", "")),
        "instruments": instrument_rows(record, devices),
        "software": software_versions(),
        "settings": dict(settings or {}),
    }
