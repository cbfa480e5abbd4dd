"""The light source's reported spectra: what its spectroradiometer's noise floor adds.

Far from an LED's emission a spectroradiometer reads noise around zero. An instrument
that clips negative readings at zero (as many report, and as the simulated CAL1 does)
turns that noise into a positive floor over hundreds of nanometres. Eq. 1 weights the
floor by every camera channel, and where a channel barely sees an LED (the blue channel
under a deep-red LED) the floor's share equals the true response: the simulated bench's
blue responses under LED700 were 0.54 of what its reported spectrum predicted, and the
calibration's per-LED gains absorbed it (0.61-0.83 for the red LEDs).

:func:`suppress_meter_floor` sets every reported sample below the detection limit, three
standard deviations of the instrument's noise (the IUPAC convention for the limit of
detection), to zero. The noise is estimated per spectrum from the spectrum itself: the
DER_SNR estimator (the median of second differences) over the samples far below the
peak that the instrument did not clip. A noise-free spectrum, or a broad one with no
noise-only region, is returned unchanged, and so is a cleaned one (the function is
repeated until it changes nothing, so applying it twice is applying it once). Raw files
are never changed: this is applied where the reported spectra become the illuminants of
Eq. 1 (processing, the per-pixel images, gonio sessions) and where a calibration meets
reported spectra (``estimate_camera_sensitivity`` and ``correct_illuminants``, so
spectra that did not come through processing are cleaned the same way).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Eq. 1. IUPAC Compendium of Chemical Terminology ("Gold Book"),
"limit of detection" (3 standard deviations of the blank). F. Stoehr et al., "DER_SNR: A
simple & general spectroscopic signal-to-noise measurement algorithm", ASP Conference
Series 394 (2008) 505.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tunespec.core.spectra import Spectra

__all__ = [
    "DETECTION_LIMIT_SD",
    "NOISE_REGION_FRACTION",
    "meter_noise_sd",
    "suppress_meter_floor",
]

#: Reported samples below this many noise standard deviations are set to zero.
DETECTION_LIMIT_SD = 3.0
#: Samples below this fraction of a spectrum's peak estimate its noise.
NOISE_REGION_FRACTION = 0.01
#: Passes of :func:`suppress_meter_floor` at most (it stops when one changes nothing).
_MAX_PASSES = 5
#: Fewest second differences an estimate of the noise needs; fewer give none.
_MIN_DIFFERENCES = 16
#: Independent noise makes two of every three samples a local extremum; a smooth tail
#: (a noise-free spectrum, however coarsely sampled) almost none. Below this fraction
#: the region is taken to hold no noise to measure.
_MIN_EXTREMUM_FRACTION = 1.0 / 3.0
#: DER_SNR's constant: 1.482602 / sqrt(6) turns the median of |2 f_i - f_i-2 - f_i+2|
#: into a Gaussian standard deviation (Stoehr et al. 2008).
_DER_SNR = 1.482602 / np.sqrt(6.0)
#: Standard deviation of a half-normal variable, in units of its Gaussian's.
_HALF_NORMAL_SD = float(np.sqrt(1.0 - 2.0 / np.pi))


def meter_noise_sd(values: NDArray[np.float64]) -> float:
    """Noise standard deviation of one reported spectrum (DER_SNR, Stoehr et al. 2008).

    The samples below :data:`NOISE_REGION_FRACTION` of the peak, in order, give the
    median of ``|2 f_i - f_(i-2) - f_(i+2)|`` times 1.482602 / sqrt(6). Where the
    instrument clips (exact zeros among them) only the samples above zero are used,
    and those are half-normal: their estimate is divided by ``sqrt(1 - 2 / pi)``, the
    ratio of a half-normal's standard deviation to the Gaussian's. 0.0 when fewer
    than 16 differences exist (a broad spectrum has no noise-only region) or where
    fewer than a third of those samples turn (a local maximum or minimum: a smooth,
    noise-free tail, which DER_SNR would mistake for noise on a coarse grid).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> v = np.exp(-0.5 * ((np.arange(400.0) - 200.0) / 10.0) ** 2)
    >>> round(meter_noise_sd(v + 0.001 * rng.standard_normal(400)), 4)  # sd 0.001
    0.0011
    >>> round(meter_noise_sd(np.maximum(v + 0.001 * rng.standard_normal(400), 0)), 4)
    0.0008
    >>> meter_noise_sd(v)  # noise-free: the tails' second differences are tiny
    0.0
    """
    v = np.asarray(values, dtype=np.float64)
    peak = float(v.max()) if v.size else 0.0
    if not peak > 0:
        return 0.0
    low = v[v < NOISE_REGION_FRACTION * peak]
    clipped = bool(np.any(low == 0.0)) and not bool(np.any(low < 0.0))
    if clipped:
        low = low[low > 0.0]
    d = np.abs(2.0 * low[2:-2] - low[:-4] - low[4:])
    if d.size < _MIN_DIFFERENCES or _extremum_fraction(low) < _MIN_EXTREMUM_FRACTION:
        return 0.0
    sd = float(_DER_SNR * np.median(d))
    if clipped:
        sd /= _HALF_NORMAL_SD
    # rounding jitter of a computed, noise-free tail turns as noise does, at a level
    # far below any instrument's
    return sd if sd > 1e-6 * peak else 0.0


def _extremum_fraction(values: NDArray[np.float64]) -> float:
    """Fraction of interior samples that are a local maximum or minimum."""
    step = np.sign(np.diff(values))
    turns = step[1:] * step[:-1] < 0
    return float(np.mean(turns)) if turns.size else 0.0


def suppress_meter_floor(
    spectra: Spectra, limit_sd: float = DETECTION_LIMIT_SD
) -> Spectra:
    """``spectra`` with every sample below ``limit_sd`` noise sd of zero set to zero.

    Each spectrum's noise comes from :func:`meter_noise_sd`. Negative samples (an
    instrument that does not clip) are set to zero too: they are noise as well.

    Examples
    --------
    >>> import numpy as np
    >>> wl = np.arange(380.0, 781.0)
    >>> led = np.exp(-0.5 * ((wl - 450.0) / 10.0) ** 2)
    >>> noisy = np.maximum(led + 0.001 * np.random.default_rng(1).standard_normal(401), 0)
    >>> s = suppress_meter_floor(Spectra(wl, noisy[None], ("LED450",)))
    >>> # the clipped noise's floor past 600 nm, in 1e-4 of the peak: before, after
    >>> round(1e4 * float(noisy[wl > 600].mean()), 1), round(1e4 * float(s.values[0, wl > 600].mean()), 1)
    (3.1, 0.2)
    >>> float(np.abs(s.values[0] - led).max()) < 0.005
    True
    """
    out = np.array(spectra.values, dtype=np.float64)
    changed = False
    for row in out:
        # again until nothing changes: the first pass's zeros sharpen the estimate
        # of the noise that stood above its limit (two passes, rarely three)
        for _ in range(_MAX_PASSES):
            floor = limit_sd * meter_noise_sd(row)
            cut = (row < floor) & (row != 0.0) if floor > 0 else row < 0
            if not np.any(cut):
                break
            row[cut] = 0.0
            changed = True
    return spectra.with_values(out) if changed else spectra
