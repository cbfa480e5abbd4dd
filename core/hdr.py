"""HDR: exposure (or LED intensity) brackets merged into one linear image.

A specular lobe is orders of magnitude brighter than the diffuse body of a sample, so
at the geometries where it matters one exposure cannot hold both. The brackets
``k = 1..K`` of one scene, with relative exposures ``t_k`` (shutter time x LED
intensity x gain, relative to the reference exposure), are merged pixel by pixel into
the response at the reference exposure.

For a linear camera each unclipped, dark-subtracted value ``c_k`` (full-scale units)
estimates ``x = c_k / t_k`` with variance ``sigma^2(t_k x) / t_k^2``, where
``sigma^2(c) = c / g + r^2`` is the photon + read noise of the sensor (``g`` the full
well in electrons, ``r`` the read noise in full-scale units; :class:`NoiseModel`).
The minimum-variance unbiased combination weights each bracket by the inverse of that
variance; the variances are evaluated at the *merged* estimate, not at each noisy
``c_k`` (weights from the noisy values bias the merge low), iterated twice from the
longest unclipped bracket (Granados et al. 2010; Hasinoff et al. 2010). A value at or
above ``saturation`` of full scale carries no information and gets weight 0; a pixel
clipped in every bracket is flagged saturated and keeps the lower bound
``saturation / t_min``.

The merged variance ``1 / sum_k w_k`` is what Eq. 6 needs: :func:`hdr_patch_responses`
turns merged ROI pixels into :class:`~tunespec.core.responses.Responses` whose
``rgb_std`` is the per-pixel merged noise and whose ``saturated`` is the fraction of
pixels clipped in every bracket, so the Wiener estimate (Eq. 5-6) weights them as it
weights a single exposure (and removes the saturated ones).

References
----------
M. Granados, B. Ajdin, M. Wand, C. Theobalt, H.-P. Seidel, H. P. A. Lensch, "Optimal
HDR reconstruction with linear digital cameras", CVPR 2010,
doi:10.1109/CVPR.2010.5540208; S. W. Hasinoff, F. Durand, W. T. Freeman,
"Noise-optimal capture for high dynamic range photography", CVPR 2010,
doi:10.1109/CVPR.2010.5540167; Trichromatic Reflectance Capture Using a Tunable
Light Source (the paper in ``shared/reference``), Eq. 6.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError
from tunespec.core.excess import clustered_slope
from tunespec.core.responses import Responses
from tunespec.core.simulate import NoiseModel

__all__ = [
    "DEFAULT_SATURATION",
    "HdrImage",
    "fit_bracket_bend",
    "hdr_patch_responses",
    "merge_brackets",
]

#: Fraction of full scale from which a value counts as clipped (the white level of a
#: raw file is where the sensor clips; highlights compress a little below it).
DEFAULT_SATURATION = 0.98
#: The sensor model used when none is given (the 5D Mark III at ISO 100).
DEFAULT_NOISE = NoiseModel()
#: Re-evaluations of the noise model at the merged estimate.
_ITERATIONS = 2
#: A bracket counts in :func:`fit_bracket_bend` from this signal-to-noise ratio: the
#: log of a noisier value is biased low by about ``1 / (2 SNR^2)`` (at 20, 0.13 %:
#: a bend of 0.0006 over brackets a factor 8 apart).
BRACKET_MIN_SNR = 20.0


@dataclass(frozen=True, eq=False)
class HdrImage:
    """Result of :func:`merge_brackets`.

    Parameters
    ----------
    value : (...)
        Merged linear response at the reference exposure (full-scale units of the
        reference; may exceed 1).
    variance : (...)
        Its noise variance (per pixel).
    saturated : (...) bool
        Clipped in every bracket: ``value`` is only a lower bound.
    n_used : (...) int
        Brackets that contributed.
    """

    value: NDArray[np.float64]
    variance: NDArray[np.float64]
    saturated: NDArray[np.bool_]
    n_used: NDArray[np.int64]

    @property
    def std(self) -> NDArray[np.float64]:
        """Noise standard deviation per pixel."""
        return np.sqrt(self.variance)


def _check(
    frames: ArrayLike, exposures: Sequence[float], saturation: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    c = np.asarray(frames, dtype=np.float64)
    t = np.asarray(exposures, dtype=np.float64)
    if t.ndim != 1 or t.size < 1 or c.shape[:1] != t.shape:
        raise InputError(
            f"{c.shape[0] if c.ndim else 0} brackets but {t.size} exposures: "
            "one relative exposure per bracket"
        )
    if not np.all(np.isfinite(t) & (t > 0)):
        raise InputError("exposures must be finite and positive")
    if not np.all(np.isfinite(c)):
        raise InputError("bracket values must be finite (NaN or inf found)")
    if not 0.0 < saturation <= 1.0:
        raise InputError(f"saturation {saturation!r}: expected a fraction in (0, 1]")
    return c, t


def merge_brackets(
    frames: ArrayLike,
    exposures: Sequence[float],
    *,
    noise: NoiseModel = DEFAULT_NOISE,
    saturation: float = DEFAULT_SATURATION,
    dark_variance: ArrayLike = 0.0,
) -> HdrImage:
    """Merge dark-subtracted exposure brackets into one linear image with its noise.

    Parameters
    ----------
    frames : (K, ...)
        The brackets, dark-subtracted, in full-scale units (1.0 = the white level), any
        shape after the first axis (pixels, planes, ROI values).
    exposures : K values
        Relative exposure of each bracket (time x intensity x gain) against the
        reference exposure 1; the result is in the reference's full-scale units.
    noise
        Sensor model: ``full_well_e`` and ``read_noise_e`` (``n_pixels`` and
        ``flat_field_residual`` are not used here).
    saturation
        Values at or above this fraction of full scale count as clipped.
    dark_variance : broadcastable to ``frames``
        Variance the dark subtraction adds (full-scale units^2), e.g. the read noise
        of a dark frame over the number of darks averaged.

    Returns
    -------
    HdrImage

    Raises
    ------
    InputError
        Mismatched brackets and exposures, non-finite values, bad saturation.

    References
    ----------
    Granados et al. (2010); Hasinoff et al. (2010); the paper, Eq. 6.
    """
    c, t = _check(frames, exposures, saturation)
    tt = t.reshape((-1,) + (1,) * (c.ndim - 1))
    ok = c < saturation
    dark_var = np.asarray(dark_variance, dtype=np.float64)
    x_k = c / tt
    # start: the longest unclipped bracket of every pixel
    order = np.argsort(-t)
    x = np.full(c.shape[1:], np.nan)
    for k in order[::-1]:
        x = np.where(ok[k], x_k[k], x)
    for _ in range(_ITERATIONS):
        signal = tt * np.nan_to_num(x, nan=0.0)
        var_k = (noise.pixel_std(signal) ** 2 + dark_var) / tt**2
        w = np.where(ok, 1.0 / var_k, 0.0)
        wsum = w.sum(axis=0)
        safe = np.where(wsum > 0, wsum, 1.0)
        x = np.where(wsum > 0, (w * x_k).sum(axis=0) / safe, np.nan)
    saturated = ~ok.any(axis=0)
    value = np.where(saturated, saturation / t.min(), x)
    variance = np.where(saturated, np.inf, 1.0 / np.where(wsum > 0, wsum, 1.0))
    return HdrImage(value, variance, saturated, ok.sum(axis=0))


def fit_bracket_bend(
    frames: ArrayLike,
    exposures: Sequence[float],
    *,
    noise: NoiseModel = DEFAULT_NOISE,
    saturation: float = DEFAULT_SATURATION,
    dark_variance: ArrayLike = 0.0,
) -> tuple[float, float]:
    """The bend ``gamma`` of a sensor's response ``c = (t x)^(1 + gamma)`` that
    brackets of one scene show, and its standard error.

    :func:`merge_brackets` divides each bracket by its relative exposure ``t_k``:
    right where the response is linear. Per pixel ``ln c_k = (1 + gamma) ln t_k +
    const``, so the slope of ``ln c_k - ln t_k`` on ``ln t_k`` (one level per
    pixel, a nuisance) is ``gamma``. Weighted least squares over the brackets each
    pixel has unclipped and at :data:`BRACKET_MIN_SNR` or more (weights ``c^2 /
    var(c)``, the noise of ``ln c``), the standard error clustered by pixel; ``(0,
    inf)`` where no pixel has two such brackets. A tone curve, a black level left
    in, exposures not as recorded: each bends it. Arguments as :func:`merge_brackets`.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(0).uniform(0.01, 0.9, (3, 500))
    >>> t = [1.0, 1 / 8, 1 / 64]
    >>> frames = np.stack([(tk * x) ** 1.1 for tk in t])
    >>> round(fit_bracket_bend(frames, t)[0], 3)
    0.1
    """
    c, t = _check(frames, exposures, saturation)
    sigma2 = noise.pixel_std(c) ** 2 + np.asarray(dark_variance, dtype=np.float64)
    c, sigma2 = c.reshape(len(t), -1), sigma2.reshape(len(t), -1)
    ok = (c < saturation) & (c > BRACKET_MIN_SNR * np.sqrt(sigma2))
    ok &= np.sum(ok, axis=0) >= 2
    if not np.any(ok):
        return 0.0, float("inf")
    w = np.where(ok, c**2 / sigma2, 0.0)
    lt = np.broadcast_to(np.log(t)[:, None], c.shape)
    y = np.log(np.where(ok, c, 1.0)) - lt
    wsum = np.where(ok.any(axis=0), w.sum(axis=0), 1.0)

    def centred(v: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.where(ok, v - np.sum(w * v, axis=0) / wsum, 0.0)

    return clustered_slope(centred(lt), centred(y), w, cluster_axis=0)


def hdr_patch_responses(
    merged: Sequence[Sequence[HdrImage]],
    patches: Sequence[str],
    illuminants: Sequence[str],
) -> Responses:
    """Responses of patches from their merged ROI pixels, ready for Eq. 5-6.

    Parameters
    ----------
    merged
        ``merged[p][i]``: the :class:`HdrImage` of patch ``p``'s ROI under illuminant
        ``i``, of shape (3, n_pixels) (R, G, B planes).
    patches, illuminants
        Names.

    Returns
    -------
    Responses
        ``rgb``: mean of the unsaturated merged pixels (of all pixels when every one is
        clipped); ``rgb_std``: the per-pixel noise, ``sqrt`` of the mean merged
        variance of those pixels, as Eq. 6 uses the per-pixel std; ``n_pixels``: the
        pixels averaged; ``saturated``: the fraction of pixels clipped in every
        bracket (any plane). The Wiener estimator gives a saturated patch a variance
        that removes it.
    """
    n_p, n_i = len(patches), len(illuminants)
    rgb = np.zeros((n_p, n_i, 3))
    std = np.zeros((n_p, n_i, 3))
    n_px = np.zeros((n_p, n_i))
    sat = np.zeros((n_p, n_i))
    if len(merged) != n_p or any(len(row) != n_i for row in merged):
        raise InputError(f"expected {n_p} x {n_i} merged ROIs")
    for p, row in enumerate(merged):
        for i, img in enumerate(row):
            if img.value.ndim != 2 or img.value.shape[0] != 3:
                raise InputError(
                    f"patch {patches[p]!r}: expected (3, n_pixels), got {img.value.shape}"
                )
            clipped = img.saturated.any(axis=0)
            use = ~clipped if (~clipped).any() else np.ones_like(clipped)
            rgb[p, i] = img.value[:, use].mean(axis=1)
            var = np.where(np.isfinite(img.variance), img.variance, 0.0)
            std[p, i] = np.sqrt(var[:, use].mean(axis=1))
            n_px[p, i] = use.sum()
            sat[p, i] = clipped.mean()
    return Responses(tuple(patches), tuple(illuminants), rgb, std, n_px, sat)
