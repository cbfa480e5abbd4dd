"""The one way TuneSpec writes a result file: temporary file, fsync, rename.

A reader (or a process started after a crash) sees the old content or the new
one, never a partial file; a full disk leaves the old file (or none) and raises
:class:`~tunespec.core.errors.DiskFullError` naming the folder. The rename replaces
whatever entry has the target's name, so a symbolic link planted at an output path
(``run/export/reflectances.csv -> ~/victim``) is replaced by the new file and what
it pointed to is never opened.
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
from collections.abc import Iterator, Sequence
from os import PathLike
from pathlib import Path
from typing import IO, Any

from tunespec.core.errors import DiskFullError

__all__ = [
    "atomic_open",
    "atomic_write_bytes",
    "atomic_write_text",
    "create_temp_file",
    "fsync_dir",
]


def fsync_dir(folder: Path) -> None:
    """Make a rename inside ``folder`` durable (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # e.g. Windows
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def create_temp_file(folder: Path, prefix: str, suffix: str = ".tmp") -> Path:
    """Create a new, empty, uniquely named file in ``folder``; returns its path.

    Unlike ``tempfile.mkstemp`` (always 0600) the file gets the permissions any
    newly created file gets, ``0666`` less the process's umask, so an output written
    through a temporary file and a rename looks like every other output (0644
    under the usual umask 022). ``O_EXCL`` with ``O_NOFOLLOW``: never opens through
    a link.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    for _ in range(100):
        path = folder / f"{prefix}{secrets.token_hex(4)}{suffix}"
        try:
            fd = os.open(path, flags, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return path
    raise FileExistsError(f"no free temporary name in {folder}")  # pragma: no cover


def _disk_full(exc: OSError, folder: Path) -> BaseException:
    if exc.errno == errno.ENOSPC:
        return DiskFullError(folder)
    return exc


def _temp_beside(path: Path, suffix: str) -> Path:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # a name cut to fit: ".<name>.<8 hex><suffix>" within 255 bytes
        stem = path.name[: max(1, 240 - len(suffix))]
        return create_temp_file(path.parent, f".{stem}.", suffix)
    except OSError as exc:
        raise _disk_full(exc, path.parent) from None


def _commit(tmp: Path, path: Path) -> None:
    os.replace(tmp, path)  # replaces a link at ``path``, never follows it
    fsync_dir(path.parent)


def atomic_write_bytes(
    path: str | PathLike[str],
    data: bytes | bytearray | memoryview | Sequence[bytes | memoryview],
    suffix: str = ".tmp",
) -> None:
    """Write ``data`` (bytes, or chunks written one after the other) to ``path``
    atomically: temporary file (``suffix`` after its name) in the same folder, fsync,
    ``os.replace``.

    Raises
    ------
    DiskFullError
        No space left: the temporary file is removed, ``path`` is as it was.
    """
    chunks = [data] if isinstance(data, bytes | bytearray | memoryview) else data
    with atomic_open(path, "wb", suffix=suffix) as fh:
        for chunk in chunks:
            fh.write(chunk)


def atomic_write_text(path: str | PathLike[str], text: str) -> None:
    """:func:`atomic_write_bytes` for UTF-8 text."""
    atomic_write_bytes(path, text.encode("utf-8"))


@contextlib.contextmanager
def atomic_open(
    path: str | PathLike[str], mode: str = "w", *, suffix: str = ".tmp", **kwargs: Any
) -> Iterator[IO[Any]]:
    """``open(path, mode)`` for writing, atomically: the file handed out is a
    temporary file beside ``path``, renamed over ``path`` when the block ends
    without an exception and removed when it raises.

    ``mode`` is ``"w"`` (text; ``encoding`` defaults to UTF-8) or ``"wb"``; the
    temporary file's name is ``path``'s with ``suffix`` after it.

    Examples
    --------
    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> with atomic_open(d / "a.csv", newline="") as fh:
    ...     _ = fh.write("x\\n")
    >>> (d / "a.csv").read_text()
    'x\\n'
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes only ('w' or 'wb'), got {mode!r}")
    path = Path(path)
    tmp = _temp_beside(path, suffix)
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
    try:
        with open(tmp, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        _commit(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
            raise DiskFullError(path.parent) from None
        raise
