"""Line transports for the CAL1 driver: a pyserial port, and a scripted fake for tests.

The driver (:class:`~tunespec.devices.cal1.driver.Cal1LightSource`) never opens
anything itself: it is handed a :class:`Transport` (PyMeasure's injected adapter).

- :class:`SerialTransport` wraps any pyserial port, so ``/dev/ttyUSB0``, ``COM3``,
  ``socket://127.0.0.1:PORT`` (the emulator) and ``loop://`` all work through
  :func:`serial.serial_for_url`.
- :class:`FakeTransport` replays a scripted exchange, ``FakeTransport([(b"OUTP:OFF\\n",
  b"OK\\n")])``, and checks that the driver sent exactly that and that everything was
  consumed (PyMeasure's ``expected_protocol``).

Transports raise :class:`~tunespec.devices.protocols.DeviceTimeoutError` when no
complete line arrives in time and
:class:`~tunespec.devices.protocols.DeviceConnectionError` when the link is lost; the
driver adds which device and what to check.
"""

from __future__ import annotations

import contextlib
import errno
import socket
import time
from typing import Protocol, runtime_checkable

import serial

from tunespec.devices.cal1.commands import BAUDRATE, MAX_LINE_BYTES, TERMINATOR
from tunespec.devices.protocols import (
    DeviceBusyError,
    DeviceConnectionError,
    DeviceProtocolError,
    DeviceTimeoutError,
)

__all__ = [
    "SerialTransport",
    "Transport",
]

#: Poll interval of the pyserial port: reads return at least this often, so a line
#: read honours its own deadline without reconfiguring the port for every call.
POLL_S = 0.05


@runtime_checkable
class Transport(Protocol):
    """A bidirectional line link. Blocking; used from one thread."""

    @property
    def url(self) -> str:
        """Where the link goes, for messages (e.g. ``/dev/ttyUSB0``)."""
        ...

    @property
    def is_open(self) -> bool: ...

    def write(self, data: bytes) -> None:
        """Send ``data`` completely."""
        ...

    def read_line(self, timeout_s: float) -> bytes:
        """The next line without its terminator (a trailing ``\\r`` is removed).

        Raises
        ------
        DeviceTimeoutError
            No complete line within ``timeout_s``.
        DeviceConnectionError
            The link was lost or is closed.
        """
        ...

    def reset_input(self) -> None:
        """Discard whatever was received and not read yet (stale replies)."""
        ...

    def reopen(self) -> None:
        """Close and open the link again (after it was lost)."""
        ...

    def close(self) -> None:
        """Release the link; idempotent."""
        ...


class SerialTransport:
    """A :class:`Transport` over a pyserial port (serial, ``socket://``, ``loop://``).

    Parameters
    ----------
    port
        An open pyserial port; its read timeout is set to :data:`POLL_S`. Use
        :meth:`open` to create one from a URL.
    url
        Shown in messages; defaults to ``port.port``.
    terminator
        Line terminator.
    max_line_bytes
        A longer line without terminator is a protocol error (a babbling device).
    """

    def __init__(
        self,
        port: serial.SerialBase,
        *,
        url: str | None = None,
        terminator: bytes = TERMINATOR,
        max_line_bytes: int = MAX_LINE_BYTES,
    ) -> None:
        self._port = port
        self._url = url if url is not None else str(port.port)
        self._terminator = terminator
        self._max_line_bytes = max_line_bytes
        self._buffer = bytearray()
        if port.timeout != POLL_S:
            port.timeout = POLL_S

    @classmethod
    def open(
        cls,
        url: str,
        *,
        baudrate: int = BAUDRATE,
        write_timeout_s: float = 2.0,
    ) -> SerialTransport:
        """Open ``url`` with :func:`serial.serial_for_url` (8N1, exclusive access).

        Raises
        ------
        DeviceBusyError
            The port is locked by another program.
        DeviceConnectionError
            The port does not exist or the connection was refused.
        """
        try:
            port = serial.serial_for_url(
                url,
                baudrate=baudrate,
                timeout=POLL_S,
                write_timeout=write_timeout_s,
                exclusive=True,
            )
        except serial.SerialException as exc:
            if "lock" in str(exc).lower() or getattr(exc, "errno", None) == (
                errno.EBUSY
            ):
                raise DeviceBusyError(f"cannot open {url}: {exc}") from exc
            raise DeviceConnectionError(f"cannot open {url}: {exc}") from exc
        except (OSError, ValueError) as exc:
            raise DeviceConnectionError(f"cannot open {url}: {exc}") from exc
        return cls(port, url=url)

    @property
    def url(self) -> str:
        """The port URL or device path."""
        return self._url

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return bool(self._port.is_open)

    def write(self, data: bytes) -> None:
        """Send ``data``; a stuck write ends with the port's write timeout."""
        self._require_open()
        try:
            self._port.write(data)
            self._port.flush()
        except serial.SerialTimeoutException as exc:
            raise DeviceTimeoutError(f"write to {self._url} timed out") from exc
        except (serial.SerialException, OSError) as exc:
            raise DeviceConnectionError(
                f"connection to {self._url} lost while sending ({exc})"
            ) from exc

    def read_line(self, timeout_s: float) -> bytes:
        """The next line, without terminator; see :meth:`Transport.read_line`."""
        self._require_open()
        deadline = time.monotonic() + timeout_s
        term = self._terminator
        while True:
            end = self._buffer.find(term)
            if end >= 0:
                line = bytes(self._buffer[:end])
                del self._buffer[: end + len(term)]
                return line.removesuffix(b"\r")
            if len(self._buffer) > self._max_line_bytes:
                size = len(self._buffer)
                self._buffer.clear()
                raise DeviceProtocolError(
                    f"{self._url} sent {size} bytes without a line terminator"
                )
            if time.monotonic() >= deadline:
                raise DeviceTimeoutError(
                    f"no complete reply from {self._url} within {timeout_s:g} s"
                )
            try:
                # socket:// reports in_waiting as 0/1, loop:// and serial the real
                # count; either way this returns after at most POLL_S.
                chunk = self._port.read(max(1, min(self._port.in_waiting, 4096)))
            except (serial.SerialException, OSError) as exc:
                raise DeviceConnectionError(
                    f"connection to {self._url} lost while reading ({exc})"
                ) from exc
            self._buffer += chunk

    def reset_input(self) -> None:
        """Discard buffered input (ours and the port's)."""
        self._buffer.clear()
        if self._port.is_open:
            try:
                self._port.reset_input_buffer()
            except (serial.SerialException, OSError) as exc:
                raise DeviceConnectionError(
                    f"connection to {self._url} lost ({exc})"
                ) from exc

    def reopen(self) -> None:
        """Close and open the port again (same settings).

        Raises
        ------
        DeviceConnectionError
            If it cannot be opened again.
        """
        self._buffer.clear()
        _close_port(self._port)
        try:
            self._port.open()
        except (serial.SerialException, OSError) as exc:
            raise DeviceConnectionError(f"cannot reopen {self._url}: {exc}") from exc

    def close(self) -> None:
        """Close the port; idempotent."""
        self._buffer.clear()
        _close_port(self._port)

    def _require_open(self) -> None:
        if not self._port.is_open:
            raise DeviceConnectionError(f"connection to {self._url} is closed")

    def __repr__(self) -> str:
        return f"SerialTransport({self._url!r}, open={self.is_open})"


def _close_port(port: serial.SerialBase) -> None:
    """Close ``port``; for ``socket://`` without pyserial's fixed 0.3 s sleep.

    pyserial's socket handler sleeps 0.3 s in ``close()`` "in case of quick
    reconnects"; our emulator accepts at once, and the sleep would slow every test
    and every reconnect after a dropped connection. Falls back to ``port.close()``
    if the handler's internals are not the expected ones.
    """
    sock = getattr(port, "_socket", None)
    if isinstance(sock, socket.socket) and port.is_open:
        with contextlib.suppress(OSError):  # already disconnected by the peer
            sock.shutdown(socket.SHUT_RDWR)
        sock.close()
        port._socket = None
        port.is_open = False
        return
    # closing a port whose device vanished must not raise
    with contextlib.suppress(serial.SerialException, OSError):
        port.close()
