"""A gonio session for a front end: run (or resume) it, and its result as arrays.

:func:`run_gonio_plan` runs a plan on the simulated gonio bench
(:func:`~tunespec.app.pipeline.gonio_bench.run_gonio_demo`) or on devices by spec
(:func:`~tunespec.app.pipeline.gonio_devices.run_gonio_session`), then returns
:func:`load_gonio_result`: the fused result per geometry read back from the session's
``gonio.nc``, as plain arrays that pickle (the GUI runs this in a process of its own).
:func:`geometry_progress` counts each geometry's frames on disk, which is what the
GUI shows as live progress per geometry.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.app.pipeline.gonio import GonioPlan, frame_names
from tunespec.core.errors import InputError
from tunespec.core.progress import ProgressFn, StopFn

__all__ = [
    "DeviceSpecs",
    "geometry_progress",
    "load_gonio_result",
    "run_gonio_plan",
]


@dataclass(frozen=True)
class DeviceSpecs:
    """The devices of a session on hardware (the specs of ``tunespec gonio-run``)."""

    light: str
    camera: str
    gonio: str
    sensitivities: str
    layout: str


def run_gonio_plan(
    out: str | Path,
    *,
    plan: str | Path | None = None,
    n_geometries: int = 14,
    devices: DeviceSpecs | None = None,
    seed: int = 0,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> dict[str, Any]:
    """Run or resume the gonio session in ``out``; return :func:`load_gonio_result`.

    ``plan``: a plan file for a new session (a started one keeps its own); none:
    the default plan of ``n_geometries``. ``devices``: None for the simulated bench.
    """
    root = Path(out)
    kept = root / "plan.json"
    if plan is not None and not kept.exists():
        GonioPlan.load(plan)  # checked before the session starts
        root.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(plan, kept)
    if devices is None:
        from tunespec.app.pipeline.gonio_bench import run_gonio_demo

        run_gonio_demo(root, n_geometries=n_geometries, seed=seed,
                       progress=progress, should_stop=should_stop)  # fmt: skip
    else:
        from tunespec.app.pipeline.gonio_devices import run_gonio_session
        from tunespec.core.io.spectral import read_spectra_csv
        from tunespec.core.layout import TargetLayout

        if not kept.exists():
            raise InputError("a session on devices needs a plan: choose a plan file")
        run_gonio_session(
            root, light=devices.light, camera=devices.camera, gonio=devices.gonio,
            sensitivity=read_spectra_csv(devices.sensitivities, allow_negative=True),
            layout=TargetLayout.load(devices.layout), layout_path=devices.layout,
            seed=seed, progress=progress, should_stop=should_stop,
        )  # fmt: skip
    return load_gonio_result(root)


def load_gonio_result(folder: str | Path) -> dict[str, Any]:
    """The fused result of a finished session (``gonio.nc``) as numpy arrays.

    Keys: ``patches``; per geometry ``theta_i``, ``theta_r``, ``phi_r`` (deg, as
    read back) and ``spectral`` (bool); ``wavelength_nm``; ``reflectance`` and its
    standard uncertainty ``u_reflectance`` (n_patch, n_geometry, n_wl); ``lab`` and
    ``u_lab`` (n_patch, n_geometry, 3: L*, a*, b*, D50); ``warnings``: what the
    processing said against the session's frames (a line each).
    """
    import xarray as xr

    path = Path(folder) / "gonio.nc"
    if not path.exists():
        raise InputError("no gonio.nc: the session is not processed yet", path=path)
    with xr.open_dataset(path, engine="scipy") as ds:
        out = {
            "patches": [str(p) for p in ds.patch.values],
            "wavelength_nm": np.asarray(ds.wavelength.values, np.float64),
            "spectral": np.asarray(ds.spectral.values).astype(bool),
            "warnings": str(ds.attrs.get("warnings", "")).splitlines(),
        }
        for a in ("theta_i", "theta_r", "phi_r"):
            out[a] = np.asarray(ds[f"{a}_readback"].values, np.float64)
        for name, var in (("reflectance", "reflectance"), ("lab", "Lab"),
                          ("u_reflectance", "u_reflectance"), ("u_lab", "u_Lab")):  # fmt: skip
            out[name] = np.asarray(ds[var].values, np.float64)
    return out


def geometry_progress(folder: str | Path) -> list[tuple[int, int]] | None:
    """Per geometry of the session's plan: (frames on disk, frames of the plan);
    None before the plan is written. LEDs: the plan's, else those of the session's
    ``leds_reported.csv``, else 22."""
    root = Path(folder)
    if not (root / "plan.json").exists():
        return None
    plan = GonioPlan.load(root / "plan.json")
    leds = list(plan.leds) or _session_leds(root)
    rows = []
    for i, step in enumerate(plan.steps):
        names = frame_names(step, leds)
        gdir = root / plan.folder(i)
        have = (
            {p.name for p in gdir.iterdir() if p.suffix == ".npy"}
            if gdir.is_dir()
            else set()
        )
        rows.append((sum(f"{n}_e{k}.npy" in have for n, k in names), len(names)))
    return rows


def _session_leds(root: Path) -> list[str]:
    from tunespec.core.io.spectral import read_spectra_csv

    path = root / "leds_reported.csv"
    if path.exists():
        return list(read_spectra_csv(path).names)
    return [f"LED{k}" for k in range(22)]
