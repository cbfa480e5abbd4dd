"""Outputs of a gonio session: a labelled NetCDF data set, CSV per geometry, plots.

``gonio.nc`` (xarray, NetCDF 3 through scipy): ``reflectance`` and ``u_reflectance``
(patch x geometry x wavelength), ``XYZ``, ``u_XYZ``, ``Lab`` and ``u_Lab`` (patch x
geometry x component), with the geometry's angles, its ``spectral`` flag and the
goniometer's read-back as coordinates; CF-style attributes (``units``,
``long_name`` on every variable, ``Conventions``, ``history``, ``source``) and a
standard uncertainty (k = 1) at every geometry. Per geometry, ``<folder>/reflectance.csv`` (spectral CSV)
and ``<folder>/colorimetry.csv`` (``patch,X,Y,Z,L,a,b,u_X,u_Y,u_Z``). ``angles.png``:
L*, a*, b* and the reflectance factor at 550 nm against the viewing angle.

xarray is used for the data set (labelled arrays written as self-describing NetCDF,
read back by any NetCDF tool); its scipy engine needs no HDF5 library.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from tunespec.app.pipeline.gonio_process import GonioResult
from tunespec.core.io.session import atomic_write_bytes, atomic_write_text
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.spectra import Spectra
from tunespec.devices.goniometer import ANGLE_AXES

__all__ = ["write_gonio_outputs"]


#: CF ``units`` and ``long_name`` of the data set's variables and coordinates.
_VARIABLE_ATTRS = {
    "reflectance": ("1", "reflectance factor (perfect diffuser = 1)"),
    "u_reflectance": ("1", "standard uncertainty (k=1) of the reflectance factor"),
    "XYZ": ("1", "CIE XYZ tristimulus values, D50, 1931 2 deg, white Y = 100"),
    "u_XYZ": ("1", "standard uncertainty (k=1) of XYZ (single shot)"),
    "Lab": ("1", "CIELAB of the reflectance, D50 (ICC white)"),
    "u_Lab": ("1", "standard uncertainty (k=1) of CIELAB"),
    "wavelength": ("nm", "wavelength"),
    "theta_i": ("degree", "polar angle of incidence"),
    "phi_i": ("degree", "azimuth of incidence"),
    "theta_r": ("degree", "polar angle of viewing"),
    "phi_r": ("degree", "azimuth of viewing"),
    "spectral": ("1", "1: full LED sequence captured; 0: spectra fused from the "
                 "single shot"),
}  # fmt: skip


def _now() -> str:
    from datetime import UTC, datetime

    return datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")


def _dataset(result: GonioResult, folder: Path):
    import xarray as xr

    from tunespec.core.io.export import tunespec_version

    geoms = [s.geometry for s in result.plan.steps]
    coords = {
        "patch": list(result.patches),
        "geometry": np.arange(len(geoms)),
        "wavelength": result.wavelength_nm,
        "component": ["X", "Y", "Z"],
        "lab_component": ["L", "a", "b"],
        "spectral": ("geometry", result.spectral.astype(np.int8)),
    }
    for a in ANGLE_AXES:
        coords[a] = ("geometry", np.array([getattr(g, a) for g in geoms]))
        coords[f"{a}_readback"] = (
            "geometry", np.array([float(p[a]) for p in result.positions])
        )  # fmt: skip
    pg = ("patch", "geometry")
    ds = xr.Dataset(
        {
            "reflectance": ((*pg, "wavelength"), result.reflectance),
            "u_reflectance": ((*pg, "wavelength"), result.u_reflectance),
            "XYZ": ((*pg, "component"), result.xyz),
            "u_XYZ": ((*pg, "component"), result.u_xyz),
            "Lab": ((*pg, "lab_component"), result.lab),
            "u_Lab": ((*pg, "lab_component"), result.u_lab),
        },
        coords=coords,
        attrs={
            "title": "TuneSpec gonio session",
            "Conventions": "CF-1.8",
            "source": f"tunespec {tunespec_version()}",
            "history": f"{_now()} tunespec gonio processing of {folder}",
            "references": "Trichromatic Reflectance Capture Using a Tunable Light "
            "Source (Eq. 1, 5); ASTM E308-15; JCGM 100:2008 (GUM)",
            "illuminant": "CIE D50, CIE 1931 2 deg, ASTM E308, white Y = 100",
            "reflectance_units": "reflectance factor (perfect diffuser = 1)",
            "angles_units": "degree",
            "u_reflectance_note": "standard uncertainty (k=1): the Wiener posterior "
            "std at spectral geometries; at fused geometries the single shot's XYZ "
            "covariance and the prior spectrum's (a^2 times the posterior variance "
            "of the patch's least specular spectral estimate) propagated through "
            "the fusion, first order",
        },
    )
    if result.warnings:  # one line each (netCDF-3 attributes hold no lists)
        ds.attrs["warnings"] = "\n".join(result.warnings)
    for name, (units, long_name) in _VARIABLE_ATTRS.items():
        ds[name].attrs.update(units=units, long_name=long_name)
    for a in ANGLE_AXES:
        ds[f"{a}_readback"].attrs.update(
            units="degree", long_name=f"{a} read back from the goniometer"
        )
    return ds


def write_gonio_outputs(result: GonioResult, folder: str | Path) -> list[Path]:
    """Write ``gonio.nc``, per-geometry CSVs and ``angles.png``; return the files."""
    root = Path(folder)
    out = [root / "gonio.nc"]
    data = _dataset(result, root.resolve()).to_netcdf(engine="scipy")
    atomic_write_bytes(out[0], bytes(data))
    for i in range(len(result.plan.steps)):
        gdir = root / result.plan.folder(i)
        spectra = Spectra(
            result.wavelength_nm, result.reflectance[:, i], result.patches
        )
        write_spectra_csv(spectra, gdir / "reflectance.csv")
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["patch", "X", "Y", "Z", "L", "a", "b", "u_X", "u_Y", "u_Z"])
        for p, name in enumerate(result.patches):
            vals = [*result.xyz[p, i], *result.lab[p, i], *result.u_xyz[p, i]]
            w.writerow([name, *(f"{v:.6g}" for v in vals)])
        atomic_write_text(gdir / "colorimetry.csv", buf.getvalue())
        out += [gdir / "reflectance.csv", gdir / "colorimetry.csv"]
    out.append(_plot(result, root / "angles.png"))
    return out


def _plot(result: GonioResult, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = result.plan.steps
    in_plane = [i for i, s in enumerate(steps) if s.geometry.phi_r == 180.0]
    order = sorted(in_plane, key=lambda i: steps[i].geometry.theta_r)
    theta = [steps[i].geometry.theta_r for i in order]
    j550 = int(np.argmin(np.abs(result.wavelength_nm - 550.0)))
    fig, axes = plt.subplots(1, 4, figsize=(14, 3.4))
    labels = ("L*", "a*", "b*", "reflectance factor at 550 nm")
    for k, ax in enumerate(axes):
        for p, name in enumerate(result.patches):
            y = result.lab[p, order, k] if k < 3 else result.reflectance[p, order, j550]
            ax.plot(theta, y, marker="o", ms=3, label=name)
        ax.set_xlabel("theta_r (deg), plane of incidence")
        ax.set_title(labels[k])
    axes[-1].legend(fontsize=6)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
    return path
