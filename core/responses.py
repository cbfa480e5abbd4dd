"""Camera responses per patch and illuminant, and their long-format CSV.

CSV columns: ``patch,illuminant,R,G,B`` and optionally ``R_std,G_std,B_std`` (per-pixel
standard deviation inside the patch ROI, as Eq. 6 of the paper uses), ``n_pixels`` and
``saturated`` (fraction of ROI pixels at or above the white level). Values are linear,
dark-corrected and flat-fielded, in units of full scale (1.0 = saturation).
"""

from __future__ import annotations

import csv
import math
from collections import Counter
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError, check_names, read_text
from tunespec.core.limits import csv_rows, shown, valid_name, valid_number

__all__ = ["CHANNELS", "Responses", "read_responses_csv", "write_responses_csv"]

CHANNELS = ("R", "G", "B")
_STD = tuple(f"{c}_std" for c in CHANNELS)


@dataclass(frozen=True, eq=False)
class Responses:
    """RGB responses of patches under illuminants.

    Parameters
    ----------
    patches : n_p names
    illuminants : n_i names, matching the illuminant spectra's names
    rgb : (n_p, n_i, 3)
        Mean response in units of full scale.
    rgb_std : (n_p, n_i, 3) or None
        Per-pixel standard deviation inside the ROI.
    n_pixels : (n_p, n_i) or None
        Pixels averaged (per colour plane).
    saturated : (n_p, n_i) or None
        Fraction of ROI pixels that were clipped.
    """

    patches: tuple[str, ...]
    illuminants: tuple[str, ...]
    rgb: NDArray[np.float64]
    rgb_std: NDArray[np.float64] | None = None
    n_pixels: NDArray[np.float64] | None = None
    saturated: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        shape = (len(self.patches), len(self.illuminants))
        object.__setattr__(self, "patches", tuple(self.patches))
        object.__setattr__(self, "illuminants", tuple(self.illuminants))
        for what, names in (("patch", self.patches), ("illuminant", self.illuminants)):
            if len(set(names)) != len(names):
                dup = sorted({n for n in names if names.count(n) > 1})
                raise InputError(f"duplicate {what} names: {', '.join(dup[:8])}")
        rgb = np.asarray(self.rgb, dtype=np.float64)
        if rgb.shape != (*shape, 3):
            raise InputError(f"rgb shape {rgb.shape}, expected {(*shape, 3)}")
        object.__setattr__(self, "rgb", rgb)
        for name, want in (
            ("rgb_std", (*shape, 3)),
            ("n_pixels", shape),
            ("saturated", shape),
        ):
            arr = getattr(self, name)
            if arr is not None:
                arr = np.asarray(arr, dtype=np.float64)
                if arr.shape != want:
                    raise InputError(f"{name} shape {arr.shape}, expected {want}")
                object.__setattr__(self, name, arr)

    def subset(
        self, patches: list[str] | None = None, illuminants: list[str] | None = None
    ) -> Responses:
        """The responses of some patches and/or illuminants, in the given order.

        ``None`` keeps all of them; an empty list keeps none.

        Raises
        ------
        InputError
            Names that are not in the responses.
        """
        pi = _indices(self.patches, patches, "patch")
        ii = _indices(self.illuminants, illuminants, "illuminant")

        def take(a: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
            return None if a is None else a[np.ix_(pi, ii)]

        return Responses(
            tuple(self.patches[i] for i in pi),
            tuple(self.illuminants[i] for i in ii),
            take(self.rgb),  # type: ignore[arg-type]
            take(self.rgb_std),
            take(self.n_pixels),
            take(self.saturated),
        )


def _indices(have: tuple[str, ...], names: list[str] | None, what: str) -> list[int]:
    if names is None:
        return list(range(len(have)))
    check_names(names, have, f"{{n}} {what} name(s) not in the responses: {{names}}")
    return [have.index(n) for n in names]


def read_responses_csv(path: str | PathLike[str]) -> Responses:
    """Read a long-format responses CSV.

    Raises
    ------
    InputError
        Missing columns, bad or non-finite numbers, negative standard deviations,
        duplicate or missing (patch, illuminant) pairs; each names the file and line.
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
        raise InputError(
            f"missing column(s) {', '.join(missing)}; expected patch,illuminant,R,G,B",
            path=path,
            line=header_line,
        )
    col = {h: i for i, h in enumerate(header)}
    has_std = all(c in col for c in _STD)
    if any(c in col for c in _STD) and not has_std:
        raise InputError(
            "give all of R_std,G_std,B_std or none", path=path, line=header_line
        )
    has_n = "n_pixels" in col
    has_sat = "saturated" in col
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
    )


def write_responses_csv(responses: Responses, path: str | PathLike[str]) -> None:
    """Write ``responses`` in long format (one row per patch and illuminant)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = ["patch", "illuminant", *CHANNELS]
    if responses.rgb_std is not None:
        header += list(_STD)
    if responses.n_pixels is not None:
        header.append("n_pixels")
    if responses.saturated is not None:
        header.append("saturated")
    with path.open("w", newline="", encoding="utf-8") as fh:
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
                w.writerow(row)
