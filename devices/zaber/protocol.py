"""Zaber ASCII protocol: encoding commands, decoding replies, alerts and info lines.

Messages are single lines of ASCII (Zaber ASCII Protocol Manual)::

    command   /1 2 move abs 10000\\n          device 1, axis 2 ('0' or none: the device)
    reply     @01 2 OK BUSY -- 0\\r\\n         flag OK|RJ, status IDLE|BUSY, warning, data
    rejected  @01 2 RJ IDLE -- BADDATA\\r\\n    data: the reason
    alert     !01 2 IDLE --\\r\\n               sent unasked (comm.alert 1) when a move ends
    info      #01 0 some text\\r\\n             extra lines (help, and multi-line replies)

An optional checksum ``:CC`` ends a message: two hex digits, the two's complement of
the low byte of the sum of every byte after the leading character (``/``, ``@``, ``!``,
``#``) and before the colon (e.g. ``@01 0 OK IDLE -- 0:8D``). Warning flags are two
characters, ``--`` for none; those starting with ``F`` are faults (e.g. ``FS`` stalled
and stopped, ``FD`` driver disabled, ``FQ`` encoder error), ``W`` warnings (``WR`` no
reference position, ``WL`` unexpected limit trigger), ``N`` notices (``NI`` command
interrupted, ``NC`` manual control).

References
----------
Zaber Technologies, "ASCII Protocol Manual" (message format, checksum, reply flags,
warning flags, commands ``home``, ``move abs``, ``stop``, ``get pos``,
``get limit.min``, ``get limit.max``, ``get device.id``, ``get system.serial``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from tunespec.devices.protocols import DeviceProtocolError

__all__ = [
    "BAUDRATE",
    "FAULT_PREFIX",
    "MAX_LINE_BYTES",
    "Alert",
    "Info",
    "Reply",
    "checksum",
    "decode_line",
    "encode_command",
]

#: Default baud rate of Zaber ASCII devices (8N1).
BAUDRATE = 115_200
#: Warning flags starting with this are faults: the axis stopped.
FAULT_PREFIX = "F"
#: Longest line accepted (a babbling link).
MAX_LINE_BYTES = 512

_REPLY = re.compile(r"@(\d{2}) (\d+)(?: (\d+))? (OK|RJ) (IDLE|BUSY) (\S{2}) ?(.*)")
_ALERT = re.compile(r"!(\d{2}) (\d+) (IDLE|BUSY) (\S{2})(?: (.*))?")
_INFO = re.compile(r"#(\d{2}) (\d+)(?: (.*))?")


def checksum(body: str) -> str:
    """Two hex digits: the two's complement of the low byte of ``body``'s byte sum.

    Examples
    --------
    >>> checksum("01 0 OK IDLE -- 0")
    '8D'
    """
    return f"{(-sum(body.encode('ascii'))) & 0xFF:02X}"


def encode_command(
    device: int, axis: int, command: str, *, with_checksum: bool = False
) -> bytes:
    """``/device axis command[:CC]\\n`` as bytes.

    Examples
    --------
    >>> encode_command(1, 1, "move abs 1000")
    b'/1 1 move abs 1000\\n'
    >>> encode_command(1, 0, "get pos", with_checksum=True)
    b'/1 0 get pos:AD\\n'
    """
    if not 0 <= device <= 99 or not 0 <= axis <= 9:
        raise ValueError(f"device {device} / axis {axis} out of range")
    body = f"{device} {axis} {command}".rstrip()
    if with_checksum:
        body += ":" + checksum(body)
    return ("/" + body + "\n").encode("ascii")


@dataclass(frozen=True)
class Reply:
    """A decoded reply ``@dd a [id] FLAG STATUS WW data``."""

    device: int
    axis: int
    ok: bool
    busy: bool
    warning: str
    data: str

    @property
    def fault(self) -> bool:
        """The warning flag is a fault (``F*``)."""
        return self.warning.startswith(FAULT_PREFIX)


@dataclass(frozen=True)
class Alert:
    """A decoded alert ``!dd a STATUS WW`` (unasked, e.g. when a move ends)."""

    device: int
    axis: int
    busy: bool
    warning: str


@dataclass(frozen=True)
class Info:
    """An info line ``#dd a text``."""

    device: int
    axis: int
    text: str


def _strip_checksum(text: str) -> str:
    """The message without its checksum, after checking it (if there is one)."""
    head, sep, tail = text.rpartition(":")
    if not sep or not re.fullmatch(r"[0-9A-Fa-f]{2}", tail):
        if sep and len(tail) == 2:
            raise DeviceProtocolError(f"bad checksum field in {text!r}")
        return text
    if checksum(head[1:]) != tail.upper():
        raise DeviceProtocolError(
            f"checksum mismatch in {text!r}: expected {checksum(head[1:])}"
        )
    return head


def decode_line(line: bytes) -> Reply | Alert | Info:
    """Decode one received line (terminator removed).

    Raises
    ------
    DeviceProtocolError
        Not ASCII, a wrong checksum, or no Zaber message.
    """
    try:
        text = line.decode("ascii").strip()
    except UnicodeDecodeError:
        raise DeviceProtocolError(f"not an ASCII line: {line[:40]!r}") from None
    text = _strip_checksum(text)
    if m := _REPLY.fullmatch(text):
        dev, ax, _id, flag, status, warn, data = m.groups()
        return Reply(int(dev), int(ax), flag == "OK", status == "BUSY", warn, data)
    if m := _ALERT.fullmatch(text):
        dev, ax, status, warn, _rest = m.groups()
        return Alert(int(dev), int(ax), status == "BUSY", warn)
    if m := _INFO.fullmatch(text):
        dev, ax, rest = m.groups()
        return Info(int(dev), int(ax), rest or "")
    raise DeviceProtocolError(f"not a Zaber ASCII message: {text[:60]!r}")
