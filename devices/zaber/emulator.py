"""A Zaber ASCII emulator: daisy-chained rotary stages served on a local TCP port.

pyserial's ``socket://`` handler reaches it, so the real driver runs unchanged against
it: ``open_zaber("zaber+socket://127.0.0.1:PORT")``. Each device has axes with a
position in microsteps, travel limits, a reference flag (set by ``home``), a speed and
a warning flag; moves take real time (``speed_steps_s``), so the driver's polling, its
timeouts and ``stop`` are exercised. Commands understood: the empty command (status),
``home``, ``move abs N``, ``move rel N``, ``stop``, ``estop``, ``get pos``,
``get limit.min``, ``get limit.max``, ``get device.id``, ``get system.serial``,
``get version``; anything else is ``RJ ... BADCOMMAND``. A command with a checksum is
checked (a wrong one: ``RJ ... BADDATA``). What is assumed where the protocol manual
leaves it to the device: a ``move`` before homing is rejected with warning ``WR`` and
``BADCOMMAND``; a move beyond a limit with ``BADDATA``.

Faults for tests (:meth:`ZaberEmulator.inject_fault`): ``stall`` (the next move stops
half way with fault ``FS``), ``no_reply`` (the next command is not answered), ``drop``
(the connection is closed).
"""

from __future__ import annotations

import socket
import threading
import time
from dataclasses import dataclass
from typing import Literal

from tunespec.devices.line_io import LineServer, received_lines
from tunespec.devices.protocols import ClosesOnExit
from tunespec.devices.zaber.protocol import MAX_LINE_BYTES, checksum

__all__ = ["StageAxis", "ZaberEmulator"]

FaultKind = Literal["stall", "no_reply", "drop"]


@dataclass
class StageAxis:
    """The state of one emulated axis (positions in microsteps)."""

    limit_min: int = -1_536_000  # -360 deg at 0.000234375 deg/step
    limit_max: int = 1_536_000
    speed_steps_s: float = 2_000_000.0
    pos: float = 0.0
    start: float = 0.0
    target: float = 0.0
    t0: float = 0.0
    homed: bool = False
    warning: str = "WR"
    stall_at: float | None = None

    def now_pos(self, t: float) -> float:
        """Position at time ``t`` (moves at constant speed)."""
        dist = self.target - self.start
        if dist == 0:
            return self.target
        travelled = min(abs(dist), self.speed_steps_s * (t - self.t0))
        if self.stall_at is not None and travelled >= abs(self.stall_at - self.start):
            self.start = self.target = self.stall_at
            self.stall_at = None
            self.warning = "FS"
            return self.target
        return self.start + travelled * (1 if dist > 0 else -1)

    def busy(self, t: float) -> bool:
        return self.now_pos(t) != self.target

    def go(self, target: float, t: float) -> None:
        self.start, self.target, self.t0 = self.now_pos(t), float(target), t


class ZaberEmulator(ClosesOnExit):
    """Serve Zaber ASCII for ``n_devices`` single-axis stages on ``host:port``.

    Parameters
    ----------
    port
        TCP port; 0 picks a free one.
    n_devices
        Devices 1..n on the chain, one axis each.
    device_id
        What ``get device.id`` answers.
    """

    def __init__(
        self,
        port: int = 0,
        *,
        n_devices: int = 4,
        device_id: int = 30222,
        host: str = "127.0.0.1",
        poll_s: float = 0.05,
    ) -> None:
        self.axes = {(d, 1): StageAxis() for d in range(1, n_devices + 1)}
        self.device_id = device_id
        #: Every command line received, in order (for tests).
        self.received: list[str] = []
        self.errors: list[BaseException] = []
        self._faults: list[FaultKind] = []
        self._lock = threading.Lock()
        self._server = LineServer(
            host, port, poll_s, self._accept, name="zaber-emulator"
        )
        self._stop = self._server.stop
        self.host, self.port = self._server.host, self._server.port

    @property
    def url(self) -> str:
        """pyserial URL."""
        return f"socket://{self.host}:{self.port}"

    def spec(self, axes: str = "") -> str:
        """A goniometer spec for :func:`~tunespec.devices.zaber.driver.open_zaber`."""
        return f"zaber+socket://{self.host}:{self.port}" + (
            f"?axes={axes}" if axes else ""
        )

    def inject_fault(self, kind: FaultKind) -> None:
        """Misbehave once (see the module docstring)."""
        if kind not in ("stall", "no_reply", "drop"):
            raise ValueError(f"unknown fault {kind!r}")
        with self._lock:
            self._faults.append(kind)

    def close(self) -> None:
        """Stop serving; idempotent."""
        self._server.close()

    # --- serving -------------------------------------------------------------------

    def _accept(self, conn: socket.socket, address: tuple[str, int]) -> None:
        """Serve one client at a time, on the accept loop's thread."""
        try:
            self._serve(conn)
        except Exception as exc:  # kept for tests, never re-raised in the thread
            self.errors.append(exc)
        finally:
            conn.close()

    def _serve(self, conn: socket.socket) -> None:
        for raw in received_lines(conn, self._stop, b"\n", MAX_LINE_BYTES):
            line = raw.decode("ascii", "replace").strip()
            self.received.append(line)
            fault = self._take_fault(line)
            if fault == "drop":
                return
            if fault == "no_reply":
                continue
            for out in self._execute(line):
                conn.sendall(out.encode("ascii") + b"\r\n")

    def _take_fault(self, line: str) -> FaultKind | None:
        with self._lock:
            if not self._faults:
                return None
            if self._faults[0] == "stall":
                if " move " not in f" {line} ":
                    return None
                self._faults.pop(0)
                dev, ax = (int(v) for v in line[1:].split()[:2])
                st = self.axes.get((dev, ax))
                if st is not None:
                    st.stall_at = float("nan")  # resolved once the move starts
                return None
            return self._faults.pop(0)

    def _execute(self, line: str) -> list[str]:
        if not line.startswith("/"):
            return []
        body = line[1:]
        bad_sum = False
        if ":" in body:
            body, _, cs = body.rpartition(":")
            bad_sum = checksum(body) != cs.upper()
        words = body.split()
        try:
            dev = int(words[0]) if words else 0
            ax = int(words[1]) if len(words) > 1 else 0
        except ValueError:
            return []
        cmd = " ".join(words[2:])
        if bad_sum:
            return [self._reply(dev, ax, False, "BADDATA")]
        if (dev, ax) not in self.axes and not (ax == 0 and (dev, 1) in self.axes):
            return (
                []
                if (dev, 1) not in self.axes
                else [self._reply(dev, ax, False, "BADAXIS")]
            )
        return [self._command(dev, ax, cmd)]

    def _reply(self, dev: int, ax: int, ok: bool, data: str = "0") -> str:
        st = self.axes.get((dev, ax if ax else 1))
        t = time.monotonic()
        status = "BUSY" if st is not None and st.busy(t) else "IDLE"
        warn = st.warning if st is not None else "--"
        return f"@{dev:02d} {ax} {'OK' if ok else 'RJ'} {status} {warn} {data}"

    def _command(self, dev: int, ax: int, cmd: str) -> str:
        st = self.axes[(dev, ax if ax else 1)]
        t = time.monotonic()
        device_level = {
            "get device.id": str(self.device_id),
            "get system.serial": str(10_000 + dev),
            "get version": "7.38",
        }
        if cmd in device_level:
            return self._reply(dev, ax, True, device_level[cmd])
        if cmd == "":
            return self._reply(dev, ax, True)
        if cmd == "get pos":
            return self._reply(dev, ax, True, str(round(st.now_pos(t))))
        if cmd in ("get limit.min", "get limit.max"):
            v = st.limit_min if cmd.endswith("min") else st.limit_max
            return self._reply(dev, ax, True, str(v))
        if cmd in ("stop", "estop"):
            st.go(round(st.now_pos(t)), t)
            st.stall_at = None
            return self._reply(dev, ax, True)
        if cmd == "home":
            st.homed, st.warning = True, "--"
            st.go(0, t)
            return self._reply(dev, ax, True)
        if cmd.startswith("move abs ") or cmd.startswith("move rel "):
            return self._move(dev, ax, st, cmd, t)
        return self._reply(dev, ax, False, "BADCOMMAND")

    def _move(self, dev: int, ax: int, st: StageAxis, cmd: str, t: float) -> str:
        try:
            n = int(cmd.split()[2])
        except (ValueError, IndexError):
            return self._reply(dev, ax, False, "BADDATA")
        if not st.homed:
            return self._reply(dev, ax, False, "BADCOMMAND")
        target = n if cmd.startswith("move abs") else round(st.now_pos(t)) + n
        if not st.limit_min <= target <= st.limit_max:
            return self._reply(dev, ax, False, "BADDATA")
        if st.warning.startswith("F"):
            st.warning = "--"  # a new move clears the fault, as a reset would
        stall = st.stall_at
        st.go(target, t)
        if stall is not None:  # stall half way
            st.stall_at = st.start + (st.target - st.start) / 2
        return self._reply(dev, ax, True)
