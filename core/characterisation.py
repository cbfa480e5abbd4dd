"""Camera characterisation from calibrated sensitivities: CCMs, an ACES IDT, a D50 mix.

What a calibrated camera gives other tools:

- :func:`colour_correction_matrix`: a 3x3 matrix from white-balanced camera RGB to CIE
  XYZ under a chosen illuminant (D50, D65, A or any SPD), white-preserving least
  squares on a training set of reflectances, with its CIEDE2000 errors on that set and
  on an independent test set;
- :func:`aces_idt`: the ACES input transform of the camera under an illuminant, by
  colour-science's ``matrix_idt`` (the *RAW to ACES* v1 method: the 190 rawtoaces
  training reflectances, CIELAB error minimised), with the same errors;
- :func:`illuminant_mix`: non-negative weights of the LEDs whose sum best matches a
  target SPD (D50 by default): the responses under that mix are the sum of the
  weighted responses (Eq. 1 is linear in the illuminant), which is what the chart's
  camera ``.ti3`` holds for ``colprof``.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (Eq. 1);
The Academy, *RAW to ACES* v1 / P-2013-001 (IDT); colour-science
``colour.characterisation.matrix_idt``; G. Finlayson, M. Drew, "White-point preserving
color correction" (1997) for the constrained least squares.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.colorimetry import _colour, _quiet_colour, delta_e_2000
from tunespec.core.errors import InputError
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "CameraTransform",
    "aces_idt",
    "colour_correction_matrix",
    "illuminant_mix",
    "standard_illuminant",
]

#: Illuminants known by name (colour-science's ``SDS_ILLUMINANTS``).
STANDARD_ILLUMINANTS = ("D50", "D65", "A")


@dataclass(frozen=True)
class CameraTransform:
    """A 3x3 camera matrix with its errors.

    Parameters
    ----------
    kind
        ``"ccm"`` (white-balanced camera RGB -> XYZ, Y of the white = 1) or
        ``"aces_idt"`` (white-balanced camera RGB -> ACES2065-1).
    illuminant
        The scene illuminant it is for.
    matrix : (3, 3)
        Applied as ``out = matrix @ (rgb * white_balance)``.
    white_balance : (3,)
        Per-channel multipliers that make the perfect white's RGB equal (G = 1).
    training, test
        ``{"set": name, "n": count, "mean_de00": ..., "max_de00": ...}``.
    """

    kind: str
    illuminant: str
    matrix: NDArray[np.float64]
    white_balance: NDArray[np.float64]
    training: Mapping[str, Any]
    test: Mapping[str, Any]

    def as_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "illuminant": self.illuminant,
            "matrix": [[float(v) for v in row] for row in self.matrix],
            "white_balance": [float(v) for v in self.white_balance],
            "training": dict(self.training),
            "test": dict(self.test),
        }


def standard_illuminant(name: str, grid: Grid) -> Spectra:
    """CIE illuminant ``name`` (D50, D65, A) on ``grid``, peak 1."""
    colour = _colour()
    if name not in colour.SDS_ILLUMINANTS:
        raise InputError(f"unknown illuminant {name!r}; known: D50, D65, A or a file")
    sd = colour.SDS_ILLUMINANTS[name]
    values = np.interp(grid.wavelength_nm, sd.wavelengths, sd.values)
    return Spectra(grid.wavelength_nm, values[None] / values.max(), (name,))


def _xyz(reflectance: NDArray, illuminant: NDArray, cmfs: NDArray) -> NDArray:
    """XYZ (Y of the perfect white = 1) of reflectances (n, n_wl) under an SPD."""
    k = 1.0 / float(cmfs[1] @ illuminant)
    return (reflectance * illuminant) @ cmfs.T * k


def _cmfs(wl: NDArray[np.float64]) -> NDArray[np.float64]:
    colour = _colour()
    c = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return np.stack([np.interp(wl, c.wavelengths, c.values[:, k]) for k in range(3)])


def _de00(xyz_est: NDArray, xyz_ref: NDArray, white_xyz: NDArray) -> NDArray:
    colour = _colour()
    xy = colour.XYZ_to_xy(white_xyz)
    return delta_e_2000(colour.XYZ_to_Lab(xyz_est, xy), colour.XYZ_to_Lab(xyz_ref, xy))


def _errors(name: str, de: NDArray[np.float64]) -> dict[str, Any]:
    return {
        "set": name,
        "n": int(de.size),
        "mean_de00": float(np.mean(de)),
        "max_de00": float(np.max(de)),
    }


def _common(*spectra: Spectra) -> Grid:
    from tunespec.core.spectra import grid_from_data

    return grid_from_data(list(spectra))


def colour_correction_matrix(
    sensitivity: Spectra,
    illuminant: Spectra,
    training: Spectra,
    test: Spectra,
) -> CameraTransform:
    """White-preserving 3x3 CCM: white-balanced camera RGB -> XYZ under ``illuminant``.

    The camera RGB of each reflectance is Eq. 1 with the SPD; it is divided by the
    perfect white's RGB (white balance). The matrix minimises the squared XYZ error
    over ``training`` with the constraint that the white maps to the illuminant's
    XYZ exactly (each row: two free coefficients, the third fixed by the row's sum).

    Errors: CIEDE2000 of the corrected XYZ against the reflectances' true XYZ
    (CIE 1931 2°), CIELAB relative to the illuminant's white, on ``training`` and
    ``test``.
    """
    grid = _common(sensitivity, illuminant, training, test)
    wl = grid.wavelength_nm
    s = sensitivity.resample(grid).values
    e = illuminant.resample(grid, average=True).values[0]
    cm = _cmfs(wl)
    white_rgb = s @ e
    if np.any(white_rgb <= 0):
        raise InputError("the camera sees no light of this illuminant in a channel")
    wb = white_rgb[1] / white_rgb
    white_xyz = _xyz(np.ones((1, wl.size)), e, cm)[0]

    def rgb_xyz(refl: Spectra) -> tuple[NDArray, NDArray]:
        r = refl.resample(grid).values
        return (r * e) @ s.T * wb / white_rgb[1], _xyz(r, e, cm)

    rgb, xyz = rgb_xyz(training)
    M = np.empty((3, 3))
    for k in range(3):
        # m3 = w_k - m1 - m2 (white (1, 1, 1) -> white_xyz[k])
        A = rgb[:, :2] - rgb[:, 2:3]
        b = xyz[:, k] - white_xyz[k] * rgb[:, 2]
        m12 = np.linalg.lstsq(A, b, rcond=None)[0]
        M[k] = [m12[0], m12[1], white_xyz[k] - m12.sum()]
    errs = []
    for name, refl in (("training", training), ("test", test)):
        r, x = rgb_xyz(refl)
        de = _de00(r @ M.T, x, white_xyz)
        errs.append(_errors(refl.meta.get("set", name), de))
    name = illuminant.names[0]
    return CameraTransform("ccm", name, M, wb, errs[0], errs[1])


def aces_idt(
    sensitivity: Spectra, illuminant: Spectra, test: Spectra
) -> CameraTransform:
    """The ACES input transform under ``illuminant`` (colour-science ``matrix_idt``).

    Trained on the 190 rawtoaces reflectances as *RAW to ACES* v1 does (CIELAB
    error, CAT02 to the ACES white); the sensitivities are put on 380-780 nm at 5 nm
    with 0 where they were not estimated. Errors: CIEDE2000 between ACES2065-1
    converted to XYZ and the reflectances' XYZ adapted to the ACES white, on the
    training set and on ``test``.

    References
    ----------
    Academy of Motion Picture Arts and Sciences, P-2013-001 (ACES input device
    transform procedure); colour-science ``colour.matrix_idt``.
    """
    colour = _colour()
    from colour.characterisation import (
        RGB_CameraSensitivities,
        training_data_sds_to_RGB,
        training_data_sds_to_XYZ,
    )

    shape = colour.SpectralShape(380, 780, 5)
    wl = shape.wavelengths
    src_wl = sensitivity.wavelength_nm
    s = np.stack(
        [np.interp(wl, src_wl, v, left=0, right=0) for v in sensitivity.values]
    )
    # colour-science (as rawtoaces) normalises the light by the channel with the
    # highest peak and then assumes it is green; a channel's scale only moves into
    # its white-balance multiplier, so R and B are scaled below G and that is undone
    k = np.maximum(s.max(axis=1) / s[1].max(), 1.0) * np.array([1.001, 1.0, 1.001])
    sens = RGB_CameraSensitivities(
        (s / k[:, None]).T, wl, labels=("red", "green", "blue")
    )
    e = np.interp(wl, illuminant.wavelength_nm, illuminant.values[0])
    sd = colour.SpectralDistribution(e, wl, name=illuminant.names[0])
    aces = colour.RGB_COLOURSPACES["ACES2065-1"]
    white_xyz = colour.xy_to_XYZ(aces.whitepoint)
    with _quiet_colour():
        M, rgb_w, xyz, rgb = colour.matrix_idt(sens, sd, additional_data=True)
        test_msds = colour.MultiSpectralDistributions(
            test.values.T, test.wavelength_nm, labels=list(test.names)
        )
        test_msds = colour.characterisation.aces_it.reshape_msds(test_msds, shape)
        cmfs = (
            colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
        )
        illum = colour.characterisation.aces_it.normalise_illuminant(sd, sens)
        rgb_t, _ = training_data_sds_to_RGB(test_msds, sens, illum)
        xyz_t = training_data_sds_to_XYZ(test_msds, cmfs, illum, "CAT02")
    to_xyz = aces.matrix_RGB_to_XYZ
    errs = [
        _errors(name, _de00((r @ M.T) @ to_xyz.T, x, white_xyz))
        for name, r, x in (
            ("rawtoaces 190", rgb, xyz),
            (test.meta.get("set", "test"), rgb_t, xyz_t),
        )
    ]
    return CameraTransform(
        "aces_idt", illuminant.names[0], np.asarray(M), np.asarray(rgb_w) / k, *errs
    )


def illuminant_mix(
    illuminants: Spectra, target: Spectra
) -> tuple[NDArray[np.float64], float]:
    """Non-negative weights ``w`` with ``sum_i w_i L_i`` closest to ``target``.

    Least squares on the grid both cover (the LEDs band-averaged onto it), target
    scaled to the LEDs' power. Returns the weights and the relative RMS mismatch of
    the mix.

    References
    ----------
    Eq. 1 of the paper for the mixed spectrum; Lawson and Hanson, *Solving Least
    Squares Problems* (1974), ch. 23 (non-negative least squares).
    """
    from scipy.optimize import nnls

    grid = _common(illuminants, target)
    L = illuminants.resample(grid, average=True).values
    t = target.resample(grid, average=True).values[0]
    t = t * (L.sum(axis=0).mean() / t.mean())
    w, resid = nnls(L.T, t)
    return w, float(resid / np.linalg.norm(t))
