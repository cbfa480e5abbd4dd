"""Realistic forward simulation of a calibration capture: responses with sensor noise.

The bench is simulated with the same image formation model the estimators invert,
:func:`tunespec.core.forward_model.render_rgb` (Eq. 1 of the paper), plus the errors a
real capture has:

* photon (shot) noise and read noise of the sensor, averaged over the ROI pixels of a
  patch (:class:`NoiseModel`);
* a flat-field residual: Eq. 2 of the paper corrects the illumination non-uniformity
  only up to a small relative error per patch and illuminant;
* a spectroradiometer that reports the LED spectra with a small wavelength-scale error
  and a per-LED power error (:func:`perturb_spd`), so the estimator works with a
  slightly wrong ``i`` in Eq. 1;
* exposure chosen per LED so that the brightest patch reaches a fixed fraction of full
  scale (:func:`scale_to_exposure`), which fixes the signal-to-noise ratio.

Responses are in units of full scale (1.0 = saturation), dark-corrected and
flat-fielded, as :mod:`tunespec.core.responses` defines them.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source: Setup, Characterization
and Reflectance Estimation (``shared/reference/paper-trichromatic-reflectance-capture``),
Eq. 1, 2 and 6.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from tunespec.core.errors import InputError
from tunespec.core.forward_model import render_rgb
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "NoiseModel",
    "check_rgb_sensitivity",
    "check_same_grid",
    "perturb_spd",
    "scale_to_exposure",
    "simulate_capture",
    "simulate_responses",
]

_WL_TOL_NM = 1e-6


@dataclass(frozen=True)
class NoiseModel:
    """Sensor noise and flat-field residual of one patch measurement.

    A patch's response is the mean of ``n_pixels`` ROI pixels per colour plane. A pixel
    with mean signal ``c`` (full-scale units) collects ``c * full_well_e`` electrons, so
    its standard deviation in full-scale units is::

        sigma_px(c) = sqrt(c * full_well_e + read_noise_e**2) / full_well_e

    and the ROI mean scatters by ``sigma_px / sqrt(n_pixels)``.

    Parameters
    ----------
    full_well_e
        Full-well capacity in electrons. 67 000 e- is the published figure of the
        Canon EOS 5D Mark III at ISO 100 (the paper's camera).
    read_noise_e
        Read noise in electrons (RMS), at the same ISO.
    n_pixels
        ROI pixels averaged per patch and colour plane (the paper averages the
        central 20 % of a patch).
    flat_field_residual
        Relative standard deviation of the multiplicative error that flat-fielding
        (Eq. 2) leaves, one draw per patch and illuminant, shared by R, G and B: the
        residual is an irradiance ratio between the white reference and the target
        position, and under one LED that ratio does not depend on the colour plane.
    """

    full_well_e: float = 67_000.0
    read_noise_e: float = 30.0
    n_pixels: int = 400
    flat_field_residual: float = 0.003

    def __post_init__(self) -> None:
        if not (0 < self.full_well_e < np.inf and 0 <= self.read_noise_e < np.inf):
            raise InputError("noise model: need full_well_e > 0 and read_noise_e >= 0")
        if not (self.n_pixels >= 2 and self.flat_field_residual >= 0):
            raise InputError(
                "noise model: need n_pixels >= 2 and flat_field_residual >= 0"
            )

    def pixel_std(self, signal: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per-pixel standard deviation for mean signal ``signal`` (full scale).

        Parameters
        ----------
        signal : any shape
            Mean pixel signal in full-scale units; negative values count as 0.

        Returns
        -------
        Same shape as ``signal``, full-scale units.

        Examples
        --------
        >>> float(NoiseModel(full_well_e=100.0, read_noise_e=0.0).pixel_std(1.0))
        0.1
        """
        c = np.maximum(np.asarray(signal, dtype=np.float64), 0.0)
        return np.sqrt(c * self.full_well_e + self.read_noise_e**2) / self.full_well_e

    def mean_std(self, signal: NDArray[np.float64]) -> NDArray[np.float64]:
        """Standard deviation of the ROI mean, ``pixel_std / sqrt(n_pixels)``."""
        return self.pixel_std(signal) / np.sqrt(self.n_pixels)


def check_same_grid(*spectra: Spectra) -> None:
    """Raise :class:`InputError` unless all ``spectra`` share one wavelength axis.

    The error names the ``meta["source"]`` of the first spectra that differ.
    """
    first = spectra[0]
    for other in spectra[1:]:
        a, b = first.wavelength_nm, other.wavelength_nm
        if a.shape != b.shape or not np.allclose(a, b, rtol=0.0, atol=_WL_TOL_NM):
            raise InputError(
                f"wavelength grids differ: {_describe_grid(first)} "
                f"({first.meta.get('source', 'spectra')}) vs. {_describe_grid(other)}; "
                "resample both onto one grid (--grid START:END:STEP)",
                path=other.meta.get("source"),
            )


def check_rgb_sensitivity(sensitivity: Spectra) -> None:
    """Raise :class:`InputError` unless ``sensitivity`` has exactly 3 curves (R, G, B).

    The error names the sensitivity's ``meta["source"]``.
    """
    if len(sensitivity) != 3:
        raise InputError(
            f"expected 3 sensitivity curves (R, G, B), got {len(sensitivity)}",
            path=sensitivity.meta.get("source"),
        )


def _describe_grid(s: Spectra) -> str:
    wl = s.wavelength_nm
    return f"{wl[0]:g}-{wl[-1]:g} nm, {wl.size} samples"


def _rng(rng: np.random.Generator | int) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def simulate_responses(
    reflectances: Spectra,
    illuminants: Spectra,
    sensitivity: Spectra,
    *,
    noise: NoiseModel | None = NoiseModel(),
    rng: np.random.Generator | int,
) -> Responses:
    """Camera responses of a target under each illuminant, with realistic noise.

    The noise-free responses are Eq. 1 (:func:`~tunespec.core.forward_model.render_rgb`).
    With a ``noise`` model, for each patch ``p``, illuminant ``i`` and channel ``k``:

    1. the flat-field residual multiplies the signal by ``1 + f z_pi`` (``z`` standard
       normal, shared by the three channels);
    2. pixels saturate at full scale: the ROI mean is the mean of a normal distribution
       clipped at 1 (exact formula, not sampled), and ``saturated`` is the sampled
       fraction of the ``n_pixels`` pixels that clip in the worst channel;
    3. photon and read noise add ``NoiseModel.mean_std`` of scatter to the mean
       (times the unclipped fraction of the pixels, so a fully saturated patch reads
       exactly 1.0);
    4. ``rgb_std`` is the per-pixel standard deviation as an ROI would report it (the
       model's ``pixel_std`` with the scatter of a sample standard deviation over
       ``n_pixels`` pixels). It does not contain the flat-field residual, which is
       invisible inside one ROI, just as on the real bench.

    Parameters
    ----------
    reflectances : Spectra, (n_p, n_wl)
        Reflectance factors of the target's patches; names become ``patches``.
    illuminants : Spectra, (n_i, n_wl)
        Spectral power of each illuminant, already multiplied by its exposure scale
        (see :func:`scale_to_exposure`), in power units such that Eq. 1 gives
        full-scale units.
    sensitivity : Spectra, (3, n_wl)
        True camera sensitivities, rows R, G, B.
    noise
        The noise model; ``None`` gives noise-free responses (clipped at 1, with
        ``saturated`` = 1 where any channel reaches full scale).
    rng
        Random generator or seed (required, so that every simulation is reproducible).

    Returns
    -------
    Responses
        ``rgb`` (n_p, n_i, 3) in full-scale units; ``rgb_std``, ``n_pixels`` and
        ``saturated`` (n_p, n_i) with a noise model, else ``saturated`` only.

    Raises
    ------
    InputError
        If the wavelength grids differ or ``sensitivity`` does not have 3 rows.

    References
    ----------
    The paper, Eq. 1 (image formation), Eq. 2 (flat field) and Eq. 6 (per-patch noise).

    Examples
    --------
    >>> import numpy as np
    >>> from tunespec.core.spectra import Grid, Spectra
    >>> wl = np.array([500.0, 510.0])
    >>> r = Spectra(wl, [[0.5, 0.5]], ("white",))
    >>> i = Spectra(wl, [[0.01, 0.01]], ("LED",))
    >>> s = Spectra(wl, np.ones((3, 2)), ("R", "G", "B"))
    >>> simulate_responses(r, i, s, noise=None, rng=0).rgb
    array([[[0.1, 0.1, 0.1]]])
    """
    check_same_grid(reflectances, illuminants, sensitivity)
    check_rgb_sensitivity(sensitivity)
    gen = _rng(rng)
    c = render_rgb(
        reflectances.values,
        illuminants.values,
        sensitivity.values,
        reflectances.step_nm,
    )
    shape = c.shape[:2]
    if noise is None:
        saturated = np.any(c >= 1.0, axis=2).astype(np.float64)
        return Responses(
            reflectances.names,
            illuminants.names,
            np.minimum(c, 1.0),
            saturated=saturated,
        )
    n = noise.n_pixels
    c = c * (1.0 + noise.flat_field_residual * gen.standard_normal(shape))[..., None]
    sigma_px = noise.pixel_std(c)
    # Mean of the pixels after clipping at full scale: E[min(X, 1)] for
    # X ~ N(c, sigma) is c - sigma phi(z) - (c - 1) Phi(-z) with z = (1 - c) / sigma.
    # sigma_px is 0 only for a dark pixel without read noise: z = +inf, no tail.
    with np.errstate(divide="ignore"):
        z = (1.0 - c) / sigma_px
    tail = ndtr(-z)
    clipped_mean = (
        c - sigma_px * np.exp(-0.5 * z**2) / np.sqrt(2 * np.pi) - (c - 1) * tail
    )
    # Clipped pixels no longer scatter: the spread shrinks with the unclipped
    # fraction (an approximation of the censored normal's variance; exact at 0 and 1).
    spread = sigma_px * np.sqrt(1.0 - tail)
    rgb = clipped_mean + spread / np.sqrt(n) * gen.standard_normal(c.shape)
    saturated = gen.binomial(n, tail.max(axis=2)) / n
    # A sample standard deviation over n pixels scatters like sqrt(chi2(n-1)/(n-1)).
    rgb_std = spread * np.sqrt(gen.chisquare(n - 1, c.shape) / (n - 1))
    return Responses(
        reflectances.names,
        illuminants.names,
        np.minimum(rgb, 1.0),
        rgb_std,
        np.full(shape, float(n)),
        saturated,
    )


def perturb_spd(
    illuminants: Spectra,
    *,
    shift_nm: float = 1.0,
    scale_sigma: float = 0.01,
    jitter_nm: float = 0.0,
    rng: np.random.Generator | int,
) -> Spectra:
    """What a spectroradiometer reports for the true spectra ``illuminants``.

    Models the metering error of the light source's internal spectroradiometer::

        reported_i(l) = (1 + scale_sigma * z_i) * true_i(l - shift_nm - jitter_nm * u_i)

    with ``z_i`` and ``u_i`` standard normal per illuminant. ``shift_nm`` is the
    instrument's wavelength-scale error, the same for every reading (a positive shift
    moves the reported peaks to longer wavelengths); ``jitter_nm`` adds an independent
    per-LED shift; ``scale_sigma`` is the relative error of each LED's reported power.

    Parameters
    ----------
    illuminants : Spectra, (n_i, n_wl)
        The true spectral power distributions. Shift on a fine grid (1 nm) and then
        resample: linear interpolation on a coarse grid also blurs a narrowband LED.
    shift_nm, scale_sigma, jitter_nm
        Error magnitudes, see above.
    rng
        Random generator or seed.

    Returns
    -------
    Spectra
        Same names and grid; values outside the grid are held at the end values.

    References
    ----------
    The paper, Eq. 1 (what the light source's spectroradiometer reports enters it).

    Examples
    --------
    >>> import numpy as np
    >>> from tunespec.core.spectra import Grid, Spectra
    >>> s = Spectra(np.arange(5.0), [[0, 0, 1, 0, 0]], ("LED",))
    >>> perturb_spd(s, shift_nm=1.0, scale_sigma=0.0, rng=0).values
    array([[0., 0., 0., 1., 0.]])
    """
    gen = _rng(rng)
    wl = illuminants.wavelength_nm
    n = len(illuminants)
    shifts = shift_nm + jitter_nm * gen.standard_normal(n)
    scales = 1.0 + scale_sigma * gen.standard_normal(n)
    out = np.stack(
        [
            np.interp(wl - d, wl, v) * a
            for v, d, a in zip(illuminants.values, shifts, scales, strict=True)
        ]
    )
    return illuminants.with_values(out)


def scale_to_exposure(
    reflectances: Spectra,
    illuminants: Spectra,
    sensitivity: Spectra,
    *,
    target: float = 0.8,
    per_illuminant: bool = True,
) -> Spectra:
    """Illuminants scaled as if each capture's exposure had been set for ``target``.

    The exposure (time x power) of each capture is chosen so that the brightest
    patch, in its brightest channel, reaches ``target`` of full scale, as an operator
    (or the capture sequence) sets it per LED. The returned spectra are the
    illuminants multiplied by that exposure factor, which is what the estimators
    take as ``i`` in Eq. 1 (responses are in full-scale units).

    Parameters
    ----------
    reflectances : Spectra, (n_p, n_wl)
    illuminants : Spectra, (n_i, n_wl)
    sensitivity : Spectra, (3, n_wl)
    target
        Fraction of full scale for the brightest response, in (0, 1].
    per_illuminant
        ``True``: one factor per illuminant (exposure set per LED). ``False``: one
        common factor (one fixed exposure for all, as the paper's 6 s), so dim LEDs
        give weak, noisier responses.

    Returns
    -------
    Spectra
        The scaled illuminants, same names and grid.

    Raises
    ------
    InputError
        If the grids differ, ``target`` is out of range, or an illuminant gives no
        response at all.

    Examples
    --------
    >>> import numpy as np
    >>> from tunespec.core.spectra import Grid, Spectra
    >>> wl = np.array([500.0, 510.0])
    >>> r = Spectra(wl, [[1.0, 1.0]], ("white",))
    >>> i = Spectra(wl, [[1.0, 1.0], [2.0, 2.0]], ("a", "b"))
    >>> s = Spectra(wl, np.ones((3, 2)), ("R", "G", "B"))
    >>> scale_to_exposure(r, i, s, target=0.5).values
    array([[0.025, 0.025],
           [0.025, 0.025]])
    """
    check_same_grid(reflectances, illuminants, sensitivity)
    check_rgb_sensitivity(sensitivity)
    if not 0.0 < target <= 1.0:
        raise InputError(f"exposure target {target} must be in (0, 1]")
    c = render_rgb(
        reflectances.values,
        illuminants.values,
        sensitivity.values,
        reflectances.step_nm,
    )
    peak = c.max(axis=(0, 2))
    if np.any(peak <= 0) or not np.all(np.isfinite(peak)):
        dark = [n for n, p in zip(illuminants.names, peak, strict=True) if not p > 0]
        raise InputError(
            f"illuminant(s) {', '.join(dark)} give no response; cannot set exposure",
            path=illuminants.meta.get("source"),
        )
    factor = (
        target / peak if per_illuminant else np.full_like(peak, target / peak.max())
    )
    return illuminants.with_values(illuminants.values * factor[:, None])


def simulate_capture(
    reflectances: Spectra,
    illuminants: Spectra,
    sensitivity: Spectra,
    *,
    grid: Grid | None = None,
    exposure_target: float = 0.8,
    noise: NoiseModel | None = NoiseModel(),
    shift_nm: float = 1.0,
    scale_sigma: float = 0.01,
    rng: np.random.Generator | int,
) -> tuple[Responses, Spectra]:
    """A whole simulated capture: true responses and the spectra the bench reports.

    Chains :func:`scale_to_exposure` (exposure per LED), :func:`simulate_responses`
    (noise, flat-field residual) and :func:`perturb_spd` (metering error). The truth
    is rendered on the inputs' own grid (use a fine one, e.g. 1 nm, so that the
    rendering is close to the continuous integral of Eq. 1); the reported
    illuminants are then resampled onto ``grid``, the working grid of the estimators.

    Parameters
    ----------
    reflectances : Spectra, (n_p, n_wl)
    illuminants : Spectra, (n_i, n_wl)
        True spectral power distributions (relative; the exposure sets the scale).
    sensitivity : Spectra, (3, n_wl)
        True camera sensitivities.
    grid
        Working grid for the reported illuminants (default: the inputs' grid).
    exposure_target
        Brightest response per illuminant, fraction of full scale.
    noise
        Sensor noise model (``None``: noise-free).
    shift_nm, scale_sigma
        Spectroradiometer errors, see :func:`perturb_spd` (0 for exact spectra).
    rng
        Random generator or seed.

    Returns
    -------
    responses : Responses
        (n_p, n_i, 3) in full-scale units.
    reported : Spectra
        The exposure-scaled illuminants as the spectroradiometer reports them, on
        ``grid``: what an estimator is given.
    """
    gen = _rng(rng)
    scaled = scale_to_exposure(
        reflectances, illuminants, sensitivity, target=exposure_target
    )
    responses = simulate_responses(
        reflectances, scaled, sensitivity, noise=noise, rng=gen
    )
    reported = perturb_spd(scaled, shift_nm=shift_nm, scale_sigma=scale_sigma, rng=gen)
    if grid is not None:
        reported = reported.resample(grid, source=illuminants.meta.get("source"))
    return responses, reported
