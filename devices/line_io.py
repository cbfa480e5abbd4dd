"""Line-oriented serving for the device emulators (CAL1, Zaber) over TCP: the listening
socket with its accept loop (:class:`LineServer`) and the request lines of one
connection (:func:`received_lines`)."""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable, Iterator

__all__ = ["LineServer", "received_lines"]


def received_lines(
    conn: socket.socket,
    stop: threading.Event,
    terminator: bytes,
    max_line_bytes: int,
    on_overflow: Callable[[], None] | None = None,
) -> Iterator[bytes]:
    """The request lines a client sends (terminator removed), until it leaves.

    Ends when the client closes or the connection fails, or when ``stop`` is set
    (``conn`` needs a timeout so that it is looked at). Bytes piling up past
    ``max_line_bytes`` without a terminator are dropped and ``on_overflow`` called.
    """
    rx = bytearray()
    while not stop.is_set():
        try:
            data = conn.recv(4096)
        except TimeoutError:
            continue
        except OSError:
            return
        if not data:
            return
        rx += data
        while (end := rx.find(terminator)) >= 0:
            line = bytes(rx[:end])
            del rx[: end + len(terminator)]
            yield line
        if len(rx) > max_line_bytes:
            rx.clear()
            if on_overflow is not None:
                on_overflow()


class LineServer:
    """A TCP listener on ``host:port`` (port 0: any free one) whose accept loop runs on
    a daemon thread and hands each connection, with ``poll_s`` as its timeout, to
    ``on_connection(conn, address)``; that handler owns (and closes) ``conn``.

    :attr:`stop` is set by :meth:`close`; handlers pass it to
    :func:`received_lines` so that they end too.
    """

    def __init__(
        self,
        host: str,
        port: int,
        poll_s: float,
        on_connection: Callable[[socket.socket, tuple[str, int]], None],
        *,
        name: str,
    ) -> None:
        self.stop = threading.Event()
        self._poll_s = poll_s
        self._on_connection = on_connection
        self._listener = socket.create_server((host, port))
        self._listener.settimeout(poll_s)
        self.host, self.port = self._listener.getsockname()[:2]
        self._thread = threading.Thread(
            target=self._accept_loop, name=f"{name}:{self.port}", daemon=True
        )
        self._thread.start()

    def close(self) -> None:
        """Stop accepting, end the handlers' line loops and release the port."""
        self.stop.set()
        self._thread.join(timeout=5.0)
        self._listener.close()

    def _accept_loop(self) -> None:
        while not self.stop.is_set():
            try:
                conn, address = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.settimeout(self._poll_s)
            self._on_connection(conn, address)
