"""A CAL1 emulator: the assumed CAL1 protocol served on a local TCP port.

pyserial's ``socket://`` handler reaches it, so the real driver runs unchanged
against it: ``open_cal1("cal1+socket://127.0.0.1:PORT")``. The light it "emits" is a
:class:`~tunespec.devices.sim.led_physics.LedPhysics` unit, exposed as
:attr:`Cal1Emulator.physics` so a simulated camera in the same process sees what is
emitted. Requests and replies are made by :mod:`tunespec.devices.cal1.commands`, the
same table the driver uses.

Behaviour: one client at a time (another one gets ``ERR 409`` to its first request
and is disconnected); the unit keeps its state when a client disconnects, as a
serial device does; bad requests get ``ERR <code> <text>``. For tests, faults can be
injected (:meth:`Cal1Emulator.inject_fault`): delay a reply (real time, as socket
timeouts are real), send no reply, drop the connection, send garbage or an error.

Run it from the command line with ``tunespec emulate cal1 --port N``.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from tunespec.devices.cal1.commands import (
    MAX_LINE_BYTES,
    TERMINATOR,
    ChannelInfo,
    ErrorCode,
    ErrorReply,
    Identity,
    MeasuredSpectrum,
    Request,
    decode_request,
    encode_error,
    encode_reply,
)
from tunespec.devices.clock import Clock, RealClock
from tunespec.devices.line_io import LineServer, received_lines
from tunespec.devices.protocols import ClosesOnExit
from tunespec.devices.sim.led_physics import LedPhysics

__all__ = ["GARBAGE", "Cal1Emulator", "FaultKind"]

_log = logging.getLogger(__name__)

FaultKind = Literal["delay", "no_reply", "drop", "garbage", "error"]
#: Default reply of a ``garbage`` fault: line noise, not ASCII, with a terminator.
GARBAGE = b"\x00\xfe#\x8f~?garbage\xff" + TERMINATOR
VENDOR = "Image Engineering"
MODEL = "CAL1"
FIRMWARE = "emulator-1.0"


@dataclass
class _Fault:
    kind: FaultKind
    command: str | None
    skip: int
    delay_s: float
    payload: bytes
    code: int
    text: str


class Cal1Emulator(ClosesOnExit):
    """Serve the CAL1 protocol for one simulated unit on ``host:port`` (TCP).

    Starts listening at once (so :attr:`port` is known); use it as a context manager
    or call :meth:`close`.

    Parameters
    ----------
    port
        TCP port; 0 picks a free one.
    physics
        The simulated unit; default ``LedPhysics(clock=clock, seed=seed)``.
    clock
        Time source when ``physics`` is not given: default ``RealClock`` (a server
        for people); tests pass a ``VirtualClock``. If both are given, it must be
        ``physics.clock``.
    seed
        Unit and noise seed when ``physics`` is not given; also the serial number.
    host
        Interface to listen on (local only by default).
    poll_s
        How often the serving threads check for :meth:`close`.
    """

    def __init__(
        self,
        port: int = 0,
        physics: LedPhysics | None = None,
        clock: Clock | None = None,
        *,
        seed: int = 0,
        host: str = "127.0.0.1",
        poll_s: float = 0.05,
    ) -> None:
        if physics is None:
            physics = LedPhysics(
                clock=clock if clock is not None else RealClock(), seed=seed
            )
        elif clock is not None and clock is not physics.clock:
            raise ValueError("clock must be physics.clock (one clock per unit)")
        self.physics = physics
        self.serial = f"EMU{physics.seed:05d}"
        #: Every request line received, decoded, in order (for tests).
        self.received: list[str] = []
        #: Unexpected exceptions of the serving threads (tests assert it is empty).
        self.errors: list[BaseException] = []
        self._poll_s = poll_s
        self._faults: list[_Fault] = []
        self._lock = threading.Lock()
        self._client: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        self._handlers: dict[str, Callable[[Request], bytes]] = {
            "identify": self._identify,
            "channel_count": self._channel_count,
            "channel_list": self._channel_list,
            "set_level": self._set_level,
            "set_levels": self._set_levels,
            "get_levels": self._get_levels,
            "all_off": self._all_off,
            "measure_spd": self._measure_spd,
            "status": self._status,
        }
        self._server = LineServer(
            host, port, poll_s, self._accept, name="cal1-emulator"
        )
        self._stop = self._server.stop
        self.host, self.port = self._server.host, self._server.port
        _log.info("CAL1 emulator listening on %s", self.url)

    # --- public -----------------------------------------------------------------------

    @property
    def clock(self) -> Clock:
        """The unit's clock."""
        return self.physics.clock

    @property
    def url(self) -> str:
        """pyserial URL, ``socket://HOST:PORT``."""
        return f"socket://{self.host}:{self.port}"

    @property
    def spec(self) -> str:
        """Light source spec for :func:`~tunespec.devices.cal1.driver.open_cal1`."""
        return f"cal1+socket://{self.host}:{self.port}"

    @property
    def levels(self) -> NDArray[np.float64]:
        """The levels now set on the unit, shape (n_channels,)."""
        return self.physics.levels()

    @property
    def lights_on(self) -> bool:
        """Whether any channel is on."""
        return self.physics.lights_on

    def inject_fault(
        self,
        kind: FaultKind,
        *,
        command: str | None = None,
        skip: int = 0,
        delay_s: float = 1.0,
        payload: bytes = GARBAGE,
        code: int = ErrorCode.INTERNAL,
        text: str = "injected fault",
    ) -> None:
        """Misbehave once, on a later request.

        Parameters
        ----------
        kind
            ``"delay"``: answer normally after ``delay_s`` (real seconds);
            ``"no_reply"``: execute nothing and answer nothing; ``"drop"``: close the
            connection instead of executing; ``"garbage"``: answer ``payload``
            instead of executing; ``"error"``: answer ``ERR code text`` instead.
        command
            Wire keyword to act on (e.g. ``"MEAS:SPD?"``, case-insensitive); ``None``
            for any request.
        skip
            Matching requests to serve normally first.
        """
        if kind not in ("delay", "no_reply", "drop", "garbage", "error"):
            raise ValueError(f"unknown fault kind {kind!r}")
        fault = _Fault(kind, command, skip, delay_s, payload, int(code), text)
        with self._lock:
            self._faults.append(fault)

    def close(self) -> None:
        """Stop serving, disconnect the client and release the port; idempotent."""
        self._server.close()
        for t in list(self._threads):
            t.join(timeout=5.0)
        self._threads.clear()

    def __repr__(self) -> str:
        return f"Cal1Emulator({self.spec!r}, seed={self.physics.seed})"

    # --- serving ----------------------------------------------------------------------

    def _accept(self, conn: socket.socket, address: tuple[str, int]) -> None:
        """Serve the first client on a thread of its own; answer a second one busy."""
        with self._lock:
            busy = self._client is not None
            if not busy:
                self._client = conn
        target = self._reject if busy else self._serve
        thread = threading.Thread(
            target=self._guarded,
            args=(target, conn),
            name=f"cal1-emulator:{self.port}:{address[1]}",
            daemon=True,
        )
        self._threads = [t for t in self._threads if t.is_alive()]
        self._threads.append(thread)
        thread.start()

    def _guarded(
        self, target: Callable[[socket.socket], None], conn: socket.socket
    ) -> None:
        """Run a connection handler; never let an exception escape the thread."""
        try:
            target(conn)
        except Exception as exc:  # recorded for tests and logged, never re-raised
            self.errors.append(exc)
            _log.exception("CAL1 emulator: internal error")
        finally:
            with self._lock:
                if self._client is conn:
                    # Freed before the socket closes, so a client reconnecting after
                    # seeing the close is never taken for a second client.
                    self._client = None
            conn.close()

    def _serve(self, conn: socket.socket) -> None:
        """Answer request lines until the client leaves, a drop fault or close()."""

        def overflow() -> None:
            conn.sendall(encode_error(ErrorCode.LINE_TOO_LONG, "line too long"))

        for line in received_lines(
            conn, self._stop, TERMINATOR, MAX_LINE_BYTES, overflow
        ):
            try:
                if not self._respond(conn, line.removesuffix(b"\r")):
                    return  # dropped on purpose
            except OSError:
                return  # the client went away while we answered

    def _reject(self, conn: socket.socket) -> None:
        """Answer a second client's first request with ERR 409, then disconnect."""
        deadline = 20  # poll intervals to wait for its request
        data = b""
        while TERMINATOR not in data and deadline > 0 and not self._stop.is_set():
            try:
                chunk = conn.recv(4096)
            except TimeoutError:
                deadline -= 1
                continue
            except OSError:
                return
            if not chunk:
                return
            data += chunk
        with contextlib.suppress(OSError):
            conn.sendall(
                encode_error(ErrorCode.BUSY, "busy: another client is connected")
            )

    def _respond(self, conn: socket.socket, line: bytes) -> bool:
        """Answer one request line; False if the connection is to be dropped."""
        text = line.decode("ascii", "replace").strip()
        self.received.append(text)
        fault = self._take_fault(text)
        if fault is not None:
            _log.info("CAL1 emulator: injected %s on %r", fault.kind, text)
            if fault.kind == "drop":
                return False
            if fault.kind == "no_reply":
                return True
            if fault.kind == "garbage":
                conn.sendall(fault.payload)
                return True
            if fault.kind == "error":
                conn.sendall(encode_error(fault.code, fault.text))
                return True
            self._stop.wait(fault.delay_s)
        conn.sendall(self._execute(line))
        return True

    def _take_fault(self, text: str) -> _Fault | None:
        keyword = text.split(maxsplit=1)[0].upper() if text else ""
        with self._lock:
            for i, fault in enumerate(self._faults):
                if fault.command is None or fault.command.upper() == keyword:
                    if fault.skip > 0:
                        fault.skip -= 1
                        return None
                    return self._faults.pop(i)
        return None

    def _execute(self, line: bytes) -> bytes:
        try:
            request = decode_request(line)
            return self._handlers[request.command.key](request)
        except ErrorReply as exc:
            return encode_error(exc.code, exc.text)

    # --- command handlers -------------------------------------------------------------

    def _identify(self, request: Request) -> bytes:
        return encode_reply("identify", Identity(VENDOR, MODEL, self.serial, FIRMWARE))

    def _channel_count(self, request: Request) -> bytes:
        return encode_reply("channel_count", self.physics.n_channels)

    def _channel_list(self, request: Request) -> bytes:
        infos = [ChannelInfo(c.name, c.peak_nm, c.kind) for c in self.physics.channels]
        return encode_reply("channel_list", infos)

    def _set_level(self, request: Request) -> bytes:
        index, level = request.args
        n = self.physics.n_channels
        if not isinstance(index, int) or index >= n:
            raise ErrorReply(ErrorCode.BAD_CHANNEL, f"channel must be 1..{n}")
        assert isinstance(level, float)
        self.physics.set_level(index, level)
        return encode_reply("set_level")

    def _set_levels(self, request: Request) -> bytes:
        levels = np.asarray(request.args[0])
        n = self.physics.n_channels
        if levels.size != n:
            raise ErrorReply(
                ErrorCode.LEVEL_COUNT, f"expected {n} levels, got {levels.size}"
            )
        self.physics.set_levels(levels)
        return encode_reply("set_levels")

    def _get_levels(self, request: Request) -> bytes:
        return encode_reply("get_levels", self.physics.levels())

    def _all_off(self, request: Request) -> bytes:
        self.physics.all_off()
        return encode_reply("all_off")

    def _measure_spd(self, request: Request) -> bytes:
        spd = self.physics.measure_spd()
        wl = spd.wavelength_nm
        measured = MeasuredSpectrum(float(wl[0]), float(wl[1] - wl[0]), spd.values[0])
        return encode_reply("measure_spd", measured)

    def _status(self, request: Request) -> bytes:
        st = self.physics.status()
        fields = {
            "READY": "1" if st.ready else "0",
            "TEMP_C": f"{st.temperature_c:.2f}",
            "ON_S": f"{st.on_time_s:.1f}",
            **{k.upper(): v for k, v in st.extra.items()},
            "MSG": st.message,
        }
        return encode_reply("status", fields)
