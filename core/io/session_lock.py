"""One writer at a time for a session folder: ``session.lock``.

:class:`SessionLock` holds ``session.lock`` (an advisory ``flock``, released by the
kernel when its process dies, so a lock left by a killed capture is recognised as
stale and taken over). Used by :class:`tunespec.core.io.session.Session` and the
commands that write a session.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import threading
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path
from typing import Any

from tunespec.core.errors import InputError
from tunespec.core.io.session_format import LOCK_NAME

__all__ = ["SessionBusyError", "SessionLock", "utc_now"]


def utc_now() -> str:
    """Now, as the session files write it: ISO 8601 UTC to the millisecond, ``Z``."""
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


# -- one writer at a time --------------------------------------------------------------
class SessionBusyError(InputError):
    """Another process is writing the session (it holds ``session.lock``)."""


#: Per process: real path of a session folder -> [open lock file descriptor, count].
_HELD: dict[str, list[int]] = {}
_HELD_GUARD = threading.Lock()


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


class SessionLock:
    """The lock of a session folder: one writing process at a time.

    ``session.lock`` holds the holder's pid, host and start time (for the message
    a second writer gets) and is locked with ``flock`` while held. The kernel drops a
    ``flock`` when its process dies, so a lock file with content but no ``flock`` is
    stale (its holder was killed): it is taken over and the old holder is kept in
    :attr:`stale_holder`. The file is never deleted (deleting it would let two
    processes lock two different files). Re-entrant within one process. Where
    ``flock`` is missing (Windows), a holder on this host whose pid is gone is stale.

    Parameters
    ----------
    root
        The session folder (created if missing).
    """

    def __init__(self, root: str | PathLike[str]) -> None:
        self.root = Path(root)
        self.path = self.root / LOCK_NAME
        self.stale_holder: dict[str, Any] | None = None
        self._key: str | None = None

    def acquire(self) -> SessionLock:
        """Take the lock; :class:`SessionBusyError` naming the holder if taken."""
        self.root.mkdir(parents=True, exist_ok=True)
        key = os.path.realpath(self.root)
        with _HELD_GUARD:
            if key in _HELD:
                _HELD[key][1] += 1
                self._key = key
                return self
            flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0)
            try:
                fd = os.open(self.path, flags, 0o644)
            except OSError as exc:
                raise InputError(
                    f"cannot open the session lock: {exc.strerror}", path=self.path
                ) from None
            try:
                previous = _read_holder(fd)
                if not _try_lock(fd, previous):
                    raise SessionBusyError(
                        "the session is being written by another capture: "
                        + _describe(previous)
                        + "; wait for it to finish or stop it",
                        path=self.root,
                    )
                if previous is not None and previous.get("pid") != os.getpid():
                    self.stale_holder = previous
                me = {
                    "pid": os.getpid(),
                    "host": socket.gethostname(),
                    "started_utc": utc_now(),
                }
                _write_holder(fd, json.dumps(me) + "\n")
            except BaseException:
                os.close(fd)
                raise
            _HELD[key] = [fd, 1]
            self._key = key
        return self

    def release(self) -> None:
        """Give the lock back (the last release of this process empties the file)."""
        key, self._key = self._key, None
        if key is None:
            return
        with _HELD_GUARD:
            entry = _HELD.get(key)
            if entry is None:
                return
            entry[1] -= 1
            if entry[1] > 0:
                return
            del _HELD[key]
            fd = entry[0]
            with contextlib.suppress(OSError):
                _write_holder(fd, "")
            os.close(fd)  # drops the flock

    def __enter__(self) -> SessionLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()


def _try_lock(fd: int, previous: dict[str, Any] | None) -> bool:
    try:
        import fcntl
    except ImportError:  # Windows: judge by the recorded holder
        if previous is None:
            return True
        same_host = previous.get("host") == socket.gethostname()
        pid = previous.get("pid")
        return same_host and isinstance(pid, int) and not _pid_alive(pid)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _read_holder(fd: int) -> dict[str, Any] | None:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        data = os.read(fd, 4096)
        holder = json.loads(data.decode("utf-8")) if data.strip() else None
    except (OSError, ValueError):
        return {"pid": "?", "host": "?", "started_utc": "?"}
    return holder if isinstance(holder, dict) else None


def _write_holder(fd: int, text: str) -> None:
    # in place: replacing the file would hand the next process another inode to lock
    os.ftruncate(fd, 0)
    os.lseek(fd, 0, os.SEEK_SET)
    os.write(fd, text.encode("utf-8"))
    os.fsync(fd)


def _describe(holder: dict[str, Any] | None) -> str:
    if holder is None:
        return "a process that has not written its name yet"
    return (
        f"pid {holder.get('pid', '?')} on host {holder.get('host', '?')} "
        f"since {holder.get('started_utc', '?')}"
    )
