"""The CAL1 command table: every byte the driver and the emulator exchange is made here.

The CAL1's command set is not public. Everything in this module is an *assumption*
(see ``devices/cal1/PROTOCOL.md`` for what must be checked on the bench); keeping the
whole protocol in this one module means that correcting it against the vendor's
reference changes the driver and the emulator together, and the scripted tests in
``tests/devices/test_cal1_protocol.py`` show the exact bytes that changed.

Wire format (assumed): line-based ASCII, one request line, exactly one reply line,
both terminated by :data:`TERMINATOR`. A reply is either the command's data, ``OK``,
or ``ERR <code> <text>``. Channels are numbered from 1 on the wire and from 0 in
Python (:attr:`~tunespec.devices.protocols.Channel.index`).

Two directions, one table:

- driver side: :func:`encode_request`, :func:`decode_reply`;
- device (emulator) side: :func:`decode_request`, :func:`encode_reply`,
  :func:`encode_error`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.devices.protocols import (
    DeviceBusyError,
    DeviceCommandError,
    DeviceError,
    DeviceProtocolError,
)

__all__ = [
    "BAUDRATE",
    "COMMANDS",
    "DEFAULT_TIMEOUT_S",
    "ENCODING",
    "ERRORS",
    "LEVEL_DECIMALS",
    "MAX_LINE_BYTES",
    "MEASURE_TIMEOUT_S",
    "RADIANCE_UNIT",
    "TERMINATOR",
    "ChannelInfo",
    "Command",
    "ErrorCode",
    "ErrorInfo",
    "ErrorReply",
    "Identity",
    "MeasuredSpectrum",
    "Request",
    "check_levels",
    "decode_reply",
    "decode_request",
    "encode_error",
    "encode_reply",
    "encode_request",
    "spectrum_problem",
]

# --- link settings (assumed; PROTOCOL.md "check on the bench") -------------------------

#: Line terminator sent and expected. Incoming ``\r\n`` is accepted too.
TERMINATOR = b"\n"
#: Character set of both directions.
ENCODING = "ascii"
#: Serial speed for real ports (8 data bits, no parity, 1 stop bit, no flow control).
BAUDRATE = 115_200
#: Reply timeout of an ordinary command.
DEFAULT_TIMEOUT_S = 2.0
#: Reply timeout of a spectrum measurement (auto-ranged integration may take seconds).
MEASURE_TIMEOUT_S = 30.0
#: Longest line either side accepts (a 401-sample spectrum is about 5.3 kB).
MAX_LINE_BYTES = 65_536
#: Decimals of a level on the wire (a fraction of full drive, 0..1).
LEVEL_DECIMALS = 4
#: Unit of the spectra the CAL1 reports (assumed: spectral radiance).
RADIANCE_UNIT = "W sr^-1 m^-2 nm^-1"

ReplyKind = Literal["ok", "idn", "int", "channels", "levels", "spectrum", "status"]
ArgKind = Literal["channel", "level", "levels"]


@dataclass(frozen=True)
class Command:
    """One row of the command table.

    Parameters
    ----------
    key
        Python-side name used by the driver and the emulator.
    keyword
        The command word on the wire.
    args
        Kinds of the arguments, in order: ``"channel"`` (0-based index in Python,
        1-based on the wire), ``"level"`` (0..1) or ``"levels"`` (one per channel,
        comma-separated).
    reply
        Kind of the reply line, decoded by :func:`decode_reply`.
    slow
        The reply may take long (spectrum measurement): use the measure timeout.
    summary
        What the command does, for PROTOCOL.md and error messages.
    """

    key: str
    keyword: str
    args: tuple[ArgKind, ...]
    reply: ReplyKind
    summary: str
    slow: bool = False


#: The command table, keyed by :attr:`Command.key`.
COMMANDS: dict[str, Command] = {
    c.key: c
    for c in (
        Command("identify", "*IDN?", (), "idn", "vendor,model,serial,firmware"),
        Command("channel_count", "CHAN:COUNT?", (), "int", "number of LED channels"),
        Command(
            "channel_list",
            "CHAN:LIST?",
            (),
            "channels",
            "name,peak_nm,N|W per channel, ';'-separated, in channel order",
        ),
        Command(
            "set_level",
            "CHAN:LEVEL",
            ("channel", "level"),
            "ok",
            "set one channel's level (channel from 1)",
        ),
        Command(
            "set_levels",
            "CHAN:LEVEL:ALL",
            ("levels",),
            "ok",
            "set every channel's level, comma-separated in channel order",
        ),
        Command("get_levels", "CHAN:LEVEL:ALL?", (), "levels", "levels now set"),
        Command("all_off", "OUTP:OFF", (), "ok", "switch every channel off"),
        Command(
            "measure_spd",
            "MEAS:SPD?",
            (),
            "spectrum",
            "measure the emitted SPD: start_nm,step_nm,count,v1..vcount",
            slow=True,
        ),
        Command(
            "status",
            "SYST:STAT?",
            (),
            "status",
            "KEY=VALUE pairs, ';'-separated: READY, TEMP_C, ON_S, ...",
        ),
    )
}

_BY_KEYWORD = {c.keyword.upper(): c for c in COMMANDS.values()}


class ErrorCode(IntEnum):
    """Codes of ``ERR <code> <text>`` replies (assumed)."""

    UNKNOWN_COMMAND = 100
    BAD_ARGUMENT = 101
    BAD_CHANNEL = 102
    BAD_LEVEL = 103
    LEVEL_COUNT = 104
    LINE_TOO_LONG = 105
    MEASUREMENT_FAILED = 200
    OVER_TEMPERATURE = 300
    BUSY = 409
    INTERNAL = 500


@dataclass(frozen=True)
class ErrorInfo:
    """How the driver reports an error code: exception class and operator hint."""

    exc_class: type[DeviceError]
    hint: str


#: Exception class and operator hint per error code; unknown codes are
#: :class:`DeviceCommandError` with a generic hint.
ERRORS: dict[int, ErrorInfo] = {
    ErrorCode.UNKNOWN_COMMAND: ErrorInfo(
        DeviceCommandError,
        "the CAL1 firmware does not know this command: its command set differs from "
        "the one assumed in devices/cal1/PROTOCOL.md (check the firmware version)",
    ),
    ErrorCode.BAD_ARGUMENT: ErrorInfo(
        DeviceCommandError,
        "the CAL1 did not accept the argument format (see devices/cal1/PROTOCOL.md)",
    ),
    ErrorCode.BAD_CHANNEL: ErrorInfo(
        DeviceCommandError, "the channel number is outside the CAL1's channels"
    ),
    ErrorCode.BAD_LEVEL: ErrorInfo(
        DeviceCommandError, "levels must lie in 0..1 (fraction of full drive)"
    ),
    ErrorCode.LEVEL_COUNT: ErrorInfo(
        DeviceCommandError, "the number of levels must equal the number of channels"
    ),
    ErrorCode.LINE_TOO_LONG: ErrorInfo(
        DeviceCommandError, "the command line was too long for the CAL1"
    ),
    ErrorCode.MEASUREMENT_FAILED: ErrorInfo(
        DeviceCommandError,
        "the internal spectroradiometer failed; check that nothing covers the CAL1's "
        "measuring port and retry",
    ),
    ErrorCode.OVER_TEMPERATURE: ErrorInfo(
        DeviceCommandError,
        "the CAL1 is over temperature; check its ventilation and let it cool down",
    ),
    ErrorCode.BUSY: ErrorInfo(
        DeviceBusyError,
        "the CAL1 is in use by another program or connection; close it and retry",
    ),
    ErrorCode.INTERNAL: ErrorInfo(
        DeviceCommandError, "the CAL1 reported an internal error; power-cycle it"
    ),
}

_GENERIC_ERROR = ErrorInfo(
    DeviceCommandError, "unknown error code (see the CAL1 manual)"
)


def error_info(code: int) -> ErrorInfo:
    """Exception class and hint for an error ``code`` (generic for unknown codes)."""
    return ERRORS.get(code, _GENERIC_ERROR)


class ErrorReply(DeviceCommandError):
    """An ``ERR <code> <text>`` reply, before the driver adds its context.

    Also raised by :func:`decode_request` (device side) for a request to refuse.
    """

    def __init__(self, code: int, text: str) -> None:
        super().__init__(f"ERR {code} {text}")
        self.code = int(code)
        self.text = text


# --- values carried by the protocol ---------------------------------------------------


@dataclass(frozen=True)
class Identity:
    """The fields of the ``*IDN?`` reply."""

    vendor: str
    model: str
    serial: str
    firmware: str


@dataclass(frozen=True)
class ChannelInfo:
    """One entry of the ``CHAN:LIST?`` reply."""

    name: str
    peak_nm: float
    kind: Literal["narrowband", "white"]


@dataclass(frozen=True)
class MeasuredSpectrum:
    """The ``MEAS:SPD?`` reply: an equidistant spectrum in :data:`RADIANCE_UNIT`."""

    start_nm: float
    step_nm: float
    values: NDArray[np.float64]

    @property
    def wavelength_nm(self) -> NDArray[np.float64]:
        """Sample wavelengths, shape (count,)."""
        return self.start_nm + self.step_nm * np.arange(
            self.values.size, dtype=np.float64
        )


@dataclass(frozen=True)
class Request:
    """A decoded request (device side): the command and its Python-side arguments."""

    command: Command
    args: tuple[int | float | NDArray[np.float64], ...]


_KIND_CODE = {"narrowband": "N", "white": "W"}
_CODE_KIND: dict[str, Literal["narrowband", "white"]] = {
    "N": "narrowband",
    "W": "white",
}


def check_levels(levels: ArrayLike, n_channels: int) -> NDArray[np.float64]:
    """Validate channel levels: shape ``(n_channels,)``, finite, each in [0, 1].

    Raises
    ------
    ValueError
        Saying what is wrong (a programming error, caught before anything is sent).
    """
    arr = np.asarray(levels, dtype=np.float64)
    if arr.shape != (n_channels,):
        raise ValueError(f"expected {n_channels} levels, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError("levels must be finite")
    if np.any(arr < 0.0) or np.any(arr > 1.0):
        bad = int(np.flatnonzero((arr < 0.0) | (arr > 1.0))[0])
        raise ValueError(f"level {arr[bad]!r} of channel {bad} is outside 0..1")
    return arr


def _fmt_level(level: float) -> str:
    return f"{level:.{LEVEL_DECIMALS}f}"


def _line(text: str) -> bytes:
    return text.encode(ENCODING) + TERMINATOR


# --- driver side ------------------------------------------------------------------------


def encode_request(key: str, *args: int | float | ArrayLike) -> bytes:
    """The request line for command ``key`` with Python-side ``args``.

    Examples
    --------
    >>> encode_request("set_level", 0, 0.5)
    b'CHAN:LEVEL 1 0.5000\\n'
    >>> encode_request("measure_spd")
    b'MEAS:SPD?\\n'
    """
    cmd = COMMANDS[key]
    if len(args) != len(cmd.args):
        raise TypeError(f"{key} takes {len(cmd.args)} argument(s), got {len(args)}")
    words = [cmd.keyword]
    for kind, value in zip(cmd.args, args, strict=True):
        if kind == "channel":
            words.append(str(int(value) + 1))  # type: ignore[arg-type]
        elif kind == "level":
            words.append(_fmt_level(float(value)))  # type: ignore[arg-type]
        else:
            arr = np.asarray(value, dtype=np.float64).ravel()
            words.append(",".join(_fmt_level(v) for v in arr))
    return _line(" ".join(words))


def decode_reply(
    key: str, line: bytes
) -> (
    Identity
    | int
    | list[ChannelInfo]
    | NDArray[np.float64]
    | MeasuredSpectrum
    | dict[str, str]
    | None
):
    """Decode the reply ``line`` (terminator stripped) to the command ``key``.

    Returns
    -------
    None (``OK``), :class:`Identity`, int, list of :class:`ChannelInfo`, levels
    (n_channels,), :class:`MeasuredSpectrum` or the status ``dict`` (upper-case keys).

    Raises
    ------
    ErrorReply
        For an ``ERR <code> <text>`` reply.
    DeviceProtocolError
        For anything else that is not a valid reply (message says what was expected).
    """
    cmd = COMMANDS[key]
    try:
        text = line.decode(ENCODING).strip()
    except UnicodeDecodeError:
        raise DeviceProtocolError(
            f"non-ASCII reply {_show(line)} to {cmd.keyword}"
        ) from None
    if text.startswith("ERR"):
        parts = text.split(maxsplit=2)
        if len(parts) >= 2 and parts[0] == "ERR" and parts[1].isdigit():
            raise ErrorReply(int(parts[1]), parts[2] if len(parts) > 2 else "")
    try:
        return _DECODERS[cmd.reply](text)
    except (ValueError, IndexError) as exc:
        raise DeviceProtocolError(
            f"invalid reply {_show(line)} to {cmd.keyword} "
            f"(expected {cmd.summary}; {exc})"
        ) from None


def _show(line: bytes, limit: int = 60) -> str:
    """A short printable rendering of a reply for messages."""
    shown = repr(line[:limit])
    return shown + (f" ... ({len(line)} bytes)" if len(line) > limit else "")


def _decode_ok(text: str) -> None:
    if text != "OK":
        raise ValueError("not OK")


def _decode_idn(text: str) -> Identity:
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 4 or not parts[1]:
        raise ValueError("expected 4 comma-separated fields")
    return Identity(*parts)


def _decode_int(text: str) -> int:
    if not text.isdigit():
        raise ValueError("not a non-negative integer")
    return int(text)


def _decode_channels(text: str) -> list[ChannelInfo]:
    out = []
    for entry in text.split(";"):
        name, peak, code = (p.strip() for p in entry.split(","))
        peak_nm = float(peak)
        if not name or code not in _CODE_KIND or not math.isfinite(peak_nm):
            raise ValueError(f"bad channel entry {entry!r}")
        out.append(ChannelInfo(name, peak_nm, _CODE_KIND[code]))
    return out


def _decode_levels(text: str) -> NDArray[np.float64]:
    arr = np.array([float(v) for v in text.split(",")], dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError("non-finite level")
    return arr


def _decode_spectrum(text: str) -> MeasuredSpectrum:
    fields = text.split(",")
    start_nm, step_nm = float(fields[0]), float(fields[1])
    count = int(fields[2])
    values = np.array([float(v) for v in fields[3:]], dtype=np.float64)
    if values.size != count or count < 2:
        raise ValueError(f"header says {count} values, {values.size} sent")
    if not (math.isfinite(start_nm) and math.isfinite(step_nm) and step_nm > 0):
        raise ValueError("bad wavelength start/step")
    if not np.all(np.isfinite(values)):
        raise ValueError("non-finite spectral value")
    return MeasuredSpectrum(start_nm, step_nm, values)


#: Largest spectral radiance a reply may hold, W sr^-1 m^-2 nm^-1 (the sun's disk
#: is about 2e4 at 500 nm; an LED light source is far below).
MAX_RADIANCE = 1e6
#: Wavelengths a spectroradiometer's reply must cover at least, nm.
SPD_MIN_COVERAGE_NM = (400.0, 700.0)
#: A visible-range spectroradiometer's grid: start, end within, step at most, nm.
SPD_GRID_LIMITS_NM = (200.0, 2000.0, 50.0)
#: Negative samples allowed (meter noise): this many noise sd, plus this fraction of
#: the peak, plus this absolute radiance.
SPD_NEGATIVE_NOISE_SD = 6.0
SPD_NEGATIVE_PEAK_FRACTION = 0.01
SPD_NEGATIVE_FLOOR = 1e-6


def spectrum_problem(spectrum: MeasuredSpectrum) -> str:
    """What makes a decoded ``MEAS:SPD?`` reply impossible ("" if nothing): a grid
    no visible spectroradiometer has, too short a range, absurd values, or values
    negative beyond the meter's noise (nothing measured)."""
    from tunespec.core.metering import reading_noise_rms

    v = spectrum.values
    wl = spectrum.wavelength_nm
    a, b = float(wl[0]), float(wl[-1])
    lo, hi, max_step = SPD_GRID_LIMITS_NM
    if a < lo or b > hi or spectrum.step_nm > max_step:
        return (
            f"wavelengths {a:g}-{b:g} nm in steps of {spectrum.step_nm:g} nm: not a "
            f"visible spectroradiometer's grid (within {lo:g}-{hi:g} nm, steps of at "
            f"most {max_step:g} nm)"
        )
    want_a, want_b = SPD_MIN_COVERAGE_NM
    if a > want_a or b < want_b:
        return (
            f"a spectrum of {a:g}-{b:g} nm ({v.size} values), expected at least "
            f"{want_a:g}-{want_b:g} nm: cut short"
        )
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) > MAX_RADIANCE:
        return f"value {v[k]:g} at {wl[k]:g} nm: no light source is that bright"
    peak = float(v.max())
    if not peak > 0:
        return "no value above zero: no light was measured"
    allowed = (
        SPD_NEGATIVE_NOISE_SD * reading_noise_rms(v, wl)
        + SPD_NEGATIVE_PEAK_FRACTION * peak
        + SPD_NEGATIVE_FLOOR
    )
    k = int(np.argmin(v))
    if v[k] < -allowed:
        return (
            f"value {v[k]:g} at {wl[k]:g} nm is negative beyond the meter's noise "
            f"(at most -{allowed:.2g} here)"
        )
    return ""


def _decode_status(text: str) -> dict[str, str]:
    out = {}
    for pair in text.split(";"):
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"bad KEY=VALUE pair {pair!r}")
        out[key.strip().upper()] = value.strip()
    for required in ("READY", "TEMP_C", "ON_S"):
        if required not in out:
            raise ValueError(f"missing {required}")
    if out["READY"] not in ("0", "1"):
        raise ValueError("READY must be 0 or 1")
    for number in ("TEMP_C", "ON_S"):
        float(out[number])  # raises ValueError for a non-number
    return out


_DECODERS = {
    "ok": _decode_ok,
    "idn": _decode_idn,
    "int": _decode_int,
    "channels": _decode_channels,
    "levels": _decode_levels,
    "spectrum": _decode_spectrum,
    "status": _decode_status,
}


# --- device (emulator) side ------------------------------------------------------------


def decode_request(line: bytes) -> Request:
    """Decode a request line (terminator stripped), as the device does.

    Keywords are case-insensitive. Channel and level *ranges* depending on the unit
    (channel count) are left to the caller; level values outside 0..1 are refused.

    Raises
    ------
    ErrorReply
        ``UNKNOWN_COMMAND`` or ``BAD_ARGUMENT``/``BAD_LEVEL``/``BAD_CHANNEL``.
    """
    try:
        text = line.decode(ENCODING).strip()
    except UnicodeDecodeError:
        raise ErrorReply(ErrorCode.BAD_ARGUMENT, "non-ASCII request") from None
    keyword, _, rest = text.partition(" ")
    cmd = _BY_KEYWORD.get(keyword.upper())
    if cmd is None:
        raise ErrorReply(ErrorCode.UNKNOWN_COMMAND, f"unknown command {keyword[:32]}")
    words = rest.split()
    if len(words) != len(cmd.args):
        raise ErrorReply(
            ErrorCode.BAD_ARGUMENT,
            f"{cmd.keyword} takes {len(cmd.args)} argument(s), got {len(words)}",
        )
    args: list[int | float | NDArray[np.float64]] = []
    for kind, word in zip(cmd.args, words, strict=True):
        try:
            if kind == "channel":
                channel = int(word)
                if channel < 1:
                    raise ErrorReply(ErrorCode.BAD_CHANNEL, f"no channel {channel}")
                args.append(channel - 1)
            elif kind == "level":
                args.append(_parse_level(word))
            else:
                levels = [_parse_level(w) for w in word.split(",")]
                args.append(np.array(levels, dtype=np.float64))
        except ValueError:
            raise ErrorReply(
                ErrorCode.BAD_ARGUMENT, f"bad {kind} argument {word[:32]}"
            ) from None
    return Request(cmd, tuple(args))


def _parse_level(word: str) -> float:
    level = float(word)
    if not (0.0 <= level <= 1.0):
        raise ErrorReply(ErrorCode.BAD_LEVEL, f"level {word[:16]} outside 0..1")
    return level


def encode_reply(
    key: str,
    value: Identity
    | int
    | Sequence[ChannelInfo]
    | ArrayLike
    | MeasuredSpectrum
    | Mapping[str, object]
    | None = None,
) -> bytes:
    """The reply line the device sends for command ``key`` with ``value``.

    ``value`` is what :func:`decode_reply` returns for that command (``None`` for
    ``OK``; a mapping of status fields whose values are formatted with ``str``).
    """
    kind = COMMANDS[key].reply
    if kind == "ok":
        return _line("OK")
    if kind == "idn":
        assert isinstance(value, Identity)
        fields = (value.vendor, value.model, value.serial, value.firmware)
        return _line(",".join(_clean(f, ",") for f in fields))
    if kind == "int":
        assert isinstance(value, int | np.integer)
        return _line(str(int(value)))
    if kind == "channels":
        infos = cast("Sequence[ChannelInfo]", value)
        entries = [
            f"{_clean(c.name, ',;')},{c.peak_nm:.1f},{_KIND_CODE[c.kind]}"
            for c in infos
        ]
        return _line(";".join(entries))
    if kind == "levels":
        arr = np.asarray(value, dtype=np.float64).ravel()
        return _line(",".join(_fmt_level(v) for v in arr))
    if kind == "spectrum":
        assert isinstance(value, MeasuredSpectrum)
        head = f"{value.start_nm:g},{value.step_nm:g},{value.values.size}"
        return _line(head + "," + ",".join(f"{v:.6e}" for v in value.values))
    assert isinstance(value, Mapping)
    pairs = [f"{_clean(str(k), '=;')}={_clean(str(v), ';')}" for k, v in value.items()]
    return _line(";".join(pairs))


def encode_error(code: int, text: str) -> bytes:
    """An ``ERR <code> <text>`` reply line."""
    return _line(f"ERR {int(code)} {_clean(text, '')}")


def _clean(text: str, forbidden: str) -> str:
    """``text`` made safe for one field: ASCII, no terminator, no separators."""
    out = text.encode(ENCODING, "replace").decode(ENCODING)
    for ch in forbidden + "\r\n":
        out = out.replace(ch, " ")
    return out
