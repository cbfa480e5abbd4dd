"""Errors raised on bad input, with the file and line they concern."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from os import PathLike


class TuneSpecError(Exception):
    """Base class of every error TuneSpec raises on purpose."""


class InputError(TuneSpecError, ValueError):
    """Bad input data: names the file (and line) and what was expected.

    ``str(err)`` reads ``"path:line: message"`` so the CLI can print it as one line.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | PathLike[str] | None = None,
        line: int | None = None,
    ) -> None:
        self.message = message
        self.path = None if path is None else str(path)
        self.line = line
        where = ""
        if self.path is not None:
            where = self.path + (f":{line}" if line is not None else "") + ": "
        super().__init__(where + message)


class DiskFullError(TuneSpecError):
    """No space left on the disk holding ``folder``.

    ``str(err)`` names the folder, the free space and (when known) about how much
    more is needed, on one line. Whatever was written before stays consistent.
    ``resume``: the command can continue where it stopped (``--resume``, a capture).
    """

    def __init__(
        self,
        folder: str | PathLike[str],
        *,
        needed_bytes: int | None = None,
        free_bytes: int | None = None,
        resume: bool = False,
    ) -> None:
        import shutil

        self.folder = str(folder)
        self.needed_bytes = needed_bytes
        if free_bytes is None:
            try:
                free_bytes = shutil.disk_usage(self.folder).free
            except OSError:
                free_bytes = None
        self.free_bytes = free_bytes
        free = "" if free_bytes is None else f", {_mb(free_bytes)} free"
        need = (
            ""
            if needed_bytes is None
            else f"; about {_mb(needed_bytes)} more is needed"
        )
        again = "continue with --resume" if resume else "run the command again"
        super().__init__(
            f"{self.folder}: no space left on the disk{free}{need}; free some space "
            f"and {again}"
        )

    @classmethod
    def from_os_error(
        cls,
        exc: OSError,
        *,
        folder: str | PathLike[str] | None = None,
        needed_bytes: int | None = None,
    ) -> DiskFullError:
        """From an ``ENOSPC`` error (its file's folder unless ``folder`` is given)."""
        import os

        if folder is None:
            folder = os.path.dirname(os.fspath(exc.filename)) if exc.filename else "."
        return cls(folder or ".", needed_bytes=needed_bytes)


def _mb(n_bytes: int) -> str:
    return f"{n_bytes / 1e6:.1f} MB"


class SingularSystemError(TuneSpecError, ArithmeticError):
    """A linear system that cannot be solved (too few or degenerate stimuli)."""


def shown_names(names: Sequence[str], limit: int) -> str:
    """The first ``limit`` of ``names`` joined by commas, `` ...`` when there are more:
    how a message lists names.

    Examples
    --------
    >>> shown_names(["A1", "A2", "A3"], 2)
    'A1, A2 ...'
    """
    return ", ".join(names[:limit]) + (" ..." if len(names) > limit else "")


def check_names(
    wanted: Iterable[str],
    available: Iterable[str],
    message: str = "{n} name(s) not found: {names}",
    *,
    path: str | PathLike[str] | None = None,
    limit: int = 8,
) -> None:
    """Raise :class:`InputError` naming the ``wanted`` names not in ``available``.

    The one "names not found" check of the readers and selections. ``message`` has
    ``{n}`` replaced by how many are missing and ``{names}`` by the first ``limit`` of
    them (`` ...`` when there are more); names are never interpreted as a format.

    Examples
    --------
    >>> try:
    ...     check_names(["A1", "Z9"], ["A1", "A2"])
    ... except InputError as exc:
    ...     print(exc)
    1 name(s) not found: Z9
    """
    have = set(available)
    missing = [n for n in wanted if n not in have]
    if missing:
        shown = shown_names(missing, limit)
        text = message.replace("{n}", str(len(missing))).replace("{names}", shown)
        raise InputError(text, path=path)
