"""Patch name maps: other tools' names for a chart's patches -> the layout's.

A name map is a CSV of two columns, a header line, then one patch a line::

    name,patch
    dark skin,A1
    light skin,A2

The first column is the name in the reference data (colour-science's ColorChecker
``"dark skin"`` ..., a vendor's ``"1"`` ...), the second the layout's patch name.
``resources/charts/colorchecker_24_colour_science_names.csv`` maps colour-science's
ColorChecker names (``colour.SDS_COLOURCHECKERS``) to the ColorChecker 24 layout's
A1 ... D6. Spectra not in the map keep their names.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

from tunespec.core.errors import InputError
from tunespec.core.limits import csv_rows, read_text, shown, valid_name
from tunespec.core.spectra import Spectra

__all__ = ["read_name_map", "rename_spectra"]


def read_name_map(path: str | PathLike[str]) -> dict[str, str]:
    """The map {their name: patch name} of a two-column CSV.

    Raises
    ------
    InputError
        Naming the file and line: not two columns, an empty or invalid name, a
        name or a patch given twice.
    """
    path = Path(path)
    rows = csv_rows(read_text(path), path=path)
    if len(rows) < 2:
        raise InputError(
            "expected a name map: a header line, then 'their name,patch' lines",
            path=path,
        )
    out: dict[str, str] = {}
    targets: set[str] = set()
    for lineno, row in rows[1:]:
        if len(row) != 2:
            raise InputError(
                f"{len(row)} fields, expected 2 (their name, patch)",
                path=path,
                line=lineno,
            )
        theirs, ours = (
            valid_name(c.strip(), "name map", path=path, line=lineno) for c in row
        )
        if theirs in out:
            raise InputError(f"{shown(theirs)} given twice", path=path, line=lineno)
        if ours in targets:
            raise InputError(f"patch {shown(ours)} given twice", path=path, line=lineno)
        out[theirs] = ours
        targets.add(ours)
    return out


def rename_spectra(
    spectra: Spectra, mapping: dict[str, str], *, source: str | None = None
) -> Spectra:
    """``spectra`` with the names the map gives (others unchanged).

    Raises
    ------
    InputError
        When no spectrum's name is in the map (the wrong map for these data), or
        the renaming makes two spectra share a name.
    """
    if not any(n in mapping for n in spectra.names):
        raise InputError(
            f"none of the names in the data ({', '.join(spectra.names[:3])} ...) is "
            "in the name map (--names)",
            path=source,
        )
    names = tuple(mapping.get(n, n) for n in spectra.names)
    if len(set(names)) != len(names):
        raise InputError(
            "the name map gives two spectra the same patch name", path=source
        )
    return spectra.with_values(spectra.values, names)
