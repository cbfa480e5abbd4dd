"""Illuminant matching: LED drive levels whose mix reproduces a target SPD.

The gonio-imager captures CIE XYZ "in a single shot by simply adjusting the tunable
light source to the desired SPD" (the paper's introduction): the 22 LEDs are mixed to
simulate an illuminant (CIE D50 by default). A mix cannot equal a smooth SPD, so the
levels are chosen for what matters colorimetrically:

1. the chromaticity of the mix is pinned to the target's (CIE 1976 u'v', two equality
   constraints), so no chromatic adaptation is needed between the two;
2. subject to that, the *metamerism* of a set of reflectances is minimised: each
   reflectance's CIELAB under the mix (the mix's own white as reference) against its
   CIELAB under the target (the target's white), with the CIE 1931 2° observer; the
   objective is the mean squared CIEDE2000 (the metamerism index of CIE 015:2018,
   section 9.2, with CIEDE2000 as the difference formula).

A linear non-negative least-squares fit of the tristimulus values (with the white's
rows weighted up) starts a sequential quadratic programme (SLSQP) that enforces the
chromaticity exactly. The levels are then scaled so that the brightest channel sits at
its upper limit: scaling changes neither chromaticity nor relative colorimetry.

Reported: Delta u'v' of the mix against the target, the CIE general colour-rendering
index Ra (CIE 13.3-1995) and the ANSI/IES TM-30-18 fidelity index Rf, both from
colour-science, and the mean / max CIEDE2000 of the reflectance set.

References
----------
CIE 015:2018 Colorimetry (u'v', CIELAB, metamerism index); CIE 13.3-1995 Method of
measuring and specifying colour rendering properties of light sources; ANSI/IES
TM-30-18 IES Method for Evaluating Light Source Color Rendition; Trichromatic
Reflectance Capture Using a Tunable Light Source (the paper in ``shared/reference``),
introduction and conclusion (the single-shot XYZ of the gonio-imager).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.colorimetry import CMFS_NAME, _colour, delta_e_2000
from tunespec.core.colorimetry import _quiet_colour as _quiet
from tunespec.core.errors import InputError
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "IlluminantMatch",
    "cmfs_on",
    "colour_rendering",
    "illuminant_spd",
    "lab_under",
    "match_illuminant",
    "matching_grid",
    "spd_delta_uv",
    "uv_prime",
]

#: Step of the grid the matching works on (nm).
MATCH_STEP_NM = 5.0
#: Widest range used (the CIE colorimetric range where LED data reach).
MATCH_RANGE_NM = (360.0, 780.0)
#: The range a matching grid must cover at least.
MIN_MATCH_RANGE_NM = (400.0, 700.0)
#: Delta u'v' up to which the chromaticity counts as pinned (numerically exact is
#: about 1e-13; the target's own JND is about 0.001-0.004).
PINNED_DUV = 1e-5
#: Most LED spectra a match takes (the CAL1 has 22; the optimiser's work grows with
#: the square of their number) and most reflectances whose metamerism it weighs.
MAX_MATCH_LEDS = 64
MAX_MATCH_REFLECTANCES = 2000
#: Weight of the white's rows in the linear start (relative to one reflectance).
_WHITE_WEIGHT = 30.0


def illuminant_spd(target: str | PathLike[str], column: str | None = None) -> Spectra:
    """A target SPD by CIE name (any of colour-science's) or from a spectral CSV.

    Parameters
    ----------
    target
        ``"D50"``, ``"D65"``, ``"A"``, ``"FL11"``, ``"LED-B3"``... (case-insensitive,
        ``colour.SDS_ILLUMINANTS``), or the path of a spectral CSV.
    column
        The CSV column to use; required when the CSV holds several spectra.

    Returns
    -------
    Spectra
        One spectrum, named after the illuminant or the column.

    Raises
    ------
    InputError
        Neither a known name nor a readable spectral CSV (naming both), or a CSV with
        several columns and no ``column``.
    """
    text = str(target)
    colour = _colour()
    by_lower = {k.lower(): k for k in colour.SDS_ILLUMINANTS}
    if text.lower() in by_lower and not Path(text).is_file():
        name = by_lower[text.lower()]
        sd = colour.SDS_ILLUMINANTS[name]
        return Spectra(
            np.asarray(sd.wavelengths, dtype=np.float64),
            np.asarray(sd.values, dtype=np.float64)[None, :],
            (name.replace(" ", "_"),),
            {"source": f"colour-science SDS_ILLUMINANTS[{name!r}]"},
        )
    path = Path(text)
    if not path.is_file():
        known = ", ".join(list(colour.SDS_ILLUMINANTS)[:12])
        raise InputError(
            f"target {text!r} is neither a CIE illuminant colour-science knows "
            f"(e.g. {known}, ...) nor a spectral CSV file"
        )
    spectra = read_spectra_csv(path)
    if column is None:
        if len(spectra) != 1:
            raise InputError(
                f"{len(spectra)} spectra in the target file; name one with "
                f"--target-column ({', '.join(spectra.names[:8])})",
                path=path,
            )
        return spectra
    return spectra.select([column], source=str(path))


def matching_grid(*spectra: Spectra, step_nm: float = MATCH_STEP_NM) -> Grid:
    """The common grid of ``spectra`` inside 360-780 nm at ``step_nm``.

    Raises
    ------
    InputError
        If the common range does not cover 400-700 nm.
    """
    lo = max([MATCH_RANGE_NM[0]] + [float(s.wavelength_nm[0]) for s in spectra])
    hi = min([MATCH_RANGE_NM[1]] + [float(s.wavelength_nm[-1]) for s in spectra])
    start = math.ceil(lo / step_nm - 1e-9) * step_nm
    end = math.floor(hi / step_nm + 1e-9) * step_nm
    if start > MIN_MATCH_RANGE_NM[0] or end < MIN_MATCH_RANGE_NM[1]:
        raise InputError(
            f"the spectra cover only {lo:g}-{hi:g} nm together; matching an "
            f"illuminant needs {MIN_MATCH_RANGE_NM[0]:g}-{MIN_MATCH_RANGE_NM[1]:g} nm"
        )
    return Grid(start, end, step_nm)


def cmfs_on(wavelength_nm: ArrayLike) -> NDArray[np.float64]:
    """The CIE 1931 2° colour-matching functions on ``wavelength_nm``, (n_wl, 3)."""
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    cmfs = _colour().MSDS_CMFS[CMFS_NAME]
    src = np.asarray(cmfs.wavelengths, dtype=np.float64)
    vals = np.asarray(cmfs.values, dtype=np.float64)
    return np.stack([np.interp(wl, src, vals[:, c], 0.0, 0.0) for c in range(3)], 1)


def uv_prime(XYZ: ArrayLike) -> NDArray[np.float64]:
    """CIE 1976 u', v' of tristimulus values ``(..., 3)`` (CIE 015:2018, eq. 8.10)."""
    X, Y, Z = np.moveaxis(np.asarray(XYZ, dtype=np.float64), -1, 0)
    d = X + 15.0 * Y + 3.0 * Z
    return np.stack([4.0 * X / d, 9.0 * Y / d], -1)


def _lab(XYZ: NDArray[np.float64], white: NDArray[np.float64]) -> NDArray[np.float64]:
    """CIELAB of ``XYZ`` relative to ``white`` (CIE 015:2018, eq. 8.7-8.9)."""
    t = XYZ / white
    d = 6.0 / 29.0
    f = np.where(t > d**3, np.cbrt(t), t / (3 * d * d) + 4.0 / 29.0)
    return np.stack(
        [
            116 * f[..., 1] - 16,
            500 * (f[..., 0] - f[..., 1]),
            200 * (f[..., 1] - f[..., 2]),
        ],
        -1,
    )


def lab_under(
    reflectance: ArrayLike, spd: ArrayLike, cmfs: NDArray[np.float64]
) -> NDArray[np.float64]:
    """CIELAB of reflectances ``(n, n_wl)`` under ``spd`` (its own white as reference).

    Tristimulus values are sums over the common grid (the step cancels in Lab).
    """
    R = np.asarray(reflectance, dtype=np.float64)
    E = np.asarray(spd, dtype=np.float64)
    white = E @ cmfs
    return _lab((R * E) @ cmfs, white)


@dataclass(frozen=True, eq=False)
class IlluminantMatch:
    """Result of :func:`match_illuminant`.

    Parameters
    ----------
    levels : (n_led,)
        Drive levels, in ``[0, max_level]`` per channel.
    channels : names of the LEDs, in the order of ``levels``.
    mix : Spectra
        The predicted SPD ``levels @ leds`` on the LED data's own wavelengths.
    target : Spectra
        The target on the matching grid, scaled to the mix's luminance.
    delta_uv : float
        Euclidean distance in CIE 1976 u'v' between mix and target.
    cri_ra, tm30_rf : float
        CIE 13.3 general colour-rendering index; ANSI/IES TM-30-18 fidelity index.
    mean_de00, max_de00 : float
        CIEDE2000 of the reflectance set under the mix vs under the target.
    n_reflectances : int
    pinned : bool
        Whether the chromaticity was reached (Delta u'v' <= :data:`PINNED_DUV`);
        False when the target lies outside the LEDs' gamut (the best linear fit
        is returned then).
    """

    levels: NDArray[np.float64]
    channels: tuple[str, ...]
    mix: Spectra
    target: Spectra
    delta_uv: float
    cri_ra: float
    tm30_rf: float
    mean_de00: float
    max_de00: float
    n_reflectances: int
    pinned: bool

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: levels per channel and the metrics."""
        return {
            "target": self.target.names[0],
            "channels": list(self.channels),
            "levels": [float(v) for v in self.levels],
            "metrics": {
                "delta_uv": self.delta_uv,
                "cri_ra": self.cri_ra,
                "tm30_rf": self.tm30_rf,
                "mean_de00": self.mean_de00,
                "max_de00": self.max_de00,
                "n_reflectances": self.n_reflectances,
                "chromaticity_pinned": self.pinned,
            },
        }


def _upper_bounds(max_level: float | ArrayLike, n: int) -> NDArray[np.float64]:
    ub = np.broadcast_to(np.asarray(max_level, dtype=np.float64), (n,)).copy()
    if not np.all(np.isfinite(ub)) or np.any(ub <= 0) or np.any(ub > 1):
        raise InputError("max_level must be in (0, 1] for every channel")
    return ub


def _linear_start(
    A: NDArray[np.float64],
    Aw: NDArray[np.float64],
    B: NDArray[np.float64],
    Bw: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Non-negative least squares of the reflectances' and the white's XYZ."""
    from scipy.optimize import lsq_linear

    M = np.concatenate(
        [A.transpose(0, 2, 1).reshape(-1, A.shape[1]), _WHITE_WEIGHT * Aw.T]
    )
    b = np.concatenate([B.ravel(), _WHITE_WEIGHT * Bw])
    col = np.linalg.norm(M, axis=0)
    col[col == 0] = 1.0
    sol = lsq_linear(M / col, b, bounds=(0.0, np.inf), method="bvls")
    return sol.x / col


def _optimise(
    L: NDArray[np.float64],
    T: NDArray[np.float64],
    R: NDArray[np.float64],
    cmfs: NDArray[np.float64],
    fixed: NDArray[np.bool_] | None = None,
) -> NDArray[np.float64]:
    """Weights (luminance of the white = 1) minimising the metamerism, u'v' pinned."""
    from scipy.optimize import minimize

    A = np.einsum("kl,jl,lc->kjc", R, L, cmfs)  # (n_r, n_led, 3)
    Aw = L @ cmfs  # (n_led, 3)
    Bw = T @ cmfs
    T = T / Bw[1]
    B, Bw = (R * T) @ cmfs, Bw / Bw[1]
    lab_t = _lab(B, Bw)
    uv_t = uv_prime(Bw)
    x0 = _linear_start(A, Aw, B, Bw)
    x0 = x0 / max(float((x0 @ Aw)[1]), 1e-12)

    def objective(x: NDArray[np.float64]) -> float:
        white = x @ Aw
        return float(
            np.mean(delta_e_2000(_lab(np.einsum("j,kjc->kc", x, A), white), lab_t) ** 2)
        )

    cons = [
        {"type": "eq", "fun": lambda x: 1e3 * (uv_prime(x @ Aw) - uv_t)},
        {"type": "eq", "fun": lambda x: (x @ Aw)[1] - 1.0},
    ]
    scale = max(float(x0.max()), 1e-12)
    bounds = [
        (0.0, 0.0) if fixed is not None and fixed[j] else (0.0, 10 * scale)
        for j in range(len(x0))
    ]
    res = minimize(
        lambda z: objective(z * scale),
        x0 / scale,
        method="SLSQP",
        bounds=[(lo / scale, hi / scale) for lo, hi in bounds],
        constraints=[
            {"type": c["type"], "fun": (lambda z, f=c["fun"]: f(z * scale))}
            for c in cons
        ],
        options={"maxiter": 300, "ftol": 1e-10},
    )
    x = np.clip(res.x * scale, 0.0, None)
    if np.max(np.abs(uv_prime(x @ Aw) - uv_t)) > 1e-5:  # SLSQP gave up: keep the start
        x = x0
    return x


def match_illuminant(
    leds: Spectra,
    target: Spectra,
    reflectances: Spectra,
    *,
    max_level: float | ArrayLike = 1.0,
) -> IlluminantMatch:
    """Drive levels of ``leds`` that simulate ``target`` for ``reflectances``.

    Parameters
    ----------
    leds : Spectra, (n_led, n_wl)
        Each LED's spectral power at level 1 (a measured or modelled set, e.g. the
        shipped CAL1 model or ``process --illuminants-out``); levels act linearly.
    target : Spectra, one spectrum
        The illuminant to simulate (:func:`illuminant_spd`); its scale is free.
    reflectances : Spectra
        The set whose metamerism is minimised (default in the CLI: the ColorChecker
        SG). Resampled to the matching grid.
    max_level
        Upper limit per channel (scalar or (n_led,)), in (0, 1].

    Returns
    -------
    IlluminantMatch

    Raises
    ------
    InputError
        Several target spectra, too short a common range, LEDs that are all dark, or
        bad limits.

    References
    ----------
    CIE 015:2018 (u'v', CIELAB, metamerism index); CIE 13.3-1995 (Ra);
    ANSI/IES TM-30-18 (Rf).
    """
    if len(target) != 1:
        raise InputError(f"expected one target spectrum, got {len(target)}")
    if len(leds) > MAX_MATCH_LEDS:
        raise InputError(
            f"{len(leds)} LED spectra, at most {MAX_MATCH_LEDS}: one column per "
            "channel of the light source (--illuminants)"
        )
    if len(reflectances) > MAX_MATCH_REFLECTANCES:
        raise InputError(
            f"{len(reflectances)} reflectances, at most {MAX_MATCH_REFLECTANCES} "
            "(--reflectances)"
        )
    ub = _upper_bounds(max_level, len(leds))
    grid = matching_grid(leds, target, reflectances)
    L = leds.resample(grid, average=True).values
    T = target.resample(grid).values[0]
    R = reflectances.resample(grid).values
    if not np.any(L.sum(axis=1) > 0) or not T.sum() > 0:
        raise InputError("the LED spectra or the target are all zero")
    cmfs = cmfs_on(grid.wavelength_nm)
    x = _optimise(L, T, R, cmfs, fixed=L.sum(axis=1) <= 0)
    on = x > 0
    levels = np.zeros_like(x)
    if on.any():
        levels = x * float(np.min(ub[on] / x[on]))
    levels = np.clip(levels, 0.0, ub)
    mix_native = Spectra(leds.wavelength_nm, levels @ leds.values, ("mix",))
    mix_grid = levels @ L
    target_scaled = T * (mix_grid @ cmfs)[1] / (T @ cmfs)[1]
    de = delta_e_2000(lab_under(R, mix_grid, cmfs), lab_under(R, target_scaled, cmfs))
    ra, rf = colour_rendering(mix_native)
    duv = float(np.hypot(*(uv_prime(mix_grid @ cmfs) - uv_prime(target_scaled @ cmfs))))
    return IlluminantMatch(
        levels=levels,
        channels=leds.names,
        mix=mix_native,
        target=Spectra(grid.wavelength_nm, target_scaled, target.names),
        delta_uv=duv,
        cri_ra=ra,
        tm30_rf=rf,
        mean_de00=float(de.mean()),
        max_de00=float(de.max()),
        n_reflectances=len(reflectances),
        pinned=duv <= PINNED_DUV,
    )


def spd_delta_uv(spd: Spectra, target: Spectra) -> float:
    """Delta u'v' (CIE 1931 2°) between the first spectra of ``spd`` and ``target``.

    Both are integrated on their common matching grid (:func:`matching_grid`).
    """
    grid = matching_grid(spd, target)
    cmfs = cmfs_on(grid.wavelength_nm)
    a = spd.resample(grid, average=True).values[0] @ cmfs
    b = target.resample(grid).values[0] @ cmfs
    return float(np.hypot(*(uv_prime(a) - uv_prime(b))))


def colour_rendering(spd: Spectra) -> tuple[float, float]:
    """CIE 13.3 Ra and ANSI/IES TM-30-18 Rf of one SPD, by colour-science.

    The SPD is handed over on its own wavelengths; colour-science aligns it to the
    test samples' range (the ends held, as its default extrapolator does).
    """
    colour = _colour()
    wl = spd.wavelength_nm
    step = np.diff(wl)
    if not (
        step.size
        and np.allclose(step, step[0], rtol=0.0, atol=1e-6)
        and 1.0 <= step[0] <= 5.0
        and abs(step[0] - round(step[0])) < 1e-6
    ):
        # colour-science needs a regular grid of whole nm, at most 5 nm for TM-30:
        # a line missing from a file, a grid finer than 1 nm or coarser than 5 nm
        # is resampled to 1 nm first
        grid = Grid(float(math.ceil(wl[0])), float(math.floor(wl[-1])), 1.0)
        spd = spd.resample(grid, average=True)
    sd = colour.SpectralDistribution(spd.values[0], spd.wavelength_nm)
    with _quiet(), colour.utilities.domain_range_scale("reference"):
        ra = float(colour.colour_rendering_index(sd))
        rf = float(colour.colour_fidelity_index(sd, method="ANSI/IES TM-30-18"))
    return ra, rf
