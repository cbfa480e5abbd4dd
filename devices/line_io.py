"""Line-oriented serving for the device emulators (CAL1, Zaber) over TCP."""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable, Iterator

__all__ = ["received_lines"]


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
