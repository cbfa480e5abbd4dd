"""Data shipped in ``tunespec.resources``: cameras, charts, LED sets, layouts.

Everything is read through :mod:`importlib.resources` so frozen builds work.
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources
from os import PathLike
from pathlib import Path

import numpy as np

from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra

__all__ = [
    "DEFAULT_CAMERA",
    "camera_names",
    "load_camera",
    "load_camera_database",
    "load_colorchecker_sg",
    "load_led_set",
    "load_training_reflectances_190",
    "read_rawtoaces_json",
    "read_sensitivities",
    "resource_path",
]

DEFAULT_CAMERA = "Canon EOS 5D Mark III"


def resource_path(*parts: str) -> Path:
    """Filesystem path of a shipped resource, e.g. ``resource_path("charts", "x.csv")``."""
    ref = resources.files("tunespec.resources").joinpath(*parts)
    path = Path(str(ref))
    if not path.exists():
        raise InputError(f"missing resource {'/'.join(parts)} (broken installation?)")
    return path


def read_rawtoaces_json(path: str | PathLike[str]) -> Spectra:
    """Read camera sensitivities in the rawtoaces-data JSON schema, as stored.

    Returns
    -------
    Spectra
        Names ``R, G, B``; ``meta`` holds ``manufacturer`` and ``model``.
    """
    from tunespec.core.io.spectral import rawtoaces_spectra
    from tunespec.core.limits import read_json

    s = rawtoaces_spectra(read_json(path), source=str(path))
    if [c.upper() for c in s.names] != ["R", "G", "B"]:
        raise InputError(f"expected channels R, G, B, found {list(s.names)}", path=path)
    return Spectra(
        s.wavelength_nm, s.values, ("R", "G", "B"), {**s.meta, "source": str(path)}
    )


def read_sensitivities(path: str | PathLike[str], grid: Grid | None = None) -> Spectra:
    """Camera sensitivities from any spectral file with channels R, G, B.

    Spectral CSV, CGATS or rawtoaces JSON, found from the content
    (:func:`tunespec.core.io.spectral.read_spectral` with ``kind="sensitivity"``: a
    rawtoaces JSON written by TuneSpec is put back on its absolute scale).

    Parameters
    ----------
    path
        The file.
    grid
        Working grid to resample onto; ``None`` keeps the file's wavelengths.

    Returns
    -------
    Spectra
        Names ``R, G, B``; ``meta["source"]`` is the file, ``meta["relative"]`` is
        set for sensitivities in relative units without an absolute scale.

    Raises
    ------
    InputError
        Naming the file: unreadable, a channel missing, a range too short for the grid.
    """
    from tunespec.core.io.spectral import read_spectral

    return read_spectral(path, grid, kind="sensitivity")


@lru_cache(maxsize=1)
def _raw_camera_database() -> dict[str, Spectra]:
    folder = resource_path("cameras")
    db: dict[str, Spectra] = {}
    for f in sorted(folder.glob("*.json")):
        s = read_rawtoaces_json(f)
        name = f"{s.meta['manufacturer']} {s.meta['model']}".strip()
        db[name] = s
    return db


def camera_names() -> list[str]:
    """Names (``"Manufacturer Model"``) of the cameras in the shipped database."""
    return list(_raw_camera_database())


def load_camera_database(grid: Grid = DEFAULT_GRID) -> dict[str, Spectra]:
    """All shipped camera sensitivities on ``grid``, each normalised to peak 1."""
    out = {}
    for name, s in _raw_camera_database().items():
        r = s.resample(grid, source=s.meta["source"])
        out[name] = r.with_values(r.values / r.values.max())
    return out


def load_camera(name: str = DEFAULT_CAMERA, grid: Grid = DEFAULT_GRID) -> Spectra:
    """One camera of the shipped database (peak 1), by name."""
    db = load_camera_database(grid)
    if name not in db:
        raise InputError(f"unknown camera {name!r}; known: {', '.join(db)}")
    return db[name]


def load_colorchecker_sg(grid: Grid = DEFAULT_GRID) -> Spectra:
    """ColorChecker SG reflectances, 140 patches A1 ... N10."""
    return read_spectra_csv(resource_path("charts", "colorchecker_sg.csv"), grid)


def load_led_set(grid: Grid = DEFAULT_GRID) -> Spectra:
    """The nominal CAL1-like 22-LED model (see ``resources/leds/SOURCE.md``)."""
    return read_spectra_csv(resource_path("leds", "cal1_model_22.csv"), grid)


def load_training_reflectances_190(grid: Grid = DEFAULT_GRID) -> Spectra:
    """colour-science's 190-patch rawtoaces training reflectances (an independent set)."""
    # colour-science changes numpy's print options on import; keep the caller's.
    with np.printoptions():
        from colour.characterisation import read_training_data_rawtoaces_v1

    msds = read_training_data_rawtoaces_v1()
    s = Spectra(
        np.asarray(msds.wavelengths, dtype=np.float64),
        np.asarray(msds.values, dtype=np.float64).T,
        tuple(str(x) for x in msds.labels),
        {"source": "colour-science rawtoaces training data v1"},
    )
    return s.resample(grid)
