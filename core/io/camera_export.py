"""The camera characterisation exports: the chart's ``.ti3`` for ArgyllCMS ``colprof``
and the ACES input transforms (colour-science ``matrix_idt``) with their CSV.

Split from :mod:`tunespec.core.io.export`, whose measurement exports these reuse
(the reflectance ``.ti3`` writer and the CSV row writer).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.core.atomic import atomic_write_text
from tunespec.core.io.cgats import CgatsTable, write_cgats
from tunespec.core.io.export import (
    _write_rows,
    reflectance_ti3,
)
from tunespec.core.limits import dumps_json
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "CAMERA_EXPORT_NAMES",
    "CameraExport",
    "camera_ti3",
    "camera_transforms",
    "export_camera_characterisation",
    "write_camera_transforms",
]


#: Files of :func:`export_camera_characterisation`.
CAMERA_EXPORT_NAMES: dict[str, str] = {
    "chart_camera_ti3": "chart_camera.ti3",
    "camera_transforms_json": "camera_transforms.json",
    "camera_transforms_csv": "camera_transforms.csv",
}


def camera_ti3(
    chart: Spectra,
    responses: Responses,
    illuminants: Spectra,
    *,
    under: str = "D50",
    created: datetime | str | None = None,
) -> CgatsTable:
    """The chart's camera ``.ti3`` for ArgyllCMS ``colprof`` (an input profile).

    Every patch of ``responses`` with its reference spectrum, XYZ and L*a*b* (D50)
    and the camera's linear RGB ``under`` one illuminant: the name of one of the
    responses' illuminants (that LED's responses as measured), or a standard
    illuminant (``"D50"``, ``"D65"``, ``"A"``), for which the responses under all
    LEDs are summed with the non-negative weights whose mix best matches its SPD
    (:func:`~tunespec.core.characterisation.illuminant_mix`; Eq. 1 is linear in the
    light). The RGB is scaled so that its largest value is 95 % (Argyll's device
    values are percent); patches clipped under a light used are left out
    (``TUNESPEC_LEFT_OUT``).

    Raises
    ------
    InputError
        Patches without reference spectra, an unknown ``under``.
    """
    from tunespec.core.characterisation import illuminant_mix, standard_illuminant

    keywords = {"TUNESPEC_CAMERA_RGB": ""}
    if under in responses.illuminants:
        weights = np.array([float(n == under) for n in responses.illuminants])
        keywords["TUNESPEC_CAMERA_RGB"] = f"measured under {under}"
    else:
        target = standard_illuminant(under, Grid(300.0, 830.0, 1.0))
        used = illuminants.select(responses.illuminants, source="illuminants")
        weights, mismatch = illuminant_mix(used, target)
        keywords["TUNESPEC_CAMERA_RGB"] = (
            f"sum of the responses under the LEDs weighted to match {under} "
            f"(relative RMS mismatch of the mix {mismatch:.3f})"
        )
    rgb = np.einsum("pic,i->pc", responses.rgb, weights)
    keep = np.ones(len(responses.patches), dtype=bool)
    if responses.saturated is not None:
        keep &= ~np.any((responses.saturated > 0) & (weights > 0), axis=1)
    names = [p for p, k in zip(responses.patches, keep, strict=True) if k]
    if len(names) < len(responses.patches):
        keywords["TUNESPEC_LEFT_OUT"] = " ".join(
            p for p, k in zip(responses.patches, keep, strict=True) if not k
        )
    scale = 0.95 / float(rgb[keep].max())
    keywords["TUNESPEC_RGB_SCALE"] = f"{scale!r} (RGB = responses x scale)"
    mixed = Responses(tuple(names), (under,), (rgb[keep] * scale)[:, None, :])
    refl = chart.select(names, source=chart.meta.get("source"))
    return reflectance_ti3(
        refl,
        responses=mixed,
        illuminant=under,
        descriptor=f"Camera RGB of the chart under {under} (TuneSpec)",
        created=created,
        keywords=keywords,
    )


def camera_transforms(
    sensitivity: Spectra,
    training: Spectra,
    *,
    illuminants: Mapping[str, Spectra] | None = None,
    idt_illuminant: str = "D55",
) -> list[Any]:
    """The ACES IDT and a 3x3 CCM per illuminant, with training and test errors.

    CCMs are trained on ``training`` (the chart) and tested on colour-science's 190
    rawtoaces reflectances; the IDT is trained on those 190 (*RAW to ACES* v1) and
    tested on ``training``. ``illuminants``: name -> SPD (default D50, D65, A).
    """
    from tunespec.core.characterisation import (
        STANDARD_ILLUMINANTS,
        aces_idt,
        colour_correction_matrix,
        standard_illuminant,
    )
    from tunespec.core.datasets import load_training_reflectances_190

    full = Grid(300.0, 830.0, 5.0)
    if illuminants is None:
        illuminants = {n: standard_illuminant(n, full) for n in STANDARD_ILLUMINANTS}
    wl = training.wavelength_nm
    test = load_training_reflectances_190(Grid(wl[0], wl[-1], training.step_nm))
    test = Spectra(
        test.wavelength_nm, test.values, test.names, {"set": "rawtoaces 190"}
    )
    chart = Spectra(
        training.wavelength_nm, training.values, training.names, {"set": "chart"}
    )
    out = [aces_idt(sensitivity, standard_illuminant(idt_illuminant, full), chart)]
    for spd in illuminants.values():
        out.append(colour_correction_matrix(sensitivity, spd, chart, test))
    return out


def write_camera_transforms(
    transforms: list[Any], json_path: str | PathLike[str], csv_path: str | PathLike[str]
) -> tuple[Path, Path]:
    """The transforms as JSON (full) and CSV (one row per transform).

    CSV columns: ``kind,illuminant,m11,...,m33,wb_r,wb_g,wb_b,train_set,train_n,
    train_mean_de00,train_max_de00,test_set,test_n,test_mean_de00,test_max_de00``.
    """
    doc = {
        "applies_as": "out = matrix @ (camera_rgb * white_balance); ccm: out is CIE "
        "XYZ with Y(white) = 1 under the illuminant; aces_idt: out is ACES2065-1",
        "transforms": [t.as_dict() for t in transforms],
    }
    json_path, csv_path = Path(json_path), Path(csv_path)
    atomic_write_text(json_path, dumps_json(doc))
    header = ["kind", "illuminant"]
    header += [f"m{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)]
    header += ["wb_r", "wb_g", "wb_b"]
    for part in ("train", "test"):
        header += [f"{part}_set", f"{part}_n", f"{part}_mean_de00", f"{part}_max_de00"]
    rows = []
    for t in transforms:
        row = [t.kind, t.illuminant, *(repr(float(v)) for v in t.matrix.ravel())]
        row += [repr(float(v)) for v in t.white_balance]
        for errs in (t.training, t.test):
            row += [errs["set"], str(errs["n"])]
            row += [repr(errs["mean_de00"]), repr(errs["max_de00"])]
        rows.append(row)
    _write_rows(csv_path, header, rows)
    return json_path, csv_path


@dataclass(frozen=True)
class CameraExport:
    """What :func:`export_camera_characterisation` wrote: the files (by
    :data:`CAMERA_EXPORT_NAMES` key), the chart's ``.ti3`` table and the transforms."""

    paths: dict[str, Path]
    table: CgatsTable
    transforms: list[Any]


def export_camera_characterisation(
    out_dir: str | PathLike[str],
    *,
    sensitivity: Spectra,
    chart: Spectra,
    responses: Responses,
    illuminants: Spectra,
    under: str = "D50",
    created: datetime | str | None = None,
) -> CameraExport:
    """``chart_camera.ti3`` (:func:`camera_ti3`) and ``camera_transforms.json/.csv``.

    ArgyllCMS ``colprof -a m -O camera.icc chart_camera`` builds an ICC input profile
    from the ``.ti3``, ``profcheck chart_camera.ti3 camera.icc`` reports its errors.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {k: out / v for k, v in CAMERA_EXPORT_NAMES.items()}
    table = camera_ti3(chart, responses, illuminants, under=under, created=created)
    write_cgats(table, paths["chart_camera_ti3"])
    transforms = camera_transforms(sensitivity, chart)
    write_camera_transforms(
        transforms, paths["camera_transforms_json"], paths["camera_transforms_csv"]
    )
    return CameraExport(paths, table, transforms)
