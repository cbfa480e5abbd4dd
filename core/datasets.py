"""Data shipped in ``tunespec.resources``: cameras, charts, LED sets, layouts.

Everything is read through :mod:`importlib.resources` so frozen builds work.
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.core.errors import InputError, check_names
from tunespec.core.spectra import DEFAULT_GRID, Grid, Spectra, read_spectra_csv

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
    """Read camera sensitivities in the rawtoaces-data JSON schema.

    Returns
    -------
    Spectra
        Names ``R, G, B``; ``meta`` holds ``manufacturer`` and ``model``.
    """
    path = Path(path)
    try:
        doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        header = doc.get("header", {})
        main = doc["spectral_data"]["data"]["main"]
        index = doc["spectral_data"].get("index", {}).get("main", ["R", "G", "B"])
        wl = np.array([float(k) for k in main])
        vals = np.array([main[k] for k in main], dtype=np.float64).T
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except json.JSONDecodeError as exc:
        raise InputError(
            f"not valid JSON: {exc.msg}", path=path, line=exc.lineno
        ) from None
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(
            f"not a rawtoaces camera file (spectral_data.data.main: {exc})", path=path
        ) from None
    if [c.upper() for c in index] != ["R", "G", "B"]:
        raise InputError(f"expected channels R, G, B, found {index}", path=path)
    order = np.argsort(wl)
    if not np.all(np.isfinite(vals)):
        raise InputError("non-finite sensitivity values", path=path)
    meta = {
        "manufacturer": str(header.get("manufacturer", "")),
        "model": str(header.get("model", "")),
        "source": str(path),
    }
    return Spectra(wl[order], vals[:, order], ("R", "G", "B"), meta)


def read_sensitivities(path: str | PathLike[str], grid: Grid | None = None) -> Spectra:
    """Camera sensitivities from a spectral CSV (R, G, B columns) or a rawtoaces JSON.

    Parameters
    ----------
    path
        ``.json``: the rawtoaces-data schema; anything else: a spectral CSV with at
        least the columns ``R``, ``G``, ``B`` (others are ignored).
    grid
        Working grid to resample onto; ``None`` keeps the file's wavelengths.

    Returns
    -------
    Spectra
        Names ``R, G, B``; ``meta["source"]`` is the file.

    Raises
    ------
    InputError
        Naming the file: unreadable, a channel missing, a range too short for the grid.
    """
    path = Path(path)
    if path.suffix.lower() == ".json":
        s = read_rawtoaces_json(path)
    else:
        s = read_spectra_csv(path)
        check_names(
            ("R", "G", "B"),
            s.names,
            "missing column(s) {names}; expected R, G, B",
            path=path,
        )
        s = s.select(["R", "G", "B"])
    s = Spectra(s.wavelength_nm, s.values, s.names, {**s.meta, "source": str(path)})
    return s if grid is None else s.resample(grid, source=str(path))


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
