"""Errors in variables: the light's reading noise carried into calibration and estimate.

Eq. 1 takes the spectra that the light source's spectroradiometer reported as the
illumination. Their noise (0.1-0.3 % of each LED's peak on a compact array
instrument) moves the calibration (the sensitivities absorb it, and the per-LED
corrections) and the estimate, which integrates the same readings. On
``benchmarks/readings_bootstrap.py`` this spread was 0.2-0.6 of the stated
standard uncertainty of L*, a*, b* on an ideal sensor, and the 95 % intervals
covered 0.93 / 0.88 / 0.90 without it.

It is carried by a parametric bootstrap (B. Efron, R. J. Tibshirani, *An
Introduction to the Bootstrap*, 1993, ch. 6): the calibration is fitted again
(:func:`~tunespec.core.sensitivity_bayes.fit_bayes`'s ``replicate_spectra``, at its
hyper-parameters) with the readings' noise drawn again :data:`REPLICATES` times at
the level measured in them (:func:`~tunespec.core.metering.reading_noise_fractions`),
on the samples the instrument reported (its own step, kept by
:func:`~tunespec.core.metering.suppress_meter_floor`) inside the emission bands and
their margins (outside, the cleaning sets the readings to zero), clipped at zero as
the instrument clips (:func:`draw_noise`). :class:`ReadingReplicates` keeps
each replicate's sensitivities (as differences from the fit's), LED corrections and
the readings it was drawn on. An estimate under the *same* readings evaluates Eq. 1
with each replicate's sensitivities, corrections and the same draw of noise (the
calibration absorbed part of it, which then cancels); under other readings, a draw
of its own (:meth:`ReadingReplicates.perturbations`). The spread of the responses
it predicts is a term of the estimate's uncertainty
(:func:`tunespec.core.uncertainty.readings_response_covariance`; not of Eq. 5's
``K_e``, see ``docs/validation.md``), and the replicates' spread widens the
sensitivities' bands (:attr:`~tunespec.core.calibration.Calibration.std`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from tunespec.core.errors import InputError
from tunespec.core.forward_model import lighting_matrix
from tunespec.core.led_correction import _corrected
from tunespec.core.metering import (
    EMISSION_MARGIN_NM,
    reading_noise_fractions,
    reading_step_nm,
)
from tunespec.core.spectra import Spectra, resampling_matrix

__all__ = ["REPLICATES", "SAME_READING_TOLERANCE", "ReadingReplicates"]

#: Calibrations fitted again with the readings' noise drawn anew. Eight replicates
#: estimate the term's variance within about +-50 % (a chi-square with 8 degrees of
#: freedom); the term is 0.2-0.6 of the other terms' standard deviation, so the total
#: moves by a few per cent.
REPLICATES = 8
#: Two readings of an LED are the same reading when they differ nowhere by more than
#: this fraction of its peak on the calibration's grid (resampling the same numbers
#: twice differs by ~1e-15; two readings of one LED by their noise, 1e-3 and more).
SAME_READING_TOLERANCE = 1e-5
#: The seed of the replicates' noise (any fixed number: the draws must be the same
#: at calibration and at estimate time).
_SEED = 20231
_MAX_REPLICATES = 64


@dataclass(frozen=True, eq=False)
class ReadingReplicates:
    """A calibration's bootstrap replicates of the readings' noise.

    ``names`` the LEDs (calibration order); ``wavelength_nm`` the calibration's grid;
    ``readings`` (n_i, n) the cleaned readings the noise was drawn on, on that grid;
    ``noise_fraction`` (n_i,) each one's noise as a fraction of its peak;
    ``reading_step_nm`` the step the instrument reported at; ``sensitivity_delta``
    (K, 3, n) each replicate's sensitivities minus the fit's; ``gain``,
    ``shift_nm`` (K, n_i) its LED corrections.
    """

    names: tuple[str, ...]
    wavelength_nm: NDArray[np.float64]
    readings: NDArray[np.float64]
    noise_fraction: NDArray[np.float64]
    reading_step_nm: float
    sensitivity_delta: NDArray[np.float64]
    gain: NDArray[np.float64]
    shift_nm: NDArray[np.float64]

    @property
    def n_replicates(self) -> int:
        return int(self.sensitivity_delta.shape[0])

    def perturbations(self, illuminants: Spectra, k: int) -> NDArray[np.float64]:
        """Replicate ``k``'s noise on ``illuminants`` (cleaned, on this grid): an LED
        whose reading is the calibration's gets the calibration's draw, any other a
        draw of its own (:func:`draw_noise`)."""
        index = {n: j for j, n in enumerate(self.names)}
        out = np.empty(illuminants.values.shape)
        fractions = reading_noise_fractions(illuminants)
        for i, (name, row) in enumerate(
            zip(illuminants.names, illuminants.values, strict=True)
        ):
            j = index.get(name, -1)
            if j >= 0 and _same_reading(row, self.readings[j]):
                key, frac = (k, j), float(self.noise_fraction[j])
            else:  # another reading: its own noise, drawn independently
                key, frac = (k, len(self.names) + i), fractions[name]
            out[i] = draw_noise(
                self.wavelength_nm, row, frac, self.reading_step_nm, key
            )
        return out

    def lighting_deviations(
        self,
        readings: Spectra,
        sensitivity: NDArray[np.float64],
        correction: tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]],
    ) -> NDArray[np.float64]:
        """Eq. 1's ``F`` (:func:`~tunespec.core.forward_model.lighting_matrix`) under
        each replicate minus under the calibration, (K, 3 n_i, n), illuminant-major;
        at reflectances ``r`` the responses move by ``dF @ r``.

        ``readings`` the spectra as reported (cleaned, on this grid);
        ``sensitivity`` (3, n) the calibration's on this grid; ``correction``
        ``(rows, gain, shift_nm)`` of each spectrum as the calibration's LED
        correction looks them up (row -1: not fitted, kept in the replicates).
        """
        wl = self.wavelength_nm
        step = float(wl[1] - wl[0]) if wl.size > 1 else 1.0
        rows, gain, shift = correction
        fitted = rows >= 0
        base = lighting_matrix(_corrected(wl, readings.values, gain, shift)[0],
                               sensitivity, step)  # fmt: skip
        out = np.empty((self.n_replicates, *base.shape))
        for k in range(self.n_replicates):
            g, d = gain.copy(), shift.copy()
            g[fitted] = self.gain[k, rows[fitted]]
            d[fitted] = self.shift_nm[k, rows[fitted]]
            noisy = readings.values + self.perturbations(readings, k)
            Sk = sensitivity + self.sensitivity_delta[k]
            out[k] = lighting_matrix(_corrected(wl, noisy, g, d)[0], Sk, step) - base
        return out

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form (:meth:`from_dict` reads it back)."""
        return {
            "names": list(self.names),
            "wavelength_nm": self.wavelength_nm.tolist(),
            "readings": self.readings.tolist(),
            "noise_fraction": self.noise_fraction.tolist(),
            "reading_step_nm": float(self.reading_step_nm),
            "sensitivity_delta": self.sensitivity_delta.tolist(),
            "gain": self.gain.tolist(),
            "shift_nm": self.shift_nm.tolist(),
        }

    @classmethod
    def from_dict(cls, doc: Any, path: str | None = None) -> ReadingReplicates:
        """Read :meth:`as_dict`'s form; a one-line :class:`InputError` if it is not."""
        try:
            if not isinstance(doc, Mapping):
                raise TypeError("not an object")
            names = tuple(str(n) for n in doc["names"])
            wl = _array(doc["wavelength_nm"], 1, (0.0, 1e5))
            n_i, n = len(names), wl.size
            reps = cls(
                names,
                wl,
                _array(doc["readings"], 2, (0.0, 1e12), (n_i, n)),
                _array(doc["noise_fraction"], 1, (0.0, 1.0), (n_i,)),
                float(_array([doc["reading_step_nm"]], 1, (0.01, 100.0))[0]),
                _array(doc["sensitivity_delta"], 3, (-1e12, 1e12), (-1, 3, n)),
                _array(doc["gain"], 2, (1e-3, 1e3), (-1, n_i)),
                _array(doc["shift_nm"], 2, (-50.0, 50.0), (-1, n_i)),
            )
            k = reps.n_replicates
            if (
                not 0 < k <= _MAX_REPLICATES
                or reps.gain.shape[0] != k
                or (reps.shift_nm.shape[0] != k)
            ):
                raise ValueError(
                    f"{k} replicates, expected 1-{_MAX_REPLICATES} of each"
                )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"reading_replicates: {exc}", path=path) from None
        return reps


def _array(
    value: Any,
    ndim: int,
    limits: tuple[float, float],
    shape: tuple[int, ...] | None = None,
) -> NDArray[np.float64]:
    """``value`` as a finite float array of ``ndim`` dimensions within ``limits``
    and of ``shape`` (-1: any size); ValueError naming what is wrong."""
    if isinstance(value, bool) or value is None:
        raise TypeError(f"expected numbers, got {value!r}")
    a = np.asarray(value, dtype=np.float64)
    if a.ndim != ndim or a.size > 10_000_000:
        raise ValueError(f"expected {ndim} dimensions, got shape {a.shape}")
    if shape is not None and any(
        s >= 0 and s != got for s, got in zip(shape, a.shape, strict=True)
    ):
        raise ValueError(f"shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)) or (
        a.size and (a.min() < limits[0] or a.max() > limits[1])
    ):
        raise ValueError(f"values outside [{limits[0]:g}, {limits[1]:g}]")
    return a


def _same_reading(a: NDArray[np.float64], b: NDArray[np.float64]) -> bool:
    peak = max(float(np.max(np.abs(b))), 1e-300)
    return a.shape == b.shape and float(np.max(np.abs(a - b))) <= (
        SAME_READING_TOLERANCE * peak
    )


def draw_noise(
    wavelength_nm: NDArray[np.float64],
    row: NDArray[np.float64],
    noise_fraction: float,
    step_nm: float,
    key: tuple[int, int],
) -> NDArray[np.float64]:
    """One draw of a reading's noise, on ``wavelength_nm``.

    Gaussian noise of ``noise_fraction`` of the spectrum's peak on the samples the
    instrument reports (every ``step_nm``) where ``row`` is not zero and within
    :data:`~tunespec.core.metering.EMISSION_MARGIN_NM` of it (the bands and margins
    the cleaning keeps; it zeroes the rest), clipped at zero as the instrument clips
    and taken about the clipped reading's mean (``v Phi(v/sd) + sd phi(v/sd)``, so a
    sample near zero, whose reading already carries its clipped floor, gets no second
    floor), resampled onto the grid as the readers resample readings (band-averaged,
    or a cubic spline from coarser data). ``key`` (replicate, spectrum) seeds it: the
    same key gives the same draw.
    """
    peak = float(np.max(row)) if row.size else 0.0
    if not (noise_fraction > 0 and peak > 0):
        return np.zeros(wavelength_nm.shape)
    x, W = _native_samples(
        float(wavelength_nm[0]), float(wavelength_nm[-1]), wavelength_nm.size, step_nm
    )
    v = np.interp(x, wavelength_nm, row)
    # the bands and their margins: what the cleaning keeps of a reading
    reach = max(1, round(EMISSION_MARGIN_NM / step_nm))
    kept = np.convolve(v > 0.0, np.ones(2 * reach + 1), mode="same") > 0
    z = np.random.default_rng([_SEED, *key]).standard_normal(x.size)
    # clipped at zero, as the instrument reports, about the clipped reading's mean
    # (a reading near zero already carries its own clipped floor: drawing another
    # one on top of it doubled it, IR-cut camera 0.100 -> 0.116 mean dE00)
    sd = noise_fraction * peak
    u = v / sd
    clip_mean = v * ndtr(u) + sd * np.exp(-0.5 * u * u) / np.sqrt(2.0 * np.pi)
    noise = np.where(kept, np.maximum(v + sd * z, 0.0) - clip_mean, 0.0)
    return W @ noise


@lru_cache(maxsize=16)
def _native_samples(
    start_nm: float, end_nm: float, n: int, step_nm: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The instrument's sample wavelengths covering the grid ``start:end`` (``n``
    samples) every ``step_nm``, and the readers' resampling from them onto the grid
    (a matrix built once per grid: 9 ms each, 880 draws in a demo)."""
    lo = np.floor(start_nm / step_nm + 1e-9) * step_nm
    hi = np.ceil(end_nm / step_nm - 1e-9) * step_nm
    x = np.arange(lo, hi + 0.5 * step_nm, step_nm)
    W = resampling_matrix(x, np.linspace(start_nm, end_nm, n), average=True)
    x.setflags(write=False)
    W.setflags(write=False)
    return x, W


def replicate_spectra(
    illuminants: Spectra, n_replicates: int = REPLICATES
) -> list[NDArray[np.float64]]:
    """The calibration's readings (cleaned, on its grid) with their noise drawn
    again, one per replicate (:func:`draw_noise`, keys ``(k, j)``); empty where
    the readings show no noise."""
    fractions = reading_noise_fractions(illuminants)
    if not any(f > 0 for f in fractions.values()):
        return []
    step = reading_step_nm(illuminants)
    wl = illuminants.wavelength_nm
    return [
        illuminants.values
        + np.array(
            [
                draw_noise(wl, row, fractions[name], step, (k, j))
                for j, (name, row) in enumerate(
                    zip(illuminants.names, illuminants.values, strict=True)
                )
            ]
        )
        for k in range(n_replicates)
    ]


def replicates_of(
    illuminants: Spectra,
    sensitivity: NDArray[np.float64],
    fits: Sequence[tuple[NDArray[np.float64], ...]],
) -> ReadingReplicates | None:
    """:class:`ReadingReplicates` from the replicates' fits ``(S, gain, shift_nm)``
    (:attr:`~tunespec.core.sensitivity_bayes.BayesFit.replicates`) on the cleaned
    readings ``illuminants`` they were drawn on; ``None`` without fits."""
    if not fits:
        return None
    fractions = reading_noise_fractions(illuminants)
    return ReadingReplicates(
        tuple(illuminants.names),
        illuminants.wavelength_nm.copy(),
        np.array(illuminants.values, dtype=np.float64),
        np.array([fractions[n] for n in illuminants.names]),
        reading_step_nm(illuminants),
        np.array([f[0] - sensitivity for f in fits]),
        np.array([f[1] for f in fits]),
        np.array([f[2] for f in fits]),
    )
