"""Spectral data: a wavelength grid and named spectra on it.

The files are read and written in :mod:`tunespec.core.io.spectral` (CSV, CGATS,
rawtoaces JSON, found from the content: ``read_spectral``, ``read_spectra_csv``) and
:mod:`tunespec.core.io.spectral_csv` (``write_spectra_csv``); this module imports no
reader, so the data classes stand below the formats.

Every input is resampled onto one working :class:`Grid` before any computation, so
reflectances, illuminants and sensitivities always share their wavelength axis.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError, check_names
from tunespec.core.limits import shown

__all__ = [
    "CALIBRATION_GRID",
    "CALIBRATION_MAX_STEP_NM",
    "DEFAULT_GRID",
    "MAX_GRID_SAMPLES",
    "Grid",
    "Spectra",
    "grid_from_data",
    "resampling_matrix",
    "spline_matrix",
]

_WL_TOL_NM = 1e-6
#: Most samples a :class:`Grid` may have (0.1 nm over 1000 nm). The estimators hold
#: n_wl x n_wl matrices, so a mistyped step (``400:700:1e-9``) must be refused here
#: rather than exhaust the memory later.
MAX_GRID_SAMPLES = 10_001


@dataclass(frozen=True)
class Grid:
    """An equidistant wavelength grid ``start_nm, start_nm + step_nm, ..., end_nm``.

    Raises
    ------
    InputError
        Non-finite values, ``END <= START``, ``STEP <= 0``, ``END - START`` not a
        multiple of ``STEP`` (to 1e-6 nm), or more than :data:`MAX_GRID_SAMPLES`.
    """

    start_nm: float
    end_nm: float
    step_nm: float

    def __post_init__(self) -> None:
        bad = f"bad grid {self.start_nm:g}:{self.end_nm:g}:{self.step_nm:g}: "
        values = (self.start_nm, self.end_nm, self.step_nm)
        if not all(math.isfinite(v) for v in values):
            raise InputError(bad + "START, END and STEP must be finite numbers")
        if not (self.step_nm > 0 and self.end_nm > self.start_nm):
            raise InputError(bad + "expected START < END and STEP > 0")
        n = (self.end_nm - self.start_nm) / self.step_nm
        if round(n) + 1 > MAX_GRID_SAMPLES:
            raise InputError(
                bad + f"{round(n) + 1} samples, at most {MAX_GRID_SAMPLES}"
            )
        # The tolerance is in nm, not in samples: a step read back from sampled
        # wavelengths (np.diff) carries rounding that grows with the sample count.
        if abs(n - round(n)) * self.step_nm > _WL_TOL_NM:
            raise InputError(bad + "END - START must be a multiple of STEP")

    @classmethod
    def parse(cls, text: str) -> Grid:
        """Parse ``"START:END:STEP"`` in nm, e.g. ``"400:700:10"``.

        Examples
        --------
        >>> Grid.parse("400:700:10").n
        31
        """
        parts = text.split(":")
        try:
            if len(parts) != 3:
                raise ValueError
            start, end, step = (float(p) for p in parts)
        except ValueError:
            raise InputError(
                f"bad grid {shown(text)}: expected START:END:STEP in nm, e.g. 400:700:10"
            ) from None
        return cls(start, end, step)

    @property
    def n(self) -> int:
        """Number of samples."""
        return round((self.end_nm - self.start_nm) / self.step_nm) + 1

    @property
    def wavelength_nm(self) -> NDArray[np.float64]:
        """The sample wavelengths, shape (n,)."""
        return self.start_nm + self.step_nm * np.arange(self.n, dtype=np.float64)

    def __str__(self) -> str:
        return f"{self.start_nm:g}:{self.end_nm:g}:{self.step_nm:g}"


#: The working grid: the ColorChecker SG reference range at 5 nm. The CAL1's shortest
#: LED reaches below 400 nm, so the grid starts at 380 nm.
DEFAULT_GRID = Grid(380.0, 730.0, 5.0)

#: The step camera sensitivities are calibrated on, at most, in nm. Chart reflectances
#: are smooth and interpolate well, but LEDs (15-25 nm FWHM) and the steep IR-cut
#: filters of phones and machine-vision cameras do not: sampled at 5-10 nm, an edge
#: inside an LED's band misplaces several per cent of its light. On the generalisation
#: benchmark 2 nm instead of 5 nm brings the median sensitivity RMS from 0.025 to
#: about 0.009 at the same colour error, for about 5x the fitting time.
CALIBRATION_MAX_STEP_NM = 2.0

#: The calibration grid of the main job and the wizard: the SG's range at 2 nm.
CALIBRATION_GRID = Grid(380.0, 730.0, CALIBRATION_MAX_STEP_NM)


@dataclass(frozen=True, eq=False)
class Spectra:
    """Named spectra on a common wavelength axis.

    Parameters
    ----------
    wavelength_nm : (n_wl,)
        Strictly increasing wavelengths in nm.
    values : (n, n_wl)
        One spectrum per row.
    names : n names
        Unique spectrum names (patch labels, LED channel names, ``R``/``G``/``B``).
    """

    wavelength_nm: NDArray[np.float64]
    values: NDArray[np.float64]
    names: tuple[str, ...]
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        wl = np.asarray(self.wavelength_nm, dtype=np.float64)
        vals = np.atleast_2d(np.asarray(self.values, dtype=np.float64))
        names = tuple(str(n) for n in self.names)
        if wl.ndim != 1 or vals.shape != (len(names), wl.size):
            raise InputError(
                f"spectra shape mismatch: {len(names)} names, {wl.size} wavelengths, "
                f"values {vals.shape}"
            )
        if not np.all(np.isfinite(wl)):
            raise InputError("wavelengths must be finite")
        if wl.size > 1 and np.any(np.diff(wl) <= 0):
            raise InputError("wavelengths must be strictly increasing")
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise InputError(f"duplicate spectrum names: {', '.join(dup)}")
        wl.flags.writeable = False
        vals.flags.writeable = False
        object.__setattr__(self, "wavelength_nm", wl)
        object.__setattr__(self, "values", vals)
        object.__setattr__(self, "names", names)

    def __len__(self) -> int:
        return len(self.names)

    def __getitem__(self, name: str) -> NDArray[np.float64]:
        try:
            return self.values[self.names.index(name)]
        except ValueError:
            raise KeyError(name) from None

    def __repr__(self) -> str:
        wl = self.wavelength_nm
        return (
            f"Spectra({len(self)} spectra, {wl[0]:g}-{wl[-1]:g} nm, {wl.size} samples)"
        )

    @property
    def step_nm(self) -> float:
        """The wavelength step in nm (the grid must be equidistant)."""
        d = np.diff(self.wavelength_nm)
        if d.size == 0 or np.ptp(d) > _WL_TOL_NM:
            raise InputError("spectra are not on an equidistant grid")
        return float(d[0])

    @property
    def grid(self) -> Grid:
        """The equidistant :class:`Grid` the spectra are sampled on."""
        wl = self.wavelength_nm
        return Grid(float(wl[0]), float(wl[-1]), self.step_nm)

    def select(self, names: Iterable[str], *, source: str | None = None) -> Spectra:
        """The spectra called ``names``, in that order.

        Raises
        ------
        InputError
            Naming ``source`` and the missing names.
        """
        names = list(names)
        check_names(names, self.names, path=source)
        idx = [self.names.index(n) for n in names]
        return Spectra(self.wavelength_nm, self.values[idx], tuple(names), self.meta)

    def resample(
        self, grid: Grid, *, source: str | None = None, average: bool = False
    ) -> Spectra:
        """Onto ``grid`` by linear interpolation (or, ``average``, band averaging).

        Linear interpolation never creates negative values or overshoot; from finer
        data it picks samples, the usual abridgement of reflectance data (ASTM
        E308). ``average=True`` is for light source spectra: from data finer than
        half the grid's step it averages with the grid's hat (linear-interpolation)
        kernels instead, so that Eq. 1's sum on the coarse grid keeps each
        spectrum's area and centroid -- a 15 nm wide LED point-sampled every 5 nm
        gains or loses several per cent of its power depending on where its peak
        falls, and its apparent position moves; from coarser data it draws a cubic
        spline through them (:func:`resampling_matrix`), an LED's shape where
        linear interpolation makes a triangle of it, and sets the spline's negative
        lobes beside a narrow peak to zero. The grid must lie inside the data's
        range.

        Raises
        ------
        InputError
            If the data do not cover the grid.
        """
        self.check_covers(grid, source=source)
        wl = self.wavelength_nm
        target = grid.wavelength_nm
        if wl.size == target.size and np.allclose(
            wl, target, rtol=0.0, atol=_WL_TOL_NM
        ):
            return Spectra(target, self.values, self.names, self.meta)
        out = self.values @ resampling_matrix(wl, target, average=average).T
        if average and np.all(self.values >= 0):
            out = np.maximum(out, 0.0)
        return Spectra(target, out, self.names, self.meta)

    def check_covers(self, grid: Grid, *, source: str | None = None) -> None:
        """Raise unless the data reach over ``grid``.

        Raises
        ------
        InputError
            Naming ``source``, the data's range and ``grid``.
        """
        wl = self.wavelength_nm
        if wl[0] > grid.start_nm + _WL_TOL_NM or wl[-1] < grid.end_nm - _WL_TOL_NM:
            raise InputError(
                f"wavelength range {wl[0]:g}-{wl[-1]:g} nm is too short for the grid "
                f"{grid} (choose a grid inside it with --grid START:END:STEP)",
                path=source,
            )

    def with_values(
        self, values: ArrayLike, names: Sequence[str] | None = None
    ) -> Spectra:
        """A copy on the same wavelengths with new values (and optionally names)."""
        return Spectra(
            self.wavelength_nm,
            np.asarray(values, dtype=np.float64),
            tuple(self.names if names is None else names),
            self.meta,
        )


#: The coarsest step :func:`grid_from_data` chooses, in nm.
MAX_DATA_GRID_STEP_NM = 10.0


def grid_from_data(
    spectra: Sequence[Spectra],
    *,
    sets_step: Sequence[bool] | None = None,
    max_step_nm: float = MAX_DATA_GRID_STEP_NM,
) -> Grid:
    """The working grid the inputs support: the widest range every input covers.

    The step is the finest step of the inputs whose ``sets_step`` is true (by
    default all), at most ``max_step_nm``. Light-source spectra are band-averaged onto
    any grid (:meth:`Spectra.resample`), keeping their area and centroid, so callers
    pass them with ``sets_step=False``: a spectroradiometer's 1 nm SPDs then set the
    range but do not force a 1 nm calibration of 5 nm chart data. Start and end are
    put on multiples of an integer step (380, 385, ... for 5 nm).

    Raises
    ------
    InputError
        No inputs, or no common range (naming each input's range and file).

    Examples
    --------
    >>> import numpy as np
    >>> a = Spectra(np.arange(380.0, 781.0, 1.0), np.ones((1, 401)), ("L",))
    >>> b = Spectra(np.arange(400.0, 731.0, 10.0), np.ones((1, 34)), ("A1",))
    >>> str(grid_from_data([a, b], sets_step=[False, True]))
    '400:730:10'
    """
    if not spectra:
        raise InputError("no spectral inputs to choose a grid from")
    sets = list(sets_step) if sets_step is not None else [True] * len(spectra)
    if not any(sets):
        sets = [True] * len(spectra)
    start = max(float(s.wavelength_nm[0]) for s in spectra)
    end = min(float(s.wavelength_nm[-1]) for s in spectra)
    steps = [
        float(np.min(np.diff(s.wavelength_nm)))
        for s, k in zip(spectra, sets, strict=True)
        if k and s.wavelength_nm.size > 1
    ]
    step = min([*steps, max_step_nm])
    if abs(step - round(step)) < _WL_TOL_NM and round(step) >= 1:
        step = float(round(step))
        start = math.ceil(start / step - 1e-9) * step
        end = math.floor(end / step + 1e-9) * step
    else:
        end = start + math.floor((end - start) / step + 1e-9) * step
    if end - start < step - _WL_TOL_NM:
        ranges = "; ".join(
            f"{s.meta.get('source', ', '.join(s.names[:3]))}: "
            f"{s.wavelength_nm[0]:g}-{s.wavelength_nm[-1]:g} nm"
            for s in spectra
        )
        raise InputError(f"the inputs share no wavelength range ({ranges})")
    return Grid(start, end, step)


#: Fewest samples a cubic spline is drawn through (fewer: linear interpolation).
_MIN_SPLINE_SAMPLES = 4


def spline_matrix(
    wl: NDArray[np.float64], target: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``W`` (n_target, n_data): the cubic spline (not-a-knot) through samples at
    ``wl``, evaluated at ``target`` and held at the end values outside ``wl``, as a
    linear operator (its weights are the spline of each unit vector). Linear
    interpolation with fewer than four samples.

    Examples
    --------
    >>> import numpy as np
    >>> W = spline_matrix(np.arange(400.0, 701.0, 10.0), np.array([405.0, 800.0]))
    >>> r = np.cos(np.arange(400.0, 701.0, 10.0) / 40.0)
    >>> [round(float(x), 4) for x in W @ r], round(float(np.cos(405 / 40)), 4)
    ([-0.7648, 0.2194], -0.7647)
    """
    if wl.size < _MIN_SPLINE_SAMPLES:
        return resampling_matrix(wl, target)
    from scipy.interpolate import CubicSpline

    return CubicSpline(wl, np.eye(wl.size), axis=0)(np.clip(target, wl[0], wl[-1]))


def resampling_matrix(
    wl: NDArray[np.float64], target: NDArray[np.float64], *, average: bool = False
) -> NDArray[np.float64]:
    """``W`` (n_target, n_data) with ``values @ W.T`` the resampled spectra.

    Linear interpolation (end values held outside the data); with ``average``, where
    the data are finer than half the target's local step, the hat function of each
    target sample (1 at it, 0 at its neighbours) weighted by the data's trapezoid
    rule and normalised: a local average that preserves area and centroid (see
    :meth:`Spectra.resample`), and elsewhere a cubic spline (not-a-knot) through
    the data: an LED 2-3 samples wide in data at 10 nm becomes a triangle by linear
    interpolation, and Eq. 1's responses of 52 cameras to the LEDs of the
    generalisation benchmark move by 1.0 % RMS of their strongest channel
    (0.16 % with the spline; ``benchmarks/metering_denoise.py``).

    References
    ----------
    ASTM E308-18 (interpolation of spectral data); CIE 167:2005 (tabulating
    spectral data for colour computations).

    Examples
    --------
    >>> import numpy as np
    >>> wl = np.arange(400.0, 421.0)
    >>> W = resampling_matrix(wl, np.arange(400.0, 421.0, 5.0), average=True)
    >>> led = np.exp(-0.5 * ((wl - 410.4) / 2.0) ** 2)
    >>> round(float((W @ led).sum() * 5.0 / led.sum()), 2)  # the area is kept
    1.0
    """
    n_t = target.size
    W = np.zeros((n_t, wl.size))
    d_data = float(np.median(np.diff(wl))) if wl.size > 1 else 0.0
    spline = None
    finest = float(np.min(np.diff(target))) if n_t > 1 else np.inf
    if average and wl.size >= _MIN_SPLINE_SAMPLES and finest <= 2.0 * d_data:
        # light spectra from coarser data: a cubic spline through the samples
        spline = spline_matrix(wl, target)
    trap = np.zeros(wl.size)
    if wl.size > 1:
        dw = np.diff(wl)
        trap[:-1] += dw / 2.0
        trap[1:] += dw / 2.0
    for j, t in enumerate(target):
        left = target[j - 1] if j > 0 else None
        right = target[j + 1] if j < n_t - 1 else None
        steps = [t - left] if left is not None else []
        steps += [right - t] if right is not None else []
        step = min(steps) if steps else 0.0
        if average and wl.size > 1 and step > 2.0 * d_data:
            lo = left if left is not None else t - (right - t)
            hi = right if right is not None else t + (t - left)
            hat = np.where(wl <= t, (wl - lo) / (t - lo), (hi - wl) / (hi - t)).clip(
                0.0, 1.0
            )
            inside = (wl >= lo) & (wl <= hi) & (wl >= wl[0]) & (wl <= wl[-1])
            w = np.where(inside, hat * trap, 0.0)
            if w.sum() > 0:
                W[j] = w / w.sum()
                continue
        if spline is not None:
            W[j] = spline[j]
            continue
        k = int(np.clip(np.searchsorted(wl, t), 1, wl.size - 1)) if wl.size > 1 else 0
        if wl.size == 1:
            W[j, 0] = 1.0
            continue
        x0, x1 = wl[k - 1], wl[k]
        f = float(np.clip((t - x0) / (x1 - x0), 0.0, 1.0))
        W[j, k - 1] += 1.0 - f
        W[j, k] += f
    return W
