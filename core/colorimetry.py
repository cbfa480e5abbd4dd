"""Colorimetry of reflectances under CIE D50 and the statistics of Table 2.

Tristimulus values follow the ICC / ArgyllCMS convention (ArgyllCMS ``spec2cie``):

1. XYZ of the reflectance under the CIE D50 spectral power distribution with the CIE
   1931 2° observer by practice ASTM E308 (colour-science's
   ``sd_to_XYZ(method="ASTM E308")``), normalised so that the perfect reflector has
   Y = 100. As ArgyllCMS does, 1, 10 and 20 nm data are integrated on their own grid
   (10 and 20 nm with the E308 weighting tables); any other grid, 5 nm included, is
   interpolated linearly to 1 nm first (:func:`astm_e308_weights_d50`);
2. CIELAB relative to the ICC PCS white D50 = (96.42, 100, 82.49) (ICC.1:2010, 6.3.4.3)
   rather than to the XYZ of the spectral D50 or to colour-science's default D50
   chromaticity (0.3457, 0.3585). The three whites differ by up to about 0.03 CIEDE2000,
   so a perfect reflector has L* = 100 but a slightly non-zero a*, b*.

For speed the ASTM E308 computation, which is linear in the reflectance, is reduced
once per wavelength grid to a weighting table ``W`` (n_wl, 3) by applying colour's
``sd_to_XYZ`` to unit impulses; ``XYZ = R @ W`` then equals colour's result for every
spectrum (to rounding, 1e-13) and is vectorised over patches.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Table 2; ASTM E308-15, Standard Practice for Computing the
Colors of Objects by Using the CIE System; ICC.1:2010 (profile version 4.3.0.0);
G. Sharma, W. Wu, E. N. Dalal, "The CIEDE2000 color-difference formula: Implementation
notes, supplementary test data, and mathematical observations", Color Research and
Application 30(1), 21-30 (2005), doi:10.1002/col.20070.
"""

from __future__ import annotations

import math
import sys
import threading
import types
import warnings
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError, check_names
from tunespec.core.spectra import Spectra

__all__ = [
    "ARGYLL_TABLE_STEPS_NM",
    "CMFS_NAME",
    "ICC_D50_XY",
    "ICC_D50_XYZ",
    "MIN_RANGE_NM",
    "ReflectanceStats",
    "astm_e308_weights_d50",
    "delta_e_2000",
    "lab_d50",
    "reflectance_stats",
    "spectral_rms",
    "xyz_d50",
    "xyz_to_lab_d50",
]

#: The ICC profile connection space white, D50, scaled to Y = 100 (ICC.1:2010).
ICC_D50_XYZ = np.array([96.42, 100.0, 82.49])
ICC_D50_XYZ.flags.writeable = False
#: Its chromaticity (= colour's ``CCS_ILLUMINANTS[CMFS_NAME]["ICC D50"]``).
ICC_D50_XY = ICC_D50_XYZ[:2] / ICC_D50_XYZ.sum()
ICC_D50_XY.flags.writeable = False
#: The observer.
CMFS_NAME = "CIE 1931 2 Degree Standard Observer"
#: Grid steps integrated with colour's ASTM E308 path as they are (as ArgyllCMS does);
#: other grids, 5 nm included, are interpolated linearly to 1 nm first.
ARGYLL_TABLE_STEPS_NM = (1.0, 10.0, 20.0)
#: The range a spectrum must cover; ASTM E308 extends shorter data to 360-780 nm by
#: repeating the end values, which is only harmless for the tails.
MIN_RANGE_NM = (400.0, 700.0)

_WL_TOL_NM = 1e-6
#: One import of colour at a time (:func:`_colour` stands a module in for a while).
_COLOUR_LOCK = threading.Lock()


def _colour() -> Any:
    """colour-science, imported on first use.

    ``import colour`` also imports ``colour.plotting`` and with it matplotlib's
    pyplot (about 0.7 s), which nothing that only parses arguments, reads files or
    reports an error should pay (``tunespec --help``). Nothing that calls this
    plots with colour: while colour is imported here, an empty module stands in for
    ``colour.plotting`` (colour 0.4's ``__init__`` imports it, and a lazy module
    would be loaded by the import system's own look-ups), taken out again
    afterwards so that ``import colour.plotting`` still gives the real one
    (``import colour`` 1.95-2.02 -> 1.39-1.57 s on a loaded machine; the images'
    warm-up, imports holding the GIL beside the LEDs' stage, 2.30 -> 1.63 s).
    colour-science 0.4 also sets numpy's legacy="1.13" print options
    when it is imported, which would change how every array in the process prints
    (reports, doctests); ``np.printoptions()`` restores the caller's options on
    leaving the block.
    """
    with _COLOUR_LOCK, np.printoptions():
        if "colour" in sys.modules:
            import colour

            return colour
        stub = types.ModuleType("colour.plotting")
        sys.modules.setdefault("colour.plotting", stub)
        try:
            import colour
        finally:
            if sys.modules.get("colour.plotting") is stub:
                del sys.modules["colour.plotting"]
        module = getattr(colour, "_module", colour)  # 0.4 wraps it in a ModuleAPI
        if vars(module).get("plotting") is stub:
            del module.plotting
    return colour


def astm_e308_weights_d50(wavelength_nm: ArrayLike) -> NDArray[np.float64]:
    """ASTM E308 weighting table for CIE D50 and the 1931 2° observer on a grid.

    Parameters
    ----------
    wavelength_nm : (n_wl,)
        Strictly increasing sample wavelengths covering at least 400-700 nm.

    Returns
    -------
    (n_wl, 3), read-only
        ``W`` such that ``XYZ = reflectance @ W`` (XYZ in 0..100, perfect reflector
        Y = 100).

    Notes
    -----
    As ArgyllCMS does: uniform 1, 10 and 20 nm grids use colour's
    ``sd_to_XYZ(method="ASTM E308")`` unchanged (10 and 20 nm: the ASTM E308
    weighting tables; values outside the grid repeat the end values); any other grid,
    5 nm included, is interpolated linearly (as :meth:`Spectra.resample`) onto the
    whole nanometres inside its range and integrated at 1 nm, which is exact for the
    piecewise-linear spectrum. Summing 5 nm samples directly (colour's 5 nm path)
    would differ from Argyll by up to 0.05 dE00. The table is cached per grid.

    Raises
    ------
    InputError
        Too short a range or wavelengths not strictly increasing.

    References
    ----------
    ASTM E308-15, Standard Practice for Computing the Colors of Objects by Using the
    CIE System (weighting tables on the measurement grid); CIE 015:2018 Colorimetry (1931 2°
    observer, illuminant D50).

    Examples
    --------
    >>> W = astm_e308_weights_d50(range(380, 731, 5))
    >>> W.shape, round(float(W[:, 1].sum()), 10)
    ((71, 3), 100.0)
    """
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    if wl.ndim != 1 or wl.size < 2 or np.any(np.diff(wl) <= 0):
        raise InputError("wavelengths must be a strictly increasing 1-D sequence")
    if wl[0] > MIN_RANGE_NM[0] + _WL_TOL_NM or wl[-1] < MIN_RANGE_NM[1] - _WL_TOL_NM:
        raise InputError(
            f"wavelength range {wl[0]:g}-{wl[-1]:g} nm is too short for colorimetry: "
            f"it must cover {MIN_RANGE_NM[0]:g}-{MIN_RANGE_NM[1]:g} nm"
        )
    key = tuple(round(float(w), 6) for w in wl)
    return _weights_cached(key)


@lru_cache(maxsize=16)
def _weights_cached(key: tuple[float, ...]) -> NDArray[np.float64]:
    wl = np.array(key)
    d = np.diff(wl)
    step = float(d[0])
    if np.ptp(d) <= _WL_TOL_NM and any(
        abs(step - s) <= _WL_TOL_NM for s in ARGYLL_TABLE_STEPS_NM
    ):
        step = float(round(step))
        W = _probe_colour(wl[0] + step * np.arange(wl.size))
    else:
        # ArgyllCMS (spec2cie, colverify) uses ASTM E308 tables only for 10 and 20 nm
        # data and integrates anything else (5 nm included) linearly interpolated at
        # 1 nm; colour's 5 nm path sums the 5 nm samples directly, which differs from
        # Argyll by up to 0.05 dE00 on the SG (measured). Do as Argyll does.
        wl_1nm = np.arange(
            math.ceil(wl[0] - _WL_TOL_NM), math.floor(wl[-1] + _WL_TOL_NM) + 1.0
        )
        W = _linear_interpolation_matrix(wl, wl_1nm).T @ _probe_colour(wl_1nm)
    W.flags.writeable = False
    return W


def _linear_interpolation_matrix(
    wl: NDArray[np.float64], at: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``P`` (n_at, n_wl) with ``P @ r == np.interp(at, wl, r)`` for ``at`` in range.

    Built from the two neighbours of each point (not by interpolating the n_wl unit
    vectors, which costs O(n_wl^2) memory on a fine grid). ``XYZ = (P r) @ W1 =
    r @ (P^T W1)``.
    """
    j = np.clip(np.searchsorted(wl, at, side="right") - 1, 0, wl.size - 2)
    t = np.clip((at - wl[j]) / (wl[j + 1] - wl[j]), 0.0, 1.0)
    P = np.zeros((at.size, wl.size))
    rows = np.arange(at.size)
    P[rows, j] = 1.0 - t
    P[rows, j + 1] += t
    return P


def _probe_colour(wl: NDArray[np.float64]) -> NDArray[np.float64]:
    """colour's ASTM E308 XYZ of each unit impulse on ``wl``: the weighting table."""
    colour = _colour()
    cmfs = colour.MSDS_CMFS[CMFS_NAME]
    d50 = colour.SDS_ILLUMINANTS["D50"]
    W = np.empty((wl.size, 3))
    # colour warns as it aligns the illuminant and the data to the observer's shape
    # (intended here); catch_warnings restores the caller's filters afterwards, which
    # colour.utilities.suppress_warnings (0.4.7) does not.
    with _quiet_colour(), colour.utilities.domain_range_scale("reference"):
        for j, impulse in enumerate(np.eye(wl.size)):
            sd = colour.SpectralDistribution(impulse, wl)
            W[j] = colour.sd_to_XYZ(sd, cmfs, d50, method="ASTM E308")
    return W


class _quiet_colour(warnings.catch_warnings):
    """Ignore colour-science's own warnings inside the block (and only those)."""

    def __enter__(self) -> Any:
        out = super().__enter__()
        u = _colour().utilities
        for category in (u.ColourWarning, u.ColourRuntimeWarning, u.ColourUsageWarning):
            warnings.simplefilter("ignore", category)
        return out


def _values_and_wavelengths(
    reflectance: Spectra | ArrayLike, wavelength_nm: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    if isinstance(reflectance, Spectra):
        return reflectance.values, reflectance.wavelength_nm
    if wavelength_nm is None:
        raise InputError("an array of reflectances needs its wavelength_nm")
    values = np.asarray(reflectance, dtype=np.float64)
    wl = np.asarray(wavelength_nm, dtype=np.float64)
    if values.ndim < 1 or wl.ndim != 1 or values.shape[-1] != wl.size:
        raise InputError(
            f"reflectance shape {values.shape} does not end in the {wl.size} "
            "wavelengths given"
        )
    return values, wl


def xyz_d50(
    reflectance: Spectra | ArrayLike, wavelength_nm: ArrayLike | None = None
) -> NDArray[np.float64]:
    """CIE XYZ under CIE D50, 1931 2° observer, ASTM E308 as ArgyllCMS applies it.

    1, 10 and 20 nm data are integrated on their own grid; other grids (5 nm
    included) are interpolated linearly to 1 nm first, see
    :func:`astm_e308_weights_d50`.

    Parameters
    ----------
    reflectance : Spectra or (..., n_wl) array
        Reflectance factors (1 = perfect reflector).
    wavelength_nm : (n_wl,), optional
        Wavelengths of an array ``reflectance``; ignored for :class:`Spectra`.

    Returns
    -------
    (..., 3)
        XYZ in 0..100 (perfect reflector Y = 100); NaN in a spectrum gives NaN.

    Raises
    ------
    InputError
        Missing wavelengths, mismatched shapes or a range not covering 400-700 nm.

    References
    ----------
    ASTM E308-15; colour-science ``sd_to_XYZ(..., method="ASTM E308")``.

    Examples
    --------
    >>> import numpy as np
    >>> xyz_d50(np.ones(71), np.arange(380.0, 731.0, 5.0)).round(3).tolist()
    [96.424, 100.0, 82.513]
    """
    values, wl = _values_and_wavelengths(reflectance, wavelength_nm)
    return values @ astm_e308_weights_d50(wl)


def xyz_to_lab_d50(XYZ: ArrayLike) -> NDArray[np.float64]:
    """CIELAB of XYZ (0..100) relative to the ICC D50 white (96.42, 100, 82.49).

    Parameters
    ----------
    XYZ : (..., 3)
        Tristimulus values in 0..100.

    Returns
    -------
    (..., 3)
        L*, a*, b*.

    References
    ----------
    CIE 015:2018 Colorimetry (the CIE 1976 L*a*b* equations); ICC.1:2010 (the D50
    PCS white 0.9642, 1, 0.8249).

    Examples
    --------
    >>> (xyz_to_lab_d50([96.42, 100.0, 82.49]).round(12) + 0.0).tolist()
    [100.0, 0.0, 0.0]
    """
    XYZ = np.asarray(XYZ, dtype=np.float64)
    colour = _colour()
    with colour.utilities.domain_range_scale("reference"):
        return np.asarray(colour.XYZ_to_Lab(XYZ / 100.0, ICC_D50_XY), dtype=np.float64)


def lab_d50(
    reflectance: Spectra | ArrayLike, wavelength_nm: ArrayLike | None = None
) -> NDArray[np.float64]:
    """CIELAB (ICC D50 white) of reflectances, ``xyz_to_lab_d50(xyz_d50(...))``.

    Parameters
    ----------
    reflectance : Spectra or (..., n_wl) array
    wavelength_nm : (n_wl,), optional

    Returns
    -------
    (..., 3)
        L*, a*, b*.

    References
    ----------
    ASTM E308-15 (tristimulus integration); CIE 015:2018 (CIE 1976 L*a*b*);
    ICC.1:2010 (D50 white).

    Examples
    --------
    >>> import numpy as np
    >>> lab_d50(np.ones(71), np.arange(380.0, 731.0, 5.0)).round(3).tolist()
    [100.0, 0.007, -0.019]
    """
    return xyz_to_lab_d50(xyz_d50(reflectance, wavelength_nm))


def delta_e_2000(lab1: ArrayLike, lab2: ArrayLike) -> NDArray[np.float64]:
    """CIEDE2000 colour difference (kL = kC = kH = 1), broadcasting.

    Parameters
    ----------
    lab1, lab2 : (..., 3)
        CIELAB values (L* in 0..100).

    Returns
    -------
    (...)
        Delta E 2000.

    References
    ----------
    Sharma, Wu and Dalal (2005); colour-science ``delta_E(method="CIE 2000")``.

    Examples
    --------
    >>> round(float(delta_e_2000([50, 2.6772, -79.7751], [50, 0, -82.7485])), 4)
    2.0425
    """
    a = np.asarray(lab1, dtype=np.float64)
    b = np.asarray(lab2, dtype=np.float64)
    colour = _colour()
    with colour.utilities.domain_range_scale("reference"):
        return np.asarray(colour.difference.delta_E_CIE2000(a, b), dtype=np.float64)


def spectral_rms(
    estimated: Spectra | ArrayLike, reference: Spectra | ArrayLike
) -> NDArray[np.float64]:
    """Root-mean-square difference over wavelengths, per spectrum (Table 2).

    Parameters
    ----------
    estimated, reference : Spectra or (..., n_wl)
        Same shape (the same names, order and grid for :class:`Spectra`; use
        :func:`reflectance_stats` to match by name and resample).

    Returns
    -------
    (...)
        ``sqrt(mean((estimated - reference)**2, axis=-1))``.

    References
    ----------
    Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
    ``shared/reference``), Table 2 (spectral RMS error
    ``sqrt(mean_lambda (r_hat - r)^2)``).

    Examples
    --------
    >>> spectral_rms([[0.5, 0.5], [0.1, 0.3]], [[0.5, 0.5], [0.0, 0.4]]).round(12).tolist()
    [0.0, 0.1]
    """
    a = estimated.values if isinstance(estimated, Spectra) else estimated
    b = reference.values if isinstance(reference, Spectra) else reference
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim < 1:
        raise InputError(f"spectral_rms: shapes {a.shape} and {b.shape} differ")
    return np.sqrt(np.mean((a - b) ** 2, axis=-1))


@dataclass(frozen=True, eq=False)
class ReflectanceStats:
    """Spectral and colorimetric deviations per patch, the paper's Table 2.

    Parameters
    ----------
    names : n patch names
    delta_e00 : (n,)
        CIEDE2000 between estimated and reference under D50 (ICC white).
    spectral_rms : (n,)
        RMS reflectance difference over the estimated grid.
    lab_estimated, lab_reference : (n, 3)
        The CIELAB values compared.
    """

    names: tuple[str, ...]
    delta_e00: NDArray[np.float64]
    spectral_rms: NDArray[np.float64]
    lab_estimated: NDArray[np.float64]
    lab_reference: NDArray[np.float64]

    @property
    def mean_delta_e00(self) -> float:
        """Average CIEDE2000 (Table 2's "average")."""
        return float(np.mean(self.delta_e00))

    @property
    def max_delta_e00(self) -> float:
        """Largest CIEDE2000."""
        return float(np.max(self.delta_e00))

    @property
    def mean_spectral_rms(self) -> float:
        """Average spectral RMS."""
        return float(np.mean(self.spectral_rms))

    @property
    def max_spectral_rms(self) -> float:
        """Largest spectral RMS."""
        return float(np.max(self.spectral_rms))

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python summary (JSON-ready).

        Returns
        -------
        dict
            ``{"patches": {name: {"delta_e00", "spectral_rms"}}, "average": {...},
            "max": {...}, "n": n}``.
        """
        return {
            "patches": {
                n: {"delta_e00": float(d), "spectral_rms": float(r)}
                for n, d, r in zip(
                    self.names, self.delta_e00, self.spectral_rms, strict=True
                )
            },
            "average": {
                "delta_e00": self.mean_delta_e00,
                "spectral_rms": self.mean_spectral_rms,
            },
            "max": {
                "delta_e00": self.max_delta_e00,
                "spectral_rms": self.max_spectral_rms,
            },
            "n": len(self.names),
        }

    def format_table(self, *, max_rows: int | None = None) -> str:
        """Table 2 as text: one row per patch, then average and max.

        Parameters
        ----------
        max_rows
            Show at most this many patch rows (the summary rows always follow).
        """
        width = max(7, *(len(n) for n in self.names))
        lines = [f"{'patch':<{width}}  {'CIEDE2000 [D50]':>15}  {'Spectral RMS':>12}"]
        rows = list(zip(self.names, self.delta_e00, self.spectral_rms, strict=True))
        shown = rows if max_rows is None else rows[:max_rows]
        lines += [f"{n:<{width}}  {d:>15.2f}  {r:>12.4f}" for n, d, r in shown]
        if len(shown) < len(rows):
            lines.append(f"... ({len(rows) - len(shown)} more)")
        lines.append(
            f"{'average':<{width}}  {self.mean_delta_e00:>15.2f}  "
            f"{self.mean_spectral_rms:>12.4f}"
        )
        lines.append(
            f"{'max':<{width}}  {self.max_delta_e00:>15.2f}  "
            f"{self.max_spectral_rms:>12.4f}"
        )
        return "\n".join(lines)


def reflectance_stats(estimated: Spectra, reference: Spectra) -> ReflectanceStats:
    """Compare estimated with reference reflectances patch by patch (Table 2).

    Patches are matched by name; the reference is resampled (linearly) onto the
    estimated grid. CIEDE2000 uses :func:`lab_d50` on that grid.

    Parameters
    ----------
    estimated : Spectra, (n, n_wl)
        Estimated reflectances on an equidistant grid covering 400-700 nm.
    reference : Spectra, (>= n, n_wl')
        Reference measurements containing every estimated name, covering the
        estimated grid.

    Returns
    -------
    ReflectanceStats

    Raises
    ------
    InputError
        Names missing from the reference (listed), no patches, non-finite values,
        a reference that does not cover the estimated grid.

    References
    ----------
    The paper in ``shared/reference``, Table 2 and its text.

    Examples
    --------
    >>> import numpy as np
    >>> wl = np.arange(400.0, 701.0, 10.0)
    >>> est = Spectra(wl, np.full((1, 31), 0.5), ("W",))
    >>> ref = Spectra(wl, np.full((1, 31), 0.5), ("W",))
    >>> reflectance_stats(est, ref).as_dict()["average"]
    {'delta_e00': 0.0, 'spectral_rms': 0.0}
    """
    src_e = estimated.meta.get("source")
    src_r = reference.meta.get("source")
    if len(estimated) == 0:
        raise InputError("estimated reflectances: no patches", path=src_e)
    check_names(
        estimated.names,
        reference.names,
        "reference reflectances: {n} estimated patch(es) missing: {names}",
        path=src_r,
        limit=20,
    )
    wl = estimated.wavelength_nm
    grid = estimated.grid
    ref = reference.select(estimated.names, source=src_r).resample(grid, source=src_r)
    for spectra, src, role in (
        (estimated, src_e, "estimated"),
        (ref, src_r, "reference"),
    ):
        bad = ~np.isfinite(spectra.values).all(axis=1)
        if np.any(bad):
            names = ", ".join(spectra.names[i] for i in np.flatnonzero(bad)[:8])
            raise InputError(
                f"{role} reflectances: non-finite values in {names}", path=src
            )
    lab_e = lab_d50(estimated.values, wl)
    lab_r = lab_d50(ref.values, wl)
    return ReflectanceStats(
        names=estimated.names,
        delta_e00=delta_e_2000(lab_e, lab_r),
        spectral_rms=spectral_rms(estimated.values, ref.values),
        lab_estimated=lab_e,
        lab_reference=lab_r,
    )
