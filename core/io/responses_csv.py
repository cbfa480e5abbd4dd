"""The long-format responses CSV: ``patch,illuminant,R,G,B[,R_std,G_std,B_std][,n_pixels][,saturated][,white_R,white_G,white_B]``.

One row per patch and illuminant; values linear, dark-corrected and flat-fielded, in
units of full scale (see :class:`tunespec.core.responses.Responses`).
"""

from __future__ import annotations

import csv
import math
from collections import Counter
from os import PathLike
from pathlib import Path

import numpy as np

from tunespec.core.atomic import atomic_open
from tunespec.core.errors import InputError
from tunespec.core.limits import csv_rows, read_text, shown, valid_name, valid_number
from tunespec.core.responses import CHANNELS, Responses

__all__ = ["read_responses_csv", "write_responses_csv"]

_STD = tuple(f"{c}_std" for c in CHANNELS)
_WHITE = tuple(f"white_{c}" for c in CHANNELS)


def read_responses_csv(path: str | PathLike[str]) -> Responses:
    """Read a long-format responses CSV.

    Raises
    ------
    InputError
        Missing columns, bad or non-finite numbers, negative standard deviations,
        duplicate or missing (patch, illuminant) pairs, a white level that differs
        between rows of one illuminant; each names the file and line.
    """
    path = Path(path)
    rows = csv_rows(read_text(path), path=path)  # blank lines skipped, numbered
    if not rows:
        raise InputError("empty file, expected a responses CSV", path=path)
    header_line, header = rows[0]
    header = [h.strip() for h in header]
    dup = sorted(h for h, k in Counter(header).items() if k > 1)
    if dup:
        raise InputError(
            f"duplicate column(s) {', '.join(map(shown, dup))}",
            path=path,
            line=header_line,
        )
    required = ["patch", "illuminant", *CHANNELS]
    missing = [c for c in required if c not in header]
    if missing:
        joined = " ".join(header)
        sep = next((d for d in (";", "\t", "|") if d in joined), None)
        if sep is not None and len(header) == 1:
            raise InputError(
                f"the columns are separated by {sep!r} (header "
                f"{shown(joined[:60])}); a responses CSV uses commas: "
                "patch,illuminant,R,G,B",
                path=path,
                line=header_line,
            )
        raise InputError(
            f"missing column(s) {', '.join(missing)}; expected patch,illuminant,R,G,B",
            path=path,
            line=header_line,
        )
    col = {h: i for i, h in enumerate(header)}
    for group in (_STD, _WHITE):
        if any(c in col for c in group) and not all(c in col for c in group):
            raise InputError(
                f"give all of {','.join(group)} or none", path=path, line=header_line
            )
    has_std = all(c in col for c in _STD)
    has_white = all(c in col for c in _WHITE)
    has_n = "n_pixels" in col
    has_sat = "saturated" in col
    white: dict[str, tuple[list[float], int]] = {}  # illuminant -> (level, line)
    records: dict[tuple[str, str], tuple[list[float], list[float], float, float]] = {}
    # dicts as ordered sets: a membership test per row stays O(1)
    patches: dict[str, None] = {}
    illums: dict[str, None] = {}
    for lineno, row in rows[1:]:
        if len(row) != len(header):
            raise InputError(
                f"{len(row)} fields, expected {len(header)}", path=path, line=lineno
            )
        p, il = row[col["patch"]].strip(), row[col["illuminant"]].strip()
        if not p or not il:
            raise InputError("empty patch or illuminant name", path=path, line=lineno)
        valid_name(p, "patch", path=path, line=lineno)
        valid_name(il, "illuminant", path=path, line=lineno)
        if (p, il) in records:
            raise InputError(
                f"duplicate row for patch {shown(p)} under {shown(il)}",
                path=path,
                line=lineno,
            )

        def num(key: str, lineno: int = lineno, row: list[str] = row) -> float:
            cell = row[col[key]]
            try:
                v = float(cell)
            except ValueError:
                raise InputError(
                    f"{key}: not a number: {shown(cell)}", path=path, line=lineno
                ) from None
            return float(valid_number(v, key, path=path, line=lineno))

        rgb = [num(c) for c in CHANNELS]
        std = [num(c) for c in _STD] if has_std else [math.nan] * 3
        if has_std and min(std) < 0:
            raise InputError("negative standard deviation", path=path, line=lineno)
        npx = num("n_pixels") if has_n else math.nan
        sat = num("saturated") if has_sat else math.nan
        if has_white:
            _white_level(white, il, [num(c) for c in _WHITE], path, lineno)
        records[(p, il)] = (rgb, std, npx, sat)
        patches.setdefault(p)
        illums.setdefault(il)
    if not records:
        raise InputError("no data rows", path=path)
    n_absent = len(patches) * len(illums) - len(records)
    if n_absent:
        # stops at the first gap: the full product may be huge
        p, i = next((p, i) for p in patches for i in illums if (p, i) not in records)
        raise InputError(
            f"{n_absent} (patch, illuminant) pair(s) missing, e.g. patch {shown(p)} "
            f"under {shown(i)}: every patch needs a row for every illuminant",
            path=path,
        )
    rgb_a = np.array([[records[(p, i)][0] for i in illums] for p in patches])
    std_a = np.array([[records[(p, i)][1] for i in illums] for p in patches])
    n_a = np.array([[records[(p, i)][2] for i in illums] for p in patches])
    s_a = np.array([[records[(p, i)][3] for i in illums] for p in patches])
    return Responses(
        tuple(patches),
        tuple(illums),
        rgb_a,
        std_a if has_std else None,
        n_a if has_n else None,
        s_a if has_sat else None,
        np.array([white[i][0] for i in illums]) if has_white else None,
    )


def _white_level(
    seen: dict[str, tuple[list[float], int]],
    illuminant: str,
    level: list[float],
    path: Path,
    lineno: int,
) -> None:
    """Record a row's white level of ``illuminant``: that of the illuminant's first
    row (it is one level per light, repeated on its rows)."""
    first = seen.setdefault(illuminant, (level, lineno))
    if not np.allclose(level, first[0], rtol=1e-9, atol=0.0):
        raise InputError(
            f"white_R,white_G,white_B under {shown(illuminant)} differ from line "
            f"{first[1]}'s: one white level per illuminant",
            path=path,
            line=lineno,
        )


def write_responses_csv(responses: Responses, path: str | PathLike[str]) -> None:
    """Write ``responses`` in long format (one row per patch and illuminant)."""
    header = ["patch", "illuminant", *CHANNELS]
    if responses.rgb_std is not None:
        header += list(_STD)
    if responses.n_pixels is not None:
        header.append("n_pixels")
    if responses.saturated is not None:
        header.append("saturated")
    if responses.white_rgb is not None:
        header += list(_WHITE)
    with atomic_open(path, newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for a, p in enumerate(responses.patches):
            for b, il in enumerate(responses.illuminants):
                row: list[str] = [p, il, *(repr(float(v)) for v in responses.rgb[a, b])]
                if responses.rgb_std is not None:
                    row += [repr(float(v)) for v in responses.rgb_std[a, b]]
                if responses.n_pixels is not None:
                    row.append(str(int(responses.n_pixels[a, b])))
                if responses.saturated is not None:
                    row.append(repr(float(responses.saturated[a, b])))
                if responses.white_rgb is not None:
                    row += [repr(float(v)) for v in responses.white_rgb[b]]
                w.writerow(row)
