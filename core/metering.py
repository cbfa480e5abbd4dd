"""The light source's reported spectra: what its spectroradiometer's noise floor adds.

Far from an LED's emission a spectroradiometer reads noise around zero. An instrument
that clips negative readings at zero (as many report, and as the simulated CAL1 does)
turns that noise into a positive floor over hundreds of nanometres. Eq. 1 weights the
floor by every camera channel, and where a channel barely sees an LED (the blue channel
under a deep-red LED) the floor's share equals the true response: the simulated bench's
blue responses under LED700 were 0.54 of what its reported spectrum predicted, and the
calibration's per-LED gains absorbed it (0.61-0.83 for the red LEDs).

:func:`suppress_meter_floor` keeps each spectrum's emission bands and sets everything
outside them to zero (:func:`emission_bands`: runs of samples above four times the
noise's standard deviation, widened by 10 nm for the tails). It works on the spectra as the instrument
reports them, from 1 to 10 nm: at 10 nm an LED is two or three samples wide, and once
resampled its interpolated noise no longer looks like noise, so the readers clean
illuminant files before anything resamples them. On the generalisation benchmark's two
22-LED lights and 52 cameras (``benchmarks/metering_denoise.py``) the response error
that noise of 0.1 % of the peak leaves falls to within 1.0-1.4x of an oracle that knows
where each LED emits, at 1, 5 and 10 nm (0.1 % and 0.3 %). A noise-free spectrum, and a cleaned one, are
returned unchanged. :func:`reading_noise_rms` estimates the noise on a spectrum's
emission from its floor (clipped or not, one reading or several averaged): the
readings' uncertainty draws it again, the self-check judges it and the CAL1 driver
checks replies against it.

What cleaning leaves, the noise inside the bands, is propagated as an uncertainty of
Eq. 1's illumination (:mod:`tunespec.core.readings`).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Eq. 1. F. Stoehr et al., "DER_SNR: A simple & general
spectroscopic signal-to-noise measurement algorithm", ASP Conference Series 394 (2008)
505. CIE 167:2005, "Recommended practice for tabulating spectral data for use in colour
computations" (coarser spectral data interpolated by a higher-order polynomial, Sprague's,
rather than linearly; :func:`~tunespec.core.spectra.resampling_matrix` uses a cubic
spline).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from tunespec.core.spectra import Grid, Spectra, resampling_matrix

__all__ = [
    "BAND_NOISE_FRACTION",
    "EMISSION_LIMIT_SD",
    "EMISSION_MARGIN_NM",
    "READING_NOISE_META",
    "READING_STEP_META",
    "as_calibrated",
    "emission_bands",
    "reading_meta",
    "reading_noise_fractions",
    "reading_noise_rms",
    "reading_step_nm",
    "suppress_meter_floor",
]

#: A reported sample above this many times the noise's standard deviation
#: (:func:`reading_noise_rms`) is emission (at 4 a noise sample passes with a
#: probability of about 3e-5, so a 22-LED light at 1 nm shows a few such single
#: samples, which :func:`emission_bands` does not take as a band). The earlier level,
#: the low samples' RMS without their highest tenth, put the LEDs' limits at a median
#: 3.4-4.6 of this standard deviation.
EMISSION_LIMIT_SD = 4.0
#: Each emission band is widened by this much on either side: an LED's tails below the
#: limit carry light a camera channel far from the peak still sees (a deep-red LED's
#: short-wavelength tail is all an IR-cut camera's red channel gets of it). Half the
#: width of a typical LED band (20-30 nm FWHM).
EMISSION_MARGIN_NM = 10.0
#: Samples above this fraction of a spectrum's peak are its emission, whatever the
#: noise: its floor lies beyond them (:data:`BAND_REACH_NM`), and a spectrum whose
#: samples below it are mostly exact zeros has been cleaned.
BAND_NOISE_FRACTION = 0.02
#: Key of a cleaned spectra's ``meta`` under which :func:`suppress_meter_floor` keeps
#: each spectrum's reading noise as reported (JSON: name -> fraction of its peak).
READING_NOISE_META = "reading_noise_fraction"
#: Key of a cleaned spectra's ``meta`` under which :func:`suppress_meter_floor` keeps
#: the step the instrument reported at (nm): where the noise was, once resampled.
READING_STEP_META = "reading_step_nm"
#: A spectrum whose low samples are mostly exact zeros has been cleaned already (an
#: instrument that clips its noise at zero leaves a quarter to a half of them at zero).
_CLEANED_ZERO_FRACTION = 2.0 / 3.0
#: Separate nonzero runs that make a floor clipped noise (:func:`_scattered_zeros`).
_MIN_NONZERO_RUNS = 4
#: How far past the samples above :data:`BAND_NOISE_FRACTION` of its peak an LED's
#: kept band can reach: its tails down to the emission limit and their margin (at
#: 1 nm and 0.3 % noise the cleaned green LEDs reach 18 nm past them).
BAND_REACH_NM = 30.0
#: Fewest second differences an estimate of the noise needs; fewer give none.
_MIN_DIFFERENCES = 16
#: Independent noise makes two of every three samples a local extremum; a smooth tail
#: (a noise-free spectrum, however coarsely sampled) almost none. Below this fraction
#: the region is taken to hold no noise to measure.
_MIN_EXTREMUM_FRACTION = 1.0 / 3.0
#: Standard deviation of ``max(0, z)`` for a standard normal ``z``: a floor clipped at
#: zero, as a fraction of the noise on the emission (the same for an average of
#: ``n`` readings, both then divided by ``sqrt(n)``).
_CLIPPED_FLOOR_SD = float(np.sqrt(0.5 - 0.5 / np.pi))


def _extremum_fraction(values: NDArray[np.float64]) -> float:
    """Fraction of interior samples that are a local maximum or minimum."""
    step = np.sign(np.diff(values))
    turns = step[1:] * step[:-1] < 0
    return float(np.mean(turns)) if turns.size else 0.0


def _far_floor(
    v: NDArray[np.float64], wavelength_nm: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """The samples more than :data:`BAND_REACH_NM` from any sample above
    :data:`BAND_NOISE_FRACTION` of the peak: where a spectrum shows its floor alone."""
    lit = wavelength_nm[v >= BAND_NOISE_FRACTION * v.max()] if v.size else v
    if lit.size == 0:
        return np.ones(v.shape, dtype=bool)
    gap = np.min(np.abs(wavelength_nm[:, None] - lit[None, :]), axis=1)
    return gap > BAND_REACH_NM


def _scattered_zeros(v: NDArray[np.float64], far: NDArray[np.bool_]) -> bool:
    """Whether ``v`` is nonzero in at least :data:`_MIN_NONZERO_RUNS` separate runs
    of its floor ``far`` (:func:`_far_floor`'s mask).

    A noise-free spectrum is zero, if anywhere, in one run at each end, a phosphor
    white's two bands are joined, and a cleaned spectrum is zero beyond its bands'
    margins; a floor clipped at zero scatters its positive samples between zeros.
    The turning test alone misses such a floor where few samples survive the
    clipping and the band's monotone flanks count among them, and the share of
    zeros alone takes it for a cleaned one (a single reading every 10 nm leaves half
    of them at zero): 8-21 of 1000 LED spectra at 10 nm, whose floor then stayed in
    Eq. 1 and once moved a calibration 0.24 RMS from the truth
    (``docs/validation.md``)."""
    return _runs((v != 0.0) & far)[0].size >= _MIN_NONZERO_RUNS


def _runs(mask: NDArray[np.bool_]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Starts and (exclusive) stops of ``mask``'s runs of True."""
    edges = np.flatnonzero(
        np.diff(np.concatenate([[False], mask, [False]]).astype(np.int8))
    )
    return edges[::2], edges[1::2]


def reading_noise_rms(
    values: NDArray[np.float64], wavelength_nm: NDArray[np.float64] | None = None
) -> float:
    """The reading noise of one reported spectrum: the standard deviation of the noise
    on its emission, which Eq. 1 integrates (:func:`tunespec.core.readings.draw_noise`
    draws it again at this level).

    Where the spectrum has a floor far from its emission (samples more than
    :data:`BAND_REACH_NM` from any sample above :data:`BAND_NOISE_FRACTION` of the
    peak; ``wavelength_nm`` their wavelengths, default 1 nm apart), the floor's
    variance comes from its second differences within each run of samples
    (``mean((2 f_i - f_(i-2) - f_(i+2))^2) / 6``, which a slow background does not
    disturb: DER_SNR's differences, Stoehr et al. 2008, averaged squared rather than
    through their median, whose constant holds for Gaussian noise only). There the
    true spectrum is zero, so an instrument that clips its noise at zero reports
    ``max(0, sigma z)``, or the mean of ``n`` such readings, whose variance is
    ``(1/2 - 1/(2 pi)) sigma^2 / n`` for any ``n``, while on the emission the noise is
    ``sigma / sqrt(n)``: the floor's standard deviation is divided by
    ``sqrt(1/2 - 1/(2 pi))`` where the floor holds no negative sample. The positive
    samples alone, by DER_SNR, read 0.56-0.66 of the noise at 1 nm, one or two
    readings averaged (``docs/validation.md``). 0.0 where there is no such floor of at least
    16 second differences (a phosphor white emits everywhere; the samples near a
    band carry its tails) or it shows no noise (all zero, as cleaned; or smooth, as
    a noise-free tail).

    Examples
    --------
    >>> import numpy as np
    >>> v = np.exp(-0.5 * ((np.arange(400.0) - 200.0) / 10.0) ** 2)
    >>> noisy = np.maximum(v + 0.001 * np.random.default_rng(0).standard_normal(400), 0)
    >>> round(reading_noise_rms(noisy), 4), reading_noise_rms(v)
    (0.0009, 0.0)
    """
    v = np.asarray(values, dtype=np.float64)
    wl = (
        np.arange(v.size, dtype=np.float64)
        if wavelength_nm is None
        else np.asarray(wavelength_nm, dtype=np.float64)
    )
    peak = float(v.max()) if v.size else 0.0
    if not peak > 0:
        return 0.0
    far = _far_floor(v, wl)
    runs = [v[a:b] for a, b in zip(*_runs(far), strict=True)]
    d = np.concatenate(
        [2.0 * r[2:-2] - r[:-4] - r[4:] for r in runs if r.size > 4] or [np.zeros(0)]
    )
    floor = np.concatenate(runs) if runs else np.zeros(0)
    if d.size < _MIN_DIFFERENCES or not np.any(floor != 0.0):
        return 0.0
    if _extremum_fraction(floor) < _MIN_EXTREMUM_FRACTION and not _scattered_zeros(
        v, far
    ):
        return 0.0
    sd = float(np.sqrt(np.mean(d * d) / 6.0))
    if not np.any(floor < 0.0):  # clipped at zero
        sd /= _CLIPPED_FLOOR_SD
    # rounding jitter of a computed, noise-free tail turns as noise does, at a level
    # far below any instrument's
    return sd if sd > 1e-6 * peak else 0.0


def reading_noise_fractions(spectra: Spectra) -> dict[str, float]:
    """Per spectrum the reading noise as a fraction of its peak, as reported: what
    :func:`suppress_meter_floor` measured before it cleaned them (``meta``), else
    :func:`reading_noise_rms` of the spectra as they stand, at their own step.

    Cleaned, a spectrum's floor is zero and shows no noise, so the cleaning keeps
    what it measured before.

    A spectrum that shows no noise where others do gets their median: one instrument
    read them all, and a phosphor white emits at every sample, so no sample of it
    shows the noise alone (``benchmarks/generalisation.py``, readings at 10 nm with
    0.3 % noise: the two whites measured 0, and the readings' term of the budget was
    1.5-1.8 times too small in L* and b* on the broad cameras, 1.3-1.4 with the whites
    read without noise).
    """
    kept = _kept_noise_fractions(spectra)
    return _others_where_unmeasured(
        kept if kept is not None else _measured_noise_fractions(spectra)
    )


def _others_where_unmeasured(noise: dict[str, float]) -> dict[str, float]:
    """``noise`` with each 0 replaced by the median of the others (all 0: as is)."""
    shown = [f for f in noise.values() if f > 0]
    if not shown:
        return noise
    return {n: f if f > 0 else float(np.median(shown)) for n, f in noise.items()}


def _kept_noise_fractions(spectra: Spectra) -> dict[str, float] | None:
    """The reading noise that a cleaning kept in ``meta`` for every spectrum, or
    ``None``."""
    kept = spectra.meta.get(READING_NOISE_META)
    if kept is not None:
        doc = json.loads(kept)
        if isinstance(doc, dict) and set(spectra.names) <= set(doc):
            return {n: float(doc[n]) for n in spectra.names}
    return None


def reading_meta(spectra: Sequence[Spectra], names: Sequence[str]) -> dict[str, str]:
    """The metering keys (:data:`READING_NOISE_META`, :data:`READING_STEP_META`) of
    spectra combined from single readings ``spectra`` (each cleaned), named
    ``names``: each one's reading noise (:func:`reading_noise_fractions`) and the
    first one's step as reported."""
    noise = {
        name: next(iter(reading_noise_fractions(s).values()), 0.0)
        for s, name in zip(spectra, names, strict=True)
    }
    out = {READING_NOISE_META: json.dumps(noise)}
    if spectra:
        out[READING_STEP_META] = repr(reading_step_nm(spectra[0]))
    return out


def reading_step_nm(spectra: Spectra) -> float:
    """The step (nm) the instrument reported ``spectra`` at: as a cleaning kept it
    (``meta``, :data:`READING_STEP_META`), else their own typical step."""
    try:
        step = float(spectra.meta.get(READING_STEP_META, "nan"))
    except (TypeError, ValueError):
        step = float("nan")
    return (
        step if np.isfinite(step) and step > 0 else _median_step(spectra.wavelength_nm)
    )


def parse_reading_meta(
    values: Mapping[str, str], names: Sequence[str]
) -> dict[str, str]:
    """The metering keys as a file states them (:data:`READING_NOISE_META`: a JSON
    object name -> fraction of the peak in [0, 1) naming every spectrum;
    :data:`READING_STEP_META`: a step in nm in (0, 100]), checked and written back
    canonically; ValueError saying what is wrong."""
    out: dict[str, str] = {}
    if READING_NOISE_META in values:
        try:
            doc = json.loads(values[READING_NOISE_META])
        except ValueError:
            raise ValueError("expected a JSON object name -> number") from None
        if not isinstance(doc, dict) or not set(names) <= set(doc):
            raise ValueError("expected a JSON object naming every spectrum")
        noise = {}
        for n in names:
            v = doc[n]
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 <= v < 1:
                raise ValueError(f"{n}: {v!r} is not a fraction in [0, 1)")
            noise[n] = float(v)
        out[READING_NOISE_META] = json.dumps(noise)
    if READING_STEP_META in values:
        try:
            step = float(values[READING_STEP_META])
        except ValueError:
            raise ValueError("expected a step in nm") from None
        if not 0 < step <= 100:
            raise ValueError(f"step {step:g} nm outside (0, 100]")
        out[READING_STEP_META] = repr(step)
    return out


def _measured_noise_fractions(spectra: Spectra) -> dict[str, float]:
    """:func:`reading_noise_rms` of each spectrum as it stands, over its peak."""
    out = {}
    for name, row in zip(spectra.names, spectra.values, strict=True):
        peak = float(np.max(row)) if row.size else 0.0
        out[name] = (
            reading_noise_rms(row, spectra.wavelength_nm) / peak if peak > 0 else 0.0
        )
    return out


def emission_bands(
    values: NDArray[np.float64],
    wavelength_nm: NDArray[np.float64],
    limit_sd: float = EMISSION_LIMIT_SD,
    margin_nm: float = EMISSION_MARGIN_NM,
    noise_sd: float | None = None,
) -> NDArray[np.bool_] | None:
    """Which reported samples belong to the light's emission bands, or ``None``.

    An LED emits in one band (a phosphor-converted white in two joined ones); what a
    spectroradiometer reports outside them is its noise, of standard deviation
    ``noise_sd`` (default: :func:`reading_noise_rms` of this spectrum). A band is a
    run of samples above ``limit_sd`` times it which holds the peak or is at least
    two samples long (one sample above it is the noise's own tail), widened by
    ``margin_nm`` on each side (at least one sample) for the band's tails below the
    limit. ``None`` where there is no noise (``noise_sd`` 0: a noise-free spectrum,
    or a white whose noise nothing measured) or where most samples below
    :data:`BAND_NOISE_FRACTION` of the peak are exact zeros (a spectrum cleaned
    already) -- the spectrum is then taken as it is.

    The level used to be the root mean square of this spectrum's low samples
    without their highest tenth; a white's low samples are mostly its own emission,
    so at 1 nm its limit was 1.7-6.7 % of the peak and the cleaning cut 0.05-2.1 %
    of its light, below 410 and above 690 nm (``docs/validation.md``).
    """
    v = np.asarray(values, dtype=np.float64)
    peak = float(v.max()) if v.size else 0.0
    if not peak > 0:
        return None
    low = v[v < BAND_NOISE_FRACTION * peak]
    if low.size == 0 or (
        np.mean(low == 0.0) > _CLEANED_ZERO_FRACTION
        and not _scattered_zeros(v, _far_floor(v, wavelength_nm))
    ):
        return None
    sd = reading_noise_rms(v, wavelength_nm) if noise_sd is None else noise_sd
    if not sd > 0:
        return None
    limit = limit_sd * sd
    step_nm = _median_step(wavelength_nm)
    margin = max(1, round(margin_nm / step_nm))
    ipk = int(np.argmax(v))
    keep = np.zeros(v.size, dtype=bool)
    for lo, hi in zip(*_runs(v > limit), strict=True):
        if hi - lo >= 2 or lo <= ipk < hi:
            keep[max(lo - margin, 0) : hi + margin] = True
    return keep


def _median_step(wavelength_nm: NDArray[np.float64]) -> float:
    """The samples' typical step in nm (1 for a single sample)."""
    return float(np.median(np.diff(wavelength_nm))) if wavelength_nm.size > 1 else 1.0


def suppress_meter_floor(spectra: Spectra) -> Spectra:
    """``spectra`` with everything outside each spectrum's emission bands set to zero.

    Each spectrum is read at the instrument's own sampling (1 to 10 nm: at 10 nm an
    LED is two or three samples wide): the bands come from :func:`emission_bands`,
    and every sample outside them, and every negative one, is set to zero. A
    noise-free spectrum is returned unchanged, and so is a cleaned one (applying
    this twice is applying it once). Call it on the spectra as reported, before any
    resampling: interpolated noise no longer looks like noise.

    Examples
    --------
    >>> import numpy as np
    >>> wl = np.arange(380.0, 781.0)
    >>> led = np.exp(-0.5 * ((wl - 450.0) / 10.0) ** 2)
    >>> noisy = np.maximum(led + 0.001 * np.random.default_rng(1).standard_normal(401), 0)
    >>> s = suppress_meter_floor(Spectra(wl, noisy[None], ("LED450",)))
    >>> # the clipped noise's floor past 600 nm, in 1e-4 of the peak: before, after
    >>> round(1e4 * float(noisy[wl > 600].mean()), 1), round(1e4 * float(s.values[0, wl > 600].mean()), 1)
    (3.1, 0.0)
    >>> float(np.abs(s.values[0] - led).max()) < 0.005
    True
    >>> suppress_meter_floor(s) is s  # cleaned once is clean
    True
    >>> ten = Spectra(wl[::10], noisy[None, ::10], ("LED450",))  # reported at 10 nm
    >>> int((ten.values > 0).sum()), int((suppress_meter_floor(ten).values > 0).sum())
    (25, 8)
    """
    values = np.asarray(spectra.values, dtype=np.float64)
    kept = _kept_noise_fractions(spectra)
    measured = kept if kept is not None else _measured_noise_fractions(spectra)
    # one instrument read them all: each spectrum is cleaned at its own noise or
    # the others' median, whichever is higher (a white has no floor of its own to
    # measure; at 10 nm one LED's floor gives a few dozen differences, and a level
    # measured low let 2 of 1000 floors through, 0 with the median)
    noise = _others_where_unmeasured(measured)
    typical = float(np.median(list(noise.values()))) if noise else 0.0
    cut = np.zeros(values.shape, dtype=bool)
    for name, row, cut_row in zip(spectra.names, values, cut, strict=True):
        sd = max(noise[name], typical) * float(np.max(row)) if row.size else 0.0
        keep = emission_bands(row, spectra.wavelength_nm, noise_sd=sd)
        cut_row[:] = row < 0 if keep is None else (row < 0) | (~keep & (row != 0.0))
    if not cut.any():
        return spectra
    # cleaned, the spectra no longer show their noise: it is kept as the instrument
    # reported it, and what an earlier cleaning kept stays (spectra cleaned, then
    # resampled: their spline's ripples beside a band are not the instrument's noise)
    meta = dict(spectra.meta)
    if kept is None:
        meta[READING_NOISE_META] = json.dumps(measured)
        meta[READING_STEP_META] = repr(_median_step(spectra.wavelength_nm))
    return Spectra(
        spectra.wavelength_nm, np.where(cut, 0.0, values), spectra.names, meta
    )


def as_calibrated(spectra: Spectra, grid: Grid) -> Spectra:
    """Spectra as a calibration on ``grid`` takes its own: cleaned as reported
    (:func:`suppress_meter_floor`), band-averaged onto ``grid`` (as ``calibrate``
    reads them) and cleaned again there (as the fit does), in that order.

    Every path that uses a calibration's corrections or its readings' replicates
    brings a capture's spectra to this form first, so that the calibration's own
    readings come out identical however they arrive. Read again from the
    instrument's 10 nm file by ``tunespec estimate``, they used to be resampled after
    one cleaning only: they kept the spline's ripples beside their bands (up to 0.3 %
    of a peak), were taken for other readings (the readings' uncertainty drew noise
    of its own: L* intervals covering 0.98-1.00 on ``benchmarks/cli_protocol.py``),
    and the per-LED corrections fitted on 2 nm samples were applied to 10 nm ones.
    """
    spectra = suppress_meter_floor(spectra)
    wl, target = spectra.wavelength_nm, grid.wavelength_nm
    if wl.shape != target.shape or not np.allclose(wl, target):
        # as Spectra.resample(average=True) draws light (cleaned, so non-negative),
        # with the end values held where the spectra stop short of the grid (an LED
        # is zero there)
        values = np.maximum(
            spectra.values @ resampling_matrix(wl, target, average=True).T, 0
        )
        spectra = Spectra(target, values, spectra.names, spectra.meta)
    return suppress_meter_floor(spectra)
