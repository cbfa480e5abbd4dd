"""Driver of the Image Engineering CAL1 tunable LED light source.

:class:`Cal1LightSource` implements :class:`~tunespec.devices.protocols.LightSource`
on top of an injected :class:`~tunespec.devices.cal1.transport.Transport`; all bytes
come from :mod:`tunespec.devices.cal1.commands`. :func:`open_cal1` opens one from a
spec string::

    open_cal1("cal1:///dev/ttyUSB0")              # serial port (Linux)
    open_cal1("cal1://COM3")                      # serial port (Windows)
    open_cal1("cal1+socket://127.0.0.1:5025")     # the emulator (tunespec emulate cal1)
    open_cal1("cal1+loop://")                     # pyserial loopback: fails identification

Failure policy: every exchange has a timeout; a timeout, a lost connection, a reply
that breaks the protocol or an error reply raises the matching
:class:`~tunespec.devices.protocols.DeviceError` subclass whose message names the
device and what to check. Once the device has been identified as a CAL1, the driver
then tries to switch the lights off (reconnecting first if the link was lost) and the
message says whether that worked. Nothing is ever sent to an unidentified device but
``*IDN?``.
"""

from __future__ import annotations

import re
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError
from tunespec.core.spectra import Spectra
from tunespec.devices.cal1.commands import (
    BAUDRATE,
    COMMANDS,
    DEFAULT_TIMEOUT_S,
    MEASURE_TIMEOUT_S,
    RADIANCE_UNIT,
    TERMINATOR,
    Command,
    ErrorReply,
    Identity,
    MeasuredSpectrum,
    check_levels,
    decode_reply,
    encode_request,
    error_info,
    spectrum_problem,
)
from tunespec.devices.cal1.transport import SerialTransport, Transport
from tunespec.devices.protocols import (
    Channel,
    ClosesOnExit,
    DeviceBusyError,
    DeviceConnectionError,
    DeviceError,
    DeviceIdentity,
    DeviceProtocolError,
    DeviceTimeoutError,
    LightStatus,
)

__all__ = ["Cal1LightSource", "open_cal1", "parse_cal1_spec"]

#: pyserial URL schemes a ``cal1+<scheme>://`` spec may name.
URL_SCHEMES = ("socket", "loop", "rfc2217", "spy", "alt", "hwgrep")
#: Most stale lines skipped while waiting for the reply to the recovery ``OUTP:OFF``.
_MAX_STALE_LINES = 8


def parse_cal1_spec(spec: str) -> str:
    """The pyserial URL or port name of a CAL1 spec string.

    Examples
    --------
    >>> parse_cal1_spec("cal1:///dev/ttyUSB0")
    '/dev/ttyUSB0'
    >>> parse_cal1_spec("cal1+socket://127.0.0.1:5025")
    'socket://127.0.0.1:5025'
    >>> parse_cal1_spec("cal1+loop://")
    'loop://'

    Raises
    ------
    InputError
        If ``spec`` is not ``cal1://PORT`` or ``cal1+SCHEME://...``.
    """
    m = re.fullmatch(r"cal1(?:\+([A-Za-z0-9]+))?://(.*)", spec.strip())
    if m is None:
        raise InputError(
            f"bad light source spec {spec!r}: expected cal1:///dev/ttyUSB0, "
            "cal1://COM3 or cal1+socket://HOST:PORT"
        )
    scheme, rest = m.groups()
    if scheme is not None:
        if scheme.lower() not in URL_SCHEMES:
            raise InputError(
                f"bad light source spec {spec!r}: unknown scheme cal1+{scheme}; "
                f"known: {', '.join('cal1+' + s for s in URL_SCHEMES)}"
            )
        if scheme.lower() == "socket":
            _check_host_port(spec, rest)
        return f"{scheme.lower()}://{rest}"
    if not rest:
        raise InputError(f"bad light source spec {spec!r}: no serial port given")
    return rest


def _check_host_port(spec: str, rest: str) -> None:
    """InputError unless ``rest`` is ``HOST:PORT`` with a port in 1-65535.

    pyserial reports a malformed socket URL with an unrelated message (its logging
    options, or a comparison with ``None``), so it is checked here first.
    """
    host, sep, port = rest.partition("?")[0].rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(
            f"bad light source spec {spec!r}: expected cal1+socket://HOST:PORT with a "
            "port number 1-65535"
        )


class Cal1LightSource(ClosesOnExit):
    """The CAL1 as a :class:`~tunespec.devices.protocols.LightSource`.

    Blocking and not thread-safe: one owner thread. Identity and channel list are
    read from the device on first use and cached.

    Parameters
    ----------
    transport
        An open line transport (injected; the driver opens nothing itself). The driver
        owns it from now on and closes it in :meth:`close`.
    spec
        The spec string it was opened from (goes into :attr:`identity`).
    timeout_s
        Reply timeout of ordinary commands.
    measure_timeout_s
        Reply timeout of a spectrum measurement.
    recovery_timeout_s
        Time allowed for switching the lights off after a failure; default
        ``2 * timeout_s``.
    recheck_timeout_s
        When switching off did not answer in time, how long to wait for the
        levels (``CHAN:LEVEL:ALL?``) before telling the operator the lights may be
        on: a reply delayed by the CAL1 may still switch them off. Default
        ``measure_timeout_s`` (the longest any command may take).
    """

    def __init__(
        self,
        transport: Transport,
        *,
        spec: str = "",
        timeout_s: float = DEFAULT_TIMEOUT_S,
        measure_timeout_s: float = MEASURE_TIMEOUT_S,
        recovery_timeout_s: float | None = None,
        recheck_timeout_s: float | None = None,
    ) -> None:
        if timeout_s <= 0 or measure_timeout_s <= 0:
            raise ValueError("timeouts must be positive")
        self._transport = transport
        self._spec = spec
        self._timeout_s = float(timeout_s)
        self._measure_timeout_s = float(measure_timeout_s)
        self._recovery_timeout_s = float(
            2.0 * timeout_s if recovery_timeout_s is None else recovery_timeout_s
        )
        self._recheck_timeout_s = float(
            measure_timeout_s if recheck_timeout_s is None else recheck_timeout_s
        )
        self._identity: DeviceIdentity | None = None
        self._channels: list[Channel] | None = None
        self._closed = False

    # --- LightSource ------------------------------------------------------------------

    @property
    def identity(self) -> DeviceIdentity:
        """Vendor, model, serial and firmware from ``*IDN?`` (read once)."""
        if self._identity is None:
            idn = self._exchange("identify")
            assert isinstance(idn, Identity)
            if "CAL1" not in idn.model.upper():
                raise DeviceProtocolError(
                    f"{self._name}: the device answers *IDN? with "
                    f"'{idn.vendor},{idn.model}', which is not a CAL1. Check that "
                    f"{self._transport.url} is the CAL1's port."
                )
            self._identity = DeviceIdentity(
                vendor=idn.vendor,
                model=idn.model,
                serial=idn.serial,
                firmware=idn.firmware,
                spec=self._spec or self._transport.url,
            )
        return self._identity

    def channels(self) -> list[Channel]:
        """The LED channels in device order (from ``CHAN:COUNT?`` and ``CHAN:LIST?``)."""
        if self._channels is None:
            self._ensure_identified()
            count = self._exchange("channel_count")
            infos = self._exchange("channel_list")
            assert isinstance(count, int) and isinstance(infos, list)
            if len(infos) != count:
                raise self._failure(
                    DeviceProtocolError(
                        f"CHAN:LIST? lists {len(infos)} channels, CHAN:COUNT? "
                        f"says {count}"
                    ),
                    COMMANDS["channel_list"],
                    self._timeout_s,
                )
            self._channels = [
                Channel(index=i, name=c.name, peak_nm=c.peak_nm, kind=c.kind)
                for i, c in enumerate(infos)
            ]
        return list(self._channels)

    def set_levels(self, levels: ArrayLike) -> None:
        """Set every channel's level, each in [0, 1], shape (n_channels,).

        Levels are sent with 4 decimals (the wire format).

        Raises
        ------
        ValueError
            Wrong shape, non-finite or out-of-range levels (nothing is sent).
        """
        arr = check_levels(levels, len(self.channels()))
        self._exchange("set_levels", arr)

    def set_level(self, index: int, level: float) -> None:
        """Set one channel (``index`` from 0) to ``level`` in [0, 1]."""
        n = len(self.channels())
        if not 0 <= index < n:
            raise ValueError(f"channel index {index} outside 0..{n - 1}")
        if not 0.0 <= level <= 1.0:
            raise ValueError(f"level {level!r} is outside 0..1")
        self._exchange("set_level", index, level)

    def levels(self) -> NDArray[np.float64]:
        """The levels the device reports as set, shape (n_channels,)."""
        n = len(self.channels())
        levels = self._exchange("get_levels")
        assert isinstance(levels, np.ndarray)
        if levels.shape != (n,):
            raise self._failure(
                DeviceProtocolError(f"{levels.size} levels reported for {n} channels"),
                COMMANDS["get_levels"],
                self._timeout_s,
            )
        return levels

    def all_off(self) -> None:
        """Switch every channel off."""
        self._ensure_identified()
        self._exchange("all_off")

    def measure_spd(self) -> Spectra:
        """The SPD emitted now as the internal spectroradiometer reports it.

        Returns
        -------
        Spectra
            One spectrum named ``"measured"`` on the spectroradiometer's wavelengths,
            in W sr^-1 m^-2 nm^-1; ``meta`` holds ``unit``, ``device`` and ``source``.
        """
        self._ensure_identified()
        spectrum = self._exchange("measure_spd")
        assert isinstance(spectrum, MeasuredSpectrum)
        problem = spectrum_problem(spectrum)
        if problem:
            v = spectrum.values
            reply = f"{spectrum.start_nm:g},{spectrum.step_nm:g},{v.size},{v[0]:g},..."
            exc = DeviceProtocolError(
                f"{self._name}: impossible reply {reply} to MEAS:SPD?: {problem}. "
                "Check the spectroradiometer (its cap, its calibration) and measure "
                "again."
            )
            raise DeviceProtocolError(str(exc) + self._switch_off_after_failure(exc))
        ident = self.identity
        return Spectra(
            spectrum.wavelength_nm,
            spectrum.values[np.newaxis, :],
            ("measured",),
            {
                "unit": RADIANCE_UNIT,
                "device": f"{ident.vendor} {ident.model} {ident.serial}".strip(),
                "source": ident.spec,
            },
        )

    def status(self) -> LightStatus:
        """Readiness, temperature and on-time from ``SYST:STAT?``.

        Keys other than ``READY``, ``TEMP_C``, ``ON_S`` and ``MSG`` go to ``extra``
        in lower case (e.g. ``warmup_left_s``).
        """
        self._ensure_identified()
        fields = self._exchange("status")
        assert isinstance(fields, dict)
        known = {"READY", "TEMP_C", "ON_S", "MSG"}
        return LightStatus(
            ready=fields["READY"] == "1",
            temperature_c=float(fields["TEMP_C"]),
            on_time_s=float(fields["ON_S"]),
            message=fields.get("MSG", ""),
            extra={k.lower(): v for k, v in fields.items() if k not in known},
        )

    def close(self) -> None:
        """Switch the lights off and release the transport; idempotent.

        Raises
        ------
        DeviceError
            If the lights could not be switched off (the transport is released
            anyway, and the message says to switch the CAL1 off by hand).
        """
        if self._closed:
            return
        try:
            if self._identity is not None and self._transport.is_open:
                self._exchange("all_off")
        finally:
            self._closed = True
            self._transport.close()

    def __repr__(self) -> str:
        return f"Cal1LightSource({self._transport!r}, closed={self._closed})"

    # --- exchanges and failures -------------------------------------------------------

    @property
    def _name(self) -> str:
        serial = f" {self._identity.serial}" if self._identity is not None else ""
        return f"CAL1 light source{serial} on {self._transport.url}"

    def _ensure_identified(self) -> None:
        self.identity  # noqa: B018 (reads *IDN? once; needed before recovery is allowed)

    def _exchange(self, key: str, *args: Any) -> Any:
        """Send command ``key`` and decode its reply; failures raise with context."""
        if self._closed:
            raise DeviceConnectionError(
                f"{self._name} was closed; open it again to use it"
            )
        cmd = COMMANDS[key]
        request = encode_request(key, *args)
        timeout_s = self._measure_timeout_s if cmd.slow else self._timeout_s
        try:
            self._transport.reset_input()
            self._transport.write(request)
            line = self._transport.read_line(timeout_s)
            if line == request.removesuffix(TERMINATOR):
                raise DeviceProtocolError(
                    f"the port echoes {cmd.keyword} back instead of answering: it is "
                    "a loopback (e.g. cal1+loop://) or not a CAL1"
                )
            return decode_reply(key, line)
        except DeviceError as exc:
            raise self._failure(exc, cmd, timeout_s) from exc

    def _failure(self, exc: DeviceError, cmd: Command, timeout_s: float) -> DeviceError:
        """The operator-facing error for ``exc``, after trying to switch off."""
        cls: type[DeviceError]
        if isinstance(exc, ErrorReply):
            info = error_info(exc.code)
            cls = info.exc_class
            what = f"refused {cmd.keyword} with ERR {exc.code} {exc.text}".rstrip()
            check = info.hint[0].upper() + info.hint[1:]
        elif isinstance(exc, DeviceTimeoutError):
            cls = DeviceTimeoutError
            what = (
                f"sending {cmd.keyword} timed out ({exc})"
                if str(exc).startswith("write")
                else f"no reply to {cmd.keyword} within {timeout_s:g} s"
            )
            check = (
                "Check that the CAL1 is switched on and its USB cable is plugged in, "
                "and that no other program is talking to it"
            )
        elif isinstance(exc, DeviceConnectionError):
            cls = DeviceConnectionError
            what = f"connection lost during {cmd.keyword} ({exc})"
            check = "Check the USB cable and the CAL1's power, then reconnect"
        elif isinstance(exc, DeviceBusyError):
            cls = DeviceBusyError
            what = f"busy during {cmd.keyword} ({exc})"
            check = "Close the other program using the CAL1 and retry"
        else:
            cls = DeviceProtocolError
            what = f"unexpected reply to {cmd.keyword}: {exc}"
            check = (
                f"Check that {self._transport.url} is the CAL1's port and the serial "
                f"settings ({BAUDRATE} baud, 8N1); see devices/cal1/PROTOCOL.md"
            )
        note = self._switch_off_after_failure(exc)
        return cls(f"{self._name}: {what}. {check}.{note}")

    def _switch_off_after_failure(self, exc: DeviceError) -> str:
        """Try ``OUTP:OFF`` after a failure; returns a sentence for the message."""
        if self._identity is None:
            return ""
        if isinstance(exc, ErrorReply) and error_info(exc.code).exc_class is (
            DeviceBusyError
        ):
            return ""  # another client owns the CAL1; leave its lights alone
        try:
            if isinstance(exc, DeviceConnectionError) or not self._transport.is_open:
                self._transport.reopen()
            self._transport.reset_input()
            self._transport.write(encode_request("all_off"))
            deadline = time.monotonic() + self._recovery_timeout_s
            for _ in range(_MAX_STALE_LINES):
                line = self._transport.read_line(max(0.0, deadline - time.monotonic()))
                try:
                    decode_reply("all_off", line)
                except DeviceProtocolError:
                    continue  # a late reply to the command that failed
                return " The lights were switched off."
            raise DeviceProtocolError("no OK among the replies")
        except DeviceError as off_exc:
            # only a late answer can hide a switch-off that happened; a refusal cannot
            if (
                isinstance(off_exc, DeviceTimeoutError)
                and self._lights_off_on_recheck()
            ):
                return " The lights were switched off (confirmed by a second check)."
            return (
                f" The lights could NOT be switched off ({off_exc}): switch the CAL1 "
                "off at its power switch before handling the sample."
            )

    def _lights_off_on_recheck(self) -> bool:
        """Ask for the levels once more, waiting out late replies; True if all off.

        A CAL1 that answered late still executes the ``OUTP:OFF`` queued behind the
        late command, so the lights may be off although switching off timed out.
        """
        try:
            if not self._transport.is_open:
                return False
            self._transport.write(encode_request("get_levels"))
            deadline = time.monotonic() + self._recheck_timeout_s
            for _ in range(2 * _MAX_STALE_LINES):
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                line = self._transport.read_line(left)
                try:
                    levels = list(decode_reply("get_levels", line))
                except DeviceProtocolError:
                    continue  # a late reply to an earlier command
                n = None if self._channels is None else len(self._channels)
                if n is not None and len(levels) != n:
                    continue  # e.g. a late spectrum: numbers, but not the levels
                return not any(float(v) > 0 for v in levels)
        except DeviceError:
            return False
        return False


def open_cal1(
    spec: str,
    *,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    measure_timeout_s: float = MEASURE_TIMEOUT_S,
    recovery_timeout_s: float | None = None,
    recheck_timeout_s: float | None = None,
    baudrate: int = BAUDRATE,
) -> Cal1LightSource:
    """Open a CAL1 from a spec string and check that it is one.

    Reads ``*IDN?`` and the channel list; the levels are left as they are.

    Parameters
    ----------
    spec
        ``cal1:///dev/ttyUSB0``, ``cal1://COM3``, ``cal1+socket://HOST:PORT`` (the
        emulator), ``cal1+loop://`` (pyserial loopback, for transport tests only).
    timeout_s, measure_timeout_s, recovery_timeout_s, recheck_timeout_s
        See :class:`Cal1LightSource`.
    baudrate
        Serial speed (ignored by ``socket://`` and ``loop://``).

    Raises
    ------
    InputError
        Malformed spec.
    DeviceConnectionError, DeviceBusyError
        The port cannot be opened / is in use.
    DeviceError
        The device does not answer as a CAL1.
    """
    url = parse_cal1_spec(spec)
    try:
        transport = SerialTransport.open(
            url, baudrate=baudrate, write_timeout_s=timeout_s
        )
    except DeviceError as exc:
        if url.startswith("socket://"):
            check = (
                "Check that the emulator runs there "
                "(tunespec emulate cal1 --port PORT) or that the address is right"
            )
        else:
            check = (
                "Check that the CAL1 is switched on and connected by USB and that "
                f"{url} is its port (Linux: ls /dev/ttyUSB*; Windows: Device Manager)"
            )
        if isinstance(exc, DeviceBusyError):
            check = "Close the other program using the port and retry"
        elif "permission" in str(exc).lower():
            check = (
                "You may not use the port: on Linux add your user to the 'dialout' "
                "group and log in again"
            )
        raise type(exc)(f"CAL1 light source: {exc}. {check}.") from exc
    device = Cal1LightSource(
        transport,
        spec=spec,
        timeout_s=timeout_s,
        measure_timeout_s=measure_timeout_s,
        recovery_timeout_s=recovery_timeout_s,
        recheck_timeout_s=recheck_timeout_s,
    )
    try:
        device.identity  # noqa: B018 (identification on open)
        device.channels()
    except BaseException:
        transport.close()
        raise
    return device
