"""The validation boundary: every file TuneSpec reads passes through here.

One place holds the limits (sizes, depths, counts) and the checks that every reader
applies -- JSON (layouts, manifests, saved results), TOML (run configurations), CSV
(spectra, responses) and CGATS -- so that a hostile or damaged file ends in one
:class:`~tunespec.core.errors.InputError` naming the file, the line or key and what
was expected, never in a traceback, a hang or unbounded memory:

- text: at most :data:`MAX_FILE_BYTES`, UTF-8 (a BOM tolerated), file names that the
  operating system refuses (too long, a folder) reported as input errors;
- JSON and TOML: nesting at most :data:`MAX_DEPTH` deep, at most :data:`MAX_NODES`
  values, strings at most :data:`MAX_STRING_CHARS`, integers at most
  :data:`MAX_INT_DIGITS` digits, no ``NaN``/``Infinity``;
- CSV: fields at most :data:`MAX_FIELD_CHARS`, at most :data:`MAX_ROWS` rows and
  :data:`MAX_COLUMNS` columns;
- values: :func:`number` refuses booleans, non-finite and out-of-range numbers,
  :func:`name` non-strings and over-long names, :func:`contained_path` paths that
  leave their project folder.

Outputs go through :func:`dumps_json`, which always writes standard JSON (non-finite
numbers become ``null``). Error messages show at most :data:`SHOWN_CHARS` of a file's
content (:func:`shown`).
"""

from __future__ import annotations

import csv
import errno
import json
import math
import os
from collections.abc import Iterable, Mapping
from os import PathLike
from pathlib import Path
from typing import Any

from tunespec.core.errors import InputError

__all__ = [
    "MAX_COLUMNS",
    "MAX_COUNT",
    "MAX_DEPTH",
    "MAX_FIELD_CHARS",
    "MAX_FILE_BYTES",
    "MAX_INT_DIGITS",
    "MAX_NAME_CHARS",
    "MAX_NODES",
    "MAX_REFLECTANCE",
    "MAX_ROWS",
    "MAX_SEED",
    "MAX_STRING_CHARS",
    "MAX_VALUE",
    "MAX_WAVELENGTH_NM",
    "check_output_dir",
    "check_output_file",
    "check_tree",
    "contained_path",
    "csv_rows",
    "dumps_json",
    "loads_json",
    "loads_toml",
    "read_bytes",
    "read_json",
    "read_text",
    "shown",
    "valid_name",
    "valid_number",
    "valid_seed",
]

#: Largest text file read (spectra, responses, CGATS, layouts, manifests, configs).
MAX_FILE_BYTES = 64 << 20
#: Deepest nesting of JSON/TOML arrays and objects (the deepest real file nests 4).
MAX_DEPTH = 32
#: Most values in one JSON/TOML document.
MAX_NODES = 2_000_000
#: Longest string in a JSON/TOML document.
MAX_STRING_CHARS = 1 << 16
#: Most digits of a JSON/TOML integer (Python refuses more than 4,300).
MAX_INT_DIGITS = 20
#: Longest CSV field (the csv module's own limit is 131,072).
MAX_FIELD_CHARS = 1 << 16
#: Most rows and columns of a CSV table.
MAX_ROWS = 1_000_000
MAX_COLUMNS = 100_000
#: Longest patch, channel, spectrum or frame name.
MAX_NAME_CHARS = 256
#: Largest magnitude of a measured value (reflectance, response, SPD, sensitivity):
#: squares and sums of a few thousand such values stay far from overflow.
MAX_VALUE = 1e12
#: Largest reflectance (fluorescent samples reach about 3; more is a wrong file).
MAX_REFLECTANCE = 10.0
#: Largest wavelength a file may give, nm (far beyond any spectroradiometer).
MAX_WAVELENGTH_NM = 1e6
#: Largest count a file may ask for (dark frames, brackets, channels, ...).
MAX_COUNT = 10_000
#: Seeds are 32-bit non-negative integers (numpy refuses negative ones).
MAX_SEED = 2**32 - 1
#: Characters of a file's content an error message may show.
SHOWN_CHARS = 40


def shown(text: object, n: int = SHOWN_CHARS) -> str:
    """``repr`` of (a value from) a file, cut to ``n`` characters for messages.

    Examples
    --------
    >>> shown("x" * 100, 8)
    "'xxxx..."
    """
    r = repr(text)
    return r if len(r) <= n else r[: n - 3] + "..."


def _os_problem(exc: OSError) -> str:
    if exc.errno == errno.ENAMETOOLONG:
        return "file name too long"
    if exc.errno == errno.EISDIR:
        return "is a folder, expected a file"
    if exc.errno == errno.ENOTDIR:
        return "a part of the path is not a folder"
    if exc.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if exc.errno == errno.ELOOP:
        return "too many levels of symbolic links"
    return f"cannot read: {exc.strerror or exc}"


def read_bytes(path: str | PathLike[str], *, max_bytes: int = MAX_FILE_BYTES) -> bytes:
    """A file's bytes, at most ``max_bytes``; :class:`InputError` otherwise."""
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size > max_bytes:
                raise InputError(
                    f"file of {size} bytes, more than the {max_bytes} allowed",
                    path=path,
                )
            data = fh.read(max_bytes + 1)
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except OSError as exc:
        raise InputError(_os_problem(exc), path=path) from None
    if len(data) > max_bytes:
        raise InputError(f"file larger than the {max_bytes} bytes allowed", path=path)
    return data


def read_text(path: str | PathLike[str], *, max_bytes: int = MAX_FILE_BYTES) -> str:
    """A text file's contents (UTF-8, a BOM tolerated); :class:`InputError` otherwise.

    Raises
    ------
    InputError
        Missing, unreadable, larger than ``max_bytes``, or not UTF-8 (with the line).
    """
    data = read_bytes(path, max_bytes=max_bytes)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(
            "not UTF-8 text (save it as UTF-8)", path=path, line=line
        ) from None


def _bad_constant(text: str) -> Any:
    raise ValueError(f"{text} is not a number in standard JSON")


def _bounded_int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        raise ValueError(f"integer of {len(text)} digits (at most {MAX_INT_DIGITS})")
    return int(text)


def _nesting(text: str) -> int:
    """Deepest bracket nesting of JSON text, outside strings (linear, no recursion)."""
    depth = deepest = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > deepest:
                deepest = depth
                if deepest > MAX_DEPTH:
                    return deepest
        elif ch in "]}":
            depth -= 1
    return deepest


def loads_json(text: str, *, path: str | PathLike[str] | None = None) -> Any:
    """Parse JSON within the limits (see the module docstring).

    Examples
    --------
    >>> loads_json('{"a": [1, 2.5]}')
    {'a': [1, 2.5]}
    >>> loads_json("[NaN]")
    Traceback (most recent call last):
    ...
    tunespec.core.errors.InputError: not valid JSON: NaN is not a number in standard JSON
    """
    if _nesting(text) > MAX_DEPTH:
        raise InputError(f"nested more than {MAX_DEPTH} deep", path=path)
    try:
        value = json.loads(text, parse_constant=_bad_constant, parse_int=_bounded_int)
    except json.JSONDecodeError as exc:
        raise InputError(
            f"not valid JSON: {exc.msg}", path=path, line=exc.lineno
        ) from None
    except (ValueError, RecursionError) as exc:
        raise InputError(f"not valid JSON: {exc}", path=path) from None
    check_tree(value, path=path)
    return value


def read_json(path: str | PathLike[str]) -> Any:
    """A JSON file's contents within the limits; :class:`InputError` otherwise."""
    return loads_json(read_text(path), path=path)


def loads_toml(text: str, *, path: str | PathLike[str] | None = None) -> Any:
    """Parse TOML within the limits (nesting, sizes, finite numbers)."""
    import tomllib

    # a cheap bound first: TOML nests with brackets and braces too (strings may
    # hold some, which only makes this stricter than needed for odd files)
    depth = deepest = 0
    for ch in text:
        if ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth = max(0, depth - 1)
    if deepest > 4 * MAX_DEPTH:
        raise InputError(f"nested more than {MAX_DEPTH} deep", path=path)
    try:
        value = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from None
    except (ValueError, RecursionError) as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from None
    check_tree(value, path=path)
    return value


def check_tree(value: Any, *, path: str | PathLike[str] | None = None) -> None:
    """Check a parsed document: depth, number of values, strings, finite numbers.

    Iterative (no recursion), so any depth is checked safely.
    """
    stack: list[tuple[Any, int, str]] = [(value, 1, "")]
    nodes = 0
    while stack:
        v, depth, key = stack.pop()
        nodes += 1
        where = f" (at {key if len(key) <= 80 else key[:60] + '...'})" if key else ""
        if nodes > MAX_NODES:
            raise InputError(f"more than {MAX_NODES} values", path=path)
        if depth > MAX_DEPTH:
            raise InputError(f"nested more than {MAX_DEPTH} deep{where}", path=path)
        if isinstance(v, str):
            if len(v) > MAX_STRING_CHARS:
                raise InputError(
                    f"a text of {len(v)} characters{where} (at most "
                    f"{MAX_STRING_CHARS})",
                    path=path,
                )
        elif isinstance(v, float):
            if not math.isfinite(v):
                raise InputError(f"non-finite number{where}", path=path)
        elif isinstance(v, int) and not isinstance(v, bool):
            if abs(v) >= 10**MAX_INT_DIGITS:
                raise InputError(f"integer too large{where}", path=path)
        elif isinstance(v, Mapping):
            for k, item in v.items():
                if not isinstance(k, str) or len(k) > MAX_STRING_CHARS:
                    raise InputError(f"bad key{where}", path=path)
                stack.append((item, depth + 1, f"{key}.{k}" if key else k))
        elif isinstance(v, list | tuple):
            for i, item in enumerate(v):
                stack.append((item, depth + 1, f"{key}[{i}]"))


def csv_rows(
    text: str, *, path: str | PathLike[str] | None = None, delimiter: str = ","
) -> list[tuple[int, list[str]]]:
    """Non-blank CSV rows (``delimiter``-separated) with their line numbers, within the limits.

    Raises
    ------
    InputError
        A field over :data:`MAX_FIELD_CHARS`, more than :data:`MAX_ROWS` rows or
        :data:`MAX_COLUMNS` columns, or a malformed row (with the line).
    """
    reader = csv.reader(text.splitlines(), delimiter=delimiter)
    out: list[tuple[int, list[str]]] = []
    old = csv.field_size_limit()
    csv.field_size_limit(MAX_FIELD_CHARS)
    try:
        for row in reader:
            if len(row) > MAX_COLUMNS:
                raise InputError(
                    f"{len(row)} fields, at most {MAX_COLUMNS}",
                    path=path,
                    line=reader.line_num,
                )
            if any(c.strip() for c in row):
                out.append((reader.line_num, row))
                if len(out) > MAX_ROWS:
                    raise InputError(f"more than {MAX_ROWS} rows", path=path)
    except csv.Error as exc:
        raise InputError(
            f"bad CSV: {exc} (fields are at most {MAX_FIELD_CHARS} characters)",
            path=path,
            line=reader.line_num + 1,
        ) from None
    finally:
        csv.field_size_limit(old)
    return out


def valid_number(
    value: Any,
    key: str,
    *,
    path: str | PathLike[str] | None = None,
    line: int | None = None,
    lo: float = -MAX_VALUE,
    hi: float = MAX_VALUE,
    integer: bool = False,
    lo_open: bool = False,
) -> Any:
    """``value`` as a finite number in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``).

    Booleans are not numbers; ``integer`` asks for an ``int``.

    Raises
    ------
    InputError
        Naming ``key``, the file (and line) and the expected range.

    Examples
    --------
    >>> valid_number(3, "n_darks", lo=1, hi=100, integer=True)
    3
    >>> valid_number(True, "iso", lo=1, hi=1e6)
    Traceback (most recent call last):
    ...
    tunespec.core.errors.InputError: iso: expected a number in [1, 1e+06], got True
    """
    kind = "an integer" if integer else "a number"
    rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
    ok = isinstance(value, int | float) and not isinstance(value, bool)
    if integer:
        ok = ok and isinstance(value, int)
    if ok:
        try:
            ok = math.isfinite(value) and (
                (lo < value if lo_open else lo <= value) and value <= hi
            )
        except OverflowError:
            ok = False
    if not ok:
        raise InputError(
            f"{key}: expected {kind} in {rng}, got {shown(value)}", path=path, line=line
        )
    return value


def valid_seed(
    value: Any, key: str = "seed", *, path: str | PathLike[str] | None = None
) -> int:
    """A random seed: an integer in ``[0, 2**32 - 1]``."""
    return int(valid_number(value, key, path=path, lo=0, hi=MAX_SEED, integer=True))


def valid_name(
    value: Any,
    key: str,
    *,
    path: str | PathLike[str] | None = None,
    line: int | None = None,
) -> str:
    """A non-empty name (patch, channel, spectrum) of at most :data:`MAX_NAME_CHARS`."""
    if not isinstance(value, str) or not value.strip():
        raise InputError(
            f"{key}: expected a non-empty text, got {shown(value)}",
            path=path,
            line=line,
        )
    if len(value) > MAX_NAME_CHARS or any(c in value for c in "\n\r\x00"):
        raise InputError(
            f"{key}: a name of at most {MAX_NAME_CHARS} characters on one line, got "
            f"{shown(value)}",
            path=path,
            line=line,
        )
    return value


def contained_path(
    rel: Any,
    key: str,
    *,
    bases: Iterable[str | PathLike[str]],
    path: str | PathLike[str] | None = None,
) -> list[Path]:
    """Candidates for a path named inside a project file, each inside one of ``bases``.

    A path written in a file (a layout's ``meta.reflectances``) may only point into
    the folder of that file or the shipped resources: absolute paths and paths
    climbing out with ``..`` (after resolving links) are refused.

    Raises
    ------
    InputError
        Naming ``key`` and the file.
    """
    if not isinstance(rel, str) or not rel or len(rel) > 1024 or "\x00" in rel:
        raise InputError(f"{key}: expected a relative file name", path=path)
    p = Path(rel)
    if p.is_absolute() or p.anchor or rel.startswith(("/", "\\")):
        raise InputError(
            f"{key}: must be relative to the file's folder (absolute paths are "
            "only accepted on the command line)",
            path=path,
        )
    out = []
    for base in bases:
        b = Path(base).resolve()
        try:
            c = (b / p).resolve()
        except (OSError, RuntimeError):
            continue
        if c == b or b in c.parents:
            out.append(c)
    if not out:
        raise InputError(
            f"{key}: {shown(rel)} leaves the project folder (only files beside the "
            "project file or shipped resources may be named there)",
            path=path,
        )
    return out


def check_output_file(path: str | PathLike[str], what: str = "output") -> Path:
    """Check, before any work, that ``path`` can be written as a file.

    Raises
    ------
    InputError
        ``path`` is an existing folder, its parent is a file, it or its nearest
        existing folder is not writable, or the name is too long.
    """
    p = Path(path)
    try:
        if p.is_dir():
            raise InputError(f"{what}: is a folder, expected a file name", path=p)
        if p.exists() and not os.access(p, os.W_OK):
            raise InputError(f"{what}: the file is not writable", path=p)
        parent = p.parent
        for q in (parent, *parent.parents):
            if q.exists():
                if not q.is_dir():
                    raise InputError(f"{what}: {q} is a file, not a folder", path=p)
                _check_writable_dir(q, what, p)
                break
    except OSError as exc:
        raise InputError(f"{what}: {_os_problem(exc)}", path=p) from None
    if len(p.name.encode()) > 255:
        raise InputError(f"{what}: file name too long", path=p)
    return p


def check_output_dir(path: str | PathLike[str], what: str = "output folder") -> Path:
    """Check, before any work, that ``path`` is or can become a folder.

    Raises
    ------
    InputError
        ``path`` (or a parent) is an existing file, the nearest existing folder is
        not writable, or the name is too long.
    """
    p = Path(path)
    try:
        for q in (p, *p.parents):
            if q.exists():
                if not q.is_dir():
                    raise InputError(
                        f"{what}: {q} is a file, expected a folder", path=p
                    )
                _check_writable_dir(q, what, p)
                break
    except OSError as exc:
        raise InputError(f"{what}: {_os_problem(exc)}", path=p) from None
    if any(len(part.encode()) > 255 for part in p.parts):
        raise InputError(f"{what}: file name too long", path=p)
    return p


def _check_writable_dir(folder: Path, what: str, path: Path) -> None:
    """The nearest existing folder of an output must take new entries."""
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{what}: {folder} is not writable", path=path)


def _finite_or_none(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_none(v) for v in value]
    if hasattr(value, "item") and hasattr(value, "dtype"):  # numpy scalars
        return _finite_or_none(value.item())
    return value


def dumps_json(value: Any, *, indent: int | None = 2) -> str:
    """Standard JSON text (ends with a newline): ``NaN``/``Infinity`` become ``null``.

    Examples
    --------
    >>> dumps_json({"rms": float("nan"), "n": 2}, indent=None)
    '{"rms": null, "n": 2}\\n'
    """
    return json.dumps(_finite_or_none(value), indent=indent, allow_nan=False) + "\n"
