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
from tunespec.core.responses import Responses
from tunespec.core.simulate import NoiseModel

__all__ = ["DEFAULT_SATURATION", "HdrImage", "hdr_patch_responses", "merge_brackets"]

#: Fraction of full scale from which a value counts as clipped (the white level of a
#: raw file is where the sensor clips; highlights compress a little below it).
DEFAULT_SATURATION = 0.98
#: The sensor model used when none is given (the 5D Mark III at ISO 100).
DEFAULT_NOISE = NoiseModel()
#: Re-evaluations of the noise model at the merged estimate.
_ITERATIONS = 2


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
    gain = 1.0 / noise.full_well_e
    read_var = (noise.read_noise_e / noise.full_well_e) ** 2 + np.asarray(
        dark_variance, dtype=np.float64
    )
    x_k = c / tt
    # start: the longest unclipped bracket of every pixel
    order = np.argsort(-t)
    x = np.full(c.shape[1:], np.nan)
    for k in order[::-1]:
        x = np.where(ok[k], x_k[k], x)
    for _ in range(_ITERATIONS):
        signal = np.maximum(tt * np.nan_to_num(x, nan=0.0), 0.0)
        var_k = (signal * gain + read_var) / tt**2
        w = np.where(ok, 1.0 / var_k, 0.0)
        wsum = w.sum(axis=0)
        safe = np.where(wsum > 0, wsum, 1.0)
        x = np.where(wsum > 0, (w * x_k).sum(axis=0) / safe, np.nan)
    saturated = ~ok.any(axis=0)
    value = np.where(saturated, saturation / t.min(), x)
    variance = np.where(saturated, np.inf, 1.0 / np.where(wsum > 0, wsum, 1.0))
    return HdrImage(value, variance, saturated, ok.sum(axis=0))


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
