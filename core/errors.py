"""Errors raised on bad input, with the file and line they concern."""

from __future__ import annotations

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


class SingularSystemError(TuneSpecError, ArithmeticError):
    """A linear system that cannot be solved (too few or degenerate stimuli)."""
