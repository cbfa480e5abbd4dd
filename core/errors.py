"""Errors raised on bad input, with the file and line they concern."""

from __future__ import annotations

import json
from os import PathLike
from pathlib import Path
from typing import Any


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


def read_text(path: str | PathLike[str]) -> str:
    """A text file's contents (UTF-8, a BOM tolerated); :class:`InputError` otherwise."""
    try:
        return Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", path=path) from None


def read_json(path: str | PathLike[str]) -> Any:
    """A JSON file's contents; :class:`InputError` with the line if it is invalid."""
    try:
        return json.loads(read_text(path))
    except json.JSONDecodeError as exc:
        raise InputError(
            f"not valid JSON: {exc.msg}", path=path, line=exc.lineno
        ) from None
