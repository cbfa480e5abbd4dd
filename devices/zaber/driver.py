"""A goniometer of Zaber motorised rotation stages, over Zaber's ASCII protocol.

:class:`ZaberGoniometer` implements :class:`~tunespec.devices.goniometer.Goniometer`
on an injected line transport (the CAL1's :class:`SerialTransport` works unchanged:
pyserial port, ``socket://`` for the emulator, ``loop://``), so it is tested against
scripted exchanges (:mod:`tunespec.devices.testing`) and the emulator
(:mod:`tunespec.devices.zaber.emulator`). Each goniometer axis is one Zaber axis
(device number on the daisy chain, axis number on the controller) with its scale
(degrees per microstep) and offset.

A move is ``move abs`` per axis, then polling (``/d a``, the empty command) until the
axis is IDLE, then ``get pos`` to read the position back. A fault flag (``F*``), a
rejection (``RJ``), a timeout (the axes are then stopped) or a position read back
further than ``tolerance`` from the target raises a
:class:`~tunespec.devices.protocols.DeviceError` naming the axis and what to check.
Alerts (``!``) and info lines (``#``) that arrive between replies are read and kept
(:attr:`ZaberGoniometer.alerts`); a fault alert fails the move.

Spec strings (:func:`open_zaber`)::

    zaber:///dev/ttyUSB0?axes=theta_i:1:1:0.000234375,theta_r:2:1:0.000234375
    zaber+socket://127.0.0.1:PORT?axes=...         (the emulator)

``axes=NAME:DEVICE:AXIS:DEG_PER_STEP[:OFFSET_DEG]`` (comma-separated); default: the
four angle axes on devices 1-4, axis 1, :data:`DEFAULT_DEG_PER_STEP` (set the scale
of the stages in use from their data sheet).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from urllib.parse import parse_qs

from tunespec.core.errors import InputError
from tunespec.devices.cal1.transport import SerialTransport, Transport
from tunespec.devices.goniometer import ANGLE_AXES, AxisInfo, check_target
from tunespec.devices.protocols import (
    ClosesOnExit,
    DeviceCommandError,
    DeviceError,
    DeviceIdentity,
    DeviceProtocolError,
    DeviceTimeoutError,
)
from tunespec.devices.zaber.protocol import (
    BAUDRATE,
    Alert,
    Info,
    Reply,
    decode_line,
    encode_command,
)

__all__ = ["DEFAULT_DEG_PER_STEP", "ZaberAxis", "ZaberGoniometer", "open_zaber"]

#: Degrees per microstep of the default axes (a typical Zaber rotary stage; set the
#: value of the stage in use).
DEFAULT_DEG_PER_STEP = 0.000234375
#: Lines skipped while waiting for one reply (alerts, info, stale replies).
_MAX_SKIPPED = 32


@dataclass(frozen=True)
class ZaberAxis:
    """A goniometer axis on a Zaber stage: ``position_deg = steps * scale + offset``."""

    name: str
    device: int
    axis: int = 1
    deg_per_step: float = DEFAULT_DEG_PER_STEP
    offset_deg: float = 0.0

    def __post_init__(self) -> None:
        if not 1 <= self.device <= 99 or not 1 <= self.axis <= 9:
            raise InputError(
                f"zaber axis {self.name}: device 1-99 and axis 1-9, got "
                f"{self.device}/{self.axis}"
            )
        if not self.deg_per_step != 0:
            raise InputError(f"zaber axis {self.name}: deg_per_step must not be 0")

    def to_steps(self, deg: float) -> int:
        return round((deg - self.offset_deg) / self.deg_per_step)

    def to_deg(self, steps: float) -> float:
        return steps * self.deg_per_step + self.offset_deg


class ZaberGoniometer(ClosesOnExit):
    """Zaber stages as a :class:`~tunespec.devices.goniometer.Goniometer`.

    Parameters
    ----------
    transport
        An open line transport (terminator ``\\n``; ``\\r`` is stripped).
    axes
        The axes, one per goniometer axis name.
    spec
        The spec it was opened from (for :attr:`identity`).
    timeout_s
        Reply timeout of one command.
    move_timeout_s
        Longest a move or homing may take; then the axes are stopped.
    poll_s
        Interval of status polls while an axis moves.
    tolerance_deg
        Largest difference between target and the position read back.
    use_checksum
        Append ``:CC`` to every command.
    """

    def __init__(
        self,
        transport: Transport,
        axes: Sequence[ZaberAxis],
        *,
        spec: str = "",
        timeout_s: float = 1.0,
        move_timeout_s: float = 60.0,
        poll_s: float = 0.05,
        tolerance_deg: float = 0.01,
        use_checksum: bool = False,
    ) -> None:
        names = [a.name for a in axes]
        if not axes or len(set(names)) != len(names):
            raise InputError(f"zaber: need distinct axis names, got {names}")
        self._t = transport
        self._axes = {a.name: a for a in axes}
        self._spec = spec
        self._timeout_s = timeout_s
        self._move_timeout_s = move_timeout_s
        self._poll_s = poll_s
        self._tolerance_deg = tolerance_deg
        self._checksum = use_checksum
        self._limits: list[AxisInfo] | None = None
        self._identity: DeviceIdentity | None = None
        #: Alerts received unasked, in order.
        self.alerts: list[Alert] = []

    # --- exchanges -----------------------------------------------------------------

    def _send(self, ax: ZaberAxis | None, command: str, device: int = 0) -> Reply:
        """One command and its reply; alerts and info lines are kept or skipped."""
        dev = ax.device if ax is not None else device
        axis = ax.axis if ax is not None else 0
        where = f"Zaber device {dev} axis {axis} on {self._t.url}"
        self._t.write(encode_command(dev, axis, command, with_checksum=self._checksum))
        for _ in range(_MAX_SKIPPED):
            try:
                msg = decode_line(self._t.read_line(self._timeout_s))
            except DeviceTimeoutError as exc:
                raise DeviceTimeoutError(
                    f"{where}: no reply to '{command}' ({exc}); check the cable, the "
                    "baud rate (115200) and that the device is in ASCII mode"
                ) from exc
            if isinstance(msg, Alert):
                self.alerts.append(msg)
                continue
            if isinstance(msg, Info):
                continue
            if (msg.device, msg.axis) != (dev, axis):
                continue  # a stale reply to an earlier command
            if not msg.ok:
                raise DeviceCommandError(
                    f"{where}: '{command}' rejected ({msg.data or 'no reason'}; "
                    f"warning flag {msg.warning})"
                )
            return msg
        raise DeviceProtocolError(f"{where}: no reply to '{command}' among the lines")

    def _number(self, ax: ZaberAxis | None, command: str, device: int = 0) -> float:
        reply = self._send(ax, command, device)
        try:
            return float(reply.data.split()[0])
        except (ValueError, IndexError):
            raise DeviceProtocolError(
                f"Zaber: '{command}' answered {reply.data!r}, expected a number"
            ) from None

    # --- Goniometer ----------------------------------------------------------------

    @property
    def identity(self) -> DeviceIdentity:
        """Device id, serial and firmware of the first axis's device."""
        if self._identity is None:
            dev = next(iter(self._axes.values())).device
            model = int(self._number(None, "get device.id", dev))
            serial = int(self._number(None, "get system.serial", dev))
            version = self._send(None, "get version", dev).data
            self._identity = DeviceIdentity(
                "Zaber", f"device id {model}", str(serial), version,
                self._spec or self._t.url,
            )  # fmt: skip
        return self._identity

    def axes(self) -> list[AxisInfo]:
        """The axes with their limits (``get limit.min`` / ``limit.max``, read once)."""
        if self._limits is None:
            out = []
            for ax in self._axes.values():
                lo = ax.to_deg(self._number(ax, "get limit.min"))
                hi = ax.to_deg(self._number(ax, "get limit.max"))
                out.append(AxisInfo(ax.name, "deg", min(lo, hi), max(lo, hi)))
            self._limits = out
        return list(self._limits)

    def home(self) -> None:
        """Home every axis, then wait for all of them."""
        for ax in self._axes.values():
            self._send(ax, "home")
        for ax in self._axes.values():
            self._wait_idle(ax, "home")

    def is_homed(self) -> bool:
        """False if any axis shows the no-reference warning ``WR``."""
        return all(self._send(ax, "").warning != "WR" for ax in self._axes.values())

    def move_to(self, targets: Mapping[str, float]) -> dict[str, float]:
        """Move, wait and read back; see :class:`Goniometer`."""
        check_target(self.axes(), targets)
        moving = [self._axes[n] for n in targets]
        for ax in moving:
            self._send(ax, f"move abs {ax.to_steps(targets[ax.name])}")
        for ax in moving:
            self._wait_idle(ax, "move")
        got = self.position()
        for name, want in targets.items():
            if abs(got[name] - want) > self._tolerance_deg:
                raise DeviceError(
                    f"Zaber axis {name} ended at {got[name]:.4f} deg, target "
                    f"{want:.4f} deg: check for an obstruction and re-home"
                )
        return got

    def position(self) -> dict[str, float]:
        """Positions read back (``get pos``), in degrees."""
        return {
            n: ax.to_deg(self._number(ax, "get pos")) for n, ax in self._axes.items()
        }

    def stop(self) -> None:
        """``stop`` every axis; the first failure is raised after trying all."""
        first: DeviceError | None = None
        for ax in self._axes.values():
            try:
                self._send(ax, "stop")
            except DeviceError as exc:
                first = first or exc
        if first is not None:
            raise first

    def close(self) -> None:
        """Release the transport; idempotent (the stages hold their position)."""
        self._t.close()

    # --- helpers -------------------------------------------------------------------

    def _wait_idle(self, ax: ZaberAxis, what: str) -> None:
        """Poll until ``ax`` is IDLE; stop everything on a fault or the deadline."""
        deadline = time.monotonic() + self._move_timeout_s
        while True:
            reply = self._send(ax, "")
            faults = [a.warning for a in self.alerts if a.warning.startswith("F")]
            if reply.fault or faults:
                flag = reply.warning if reply.fault else faults[-1]
                self.alerts.clear()
                self._stop_quietly()
                raise DeviceError(
                    f"Zaber axis {ax.name} (device {ax.device}): {what} failed with "
                    f"fault {flag} (e.g. FS stalled, FD driver disabled); clear it "
                    "and re-home"
                )
            if not reply.busy:
                return
            if time.monotonic() > deadline:
                self._stop_quietly()
                raise DeviceTimeoutError(
                    f"Zaber axis {ax.name}: {what} not finished after "
                    f"{self._move_timeout_s:g} s; the axes were stopped"
                )
            time.sleep(self._poll_s)

    def _stop_quietly(self) -> None:
        with contextlib.suppress(DeviceError):
            self.stop()


def _parse_axes(text: str, spec: str) -> list[ZaberAxis]:
    out = []
    for part in text.split(","):
        fields = part.split(":")
        try:
            if not 4 <= len(fields) <= 5:
                raise ValueError
            name, dev, ax, scale = (
                fields[0],
                int(fields[1]),
                int(fields[2]),
                float(fields[3]),
            )
            offset = float(fields[4]) if len(fields) == 5 else 0.0
        except ValueError:
            raise InputError(
                f"bad goniometer spec {spec!r}: axes=NAME:DEVICE:AXIS:DEG_PER_STEP"
                f"[:OFFSET_DEG], got {part!r}"
            ) from None
        out.append(ZaberAxis(name, dev, ax, scale, offset))
    return out


def open_zaber(spec: str, **kwargs: object) -> ZaberGoniometer:
    """A :class:`ZaberGoniometer` from ``zaber://PORT`` or ``zaber+socket://H:P``.

    Raises
    ------
    InputError
        A malformed spec.
    DeviceError
        The port cannot be opened.
    """
    head, _, query = spec.strip().partition("?")
    if head.startswith("zaber+socket://"):
        url = "socket://" + head.removeprefix("zaber+socket://")
    elif head.startswith("zaber://"):
        url = head.removeprefix("zaber://")
    else:
        raise InputError(
            f"bad goniometer spec {spec!r}: expected zaber:///dev/ttyUSB0 or "
            "zaber+socket://HOST:PORT"
        )
    if not url or url == "socket://":
        raise InputError(f"bad goniometer spec {spec!r}: no port given")
    q = {k: v[-1] for k, v in parse_qs(query).items()}
    axes = (
        _parse_axes(q["axes"], spec)
        if "axes" in q
        else [ZaberAxis(n, i + 1) for i, n in enumerate(ANGLE_AXES)]
    )
    transport = SerialTransport.open(url, baudrate=BAUDRATE)
    return ZaberGoniometer(transport, axes, spec=spec, **kwargs)  # type: ignore[arg-type]
