"""Each target's own prior: how far a measured target reaches beyond the prior set.

The prior reflectances of Eq. 5 (e.g. the ColorChecker SG's 140) span fewer spectra
than the world. :func:`fit_generic_prior` fits, per target, the prior set's
covariance scaled and a generic smooth component (Matern 3/2) to the target's own
responses by maximum evidence; :func:`fit_target_priors` wraps it for an estimate
(:class:`~tunespec.core.wiener.TargetPriors`). The uncertainty's prior-mismatch term
(:mod:`tunespec.core.uncertainty`) and the estimate's per-target prior
(:func:`~tunespec.core.wiener.with_target_priors`) both take it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tunespec.core.responses import Responses
from tunespec.core.wiener import TargetPriors, WienerEstimate, checked_noise_covariance

__all__ = [
    "GENERIC_ALPHAS",
    "GENERIC_LENGTHS_NM",
    "GENERIC_SIGMAS",
    "fit_generic_prior",
    "fit_target_priors",
    "matern32",
]

#: Correlation lengths (nm) tried for the generic prior component (Matern 3/2).
#: Surface reflectances are smooth: a handful of basis functions describe them
#: (L. T. Maloney, "Evaluation of linear models of surface spectral reflectance with
#: small numbers of parameters", JOSA A 3 (1986) 1673-1683), so no shorter scale
#: is offered: structure finer than the LEDs resolve would only be invented.
GENERIC_LENGTHS_NM = (20.0, 40.0, 80.0)
#: Standard deviations tried for it (reflectance units).
GENERIC_SIGMAS = np.concatenate([[0.0], np.logspace(-3.0, np.log10(0.3), 11)])
#: Scales of the prior's own covariance tried per target.
GENERIC_ALPHAS = (1.0, 1.5, 2.0, 3.0, 5.0)
#: Targets whose bordered systems are factorised at once.
_CHUNK = 256
#: Corner of the bordered matrix [[C, y], [y', corner]] whose Cholesky factor gives
#: ``L_C^-1 y`` in :func:`fit_generic_prior`: any value above ``y' C^-1 y`` keeps it
#: positive definite and leaves the factor's other entries as they are.
_BORDER_CORNER = 1e300


def matern32(
    wavelength_nm: NDArray[np.float64], length_nm: float
) -> NDArray[np.float64]:
    """Matern-3/2 correlation matrix of a spectrum on ``wavelength_nm``.

    ``k(d) = (1 + sqrt(3) d / l) exp(-sqrt(3) d / l)`` (Rasmussen & Williams 2006,
    Eq. 4.17): once differentiable curves, as reflectances are.

    Examples
    --------
    >>> import numpy as np
    >>> K = matern32(np.array([400.0, 410.0]), 10.0)
    >>> round(float(K[0, 1]), 4)
    0.4834
    """
    d = (
        np.abs(wavelength_nm[:, None] - wavelength_nm[None, :])
        * np.sqrt(3.0)
        / length_nm
    )
    return (1.0 + d) * np.exp(-d)


def fit_generic_prior(
    F: NDArray[np.float64],
    K: NDArray[np.float64],
    mean: NDArray[np.float64],
    rgb: NDArray[np.float64],
    noise: NDArray[np.float64],
    wavelength_nm: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, NDArray[np.float64]]:
    """How far each measured target reaches beyond the prior.

    The prior reflectances (e.g. the SG's 140) span fewer spectra than the world;
    the error of a Wiener estimate outside that span is what the prior cannot
    predict. For each target ``p`` the prior covariance is taken as
    ``alpha_p^2 K + sigma_p^2 M_l``: the prior's own covariance, scaled for a
    target more extreme than the prior set (a saturated print against a chart),
    plus a Matern-3/2 correlation ``M_l`` (:func:`matern32`) for shapes the prior
    set lacks. ``l`` maximises the marginal likelihood of the measured responses of
    the whole batch, ``c_p - F m ~ N(0, F (alpha_p^2 K + sigma_p^2 M_l) F' + N_p)``,
    and ``(alpha_p, sigma_p)`` that of each target's own responses; a target like
    the prior set keeps ``(1, 0)``. No reference values are used.

    Parameters
    ----------
    F : (3 n_i, n_wl)
    K : (n_wl, n_wl), mean (n_wl,)
    rgb : (n_p, 3 n_i)
    noise : (n_p, 3 n_i, 3 n_i)
        Response covariance of each target (noise and calibration).
    wavelength_nm : (n_wl,)

    Returns
    -------
    alpha, sigma : (n_p,)
    length_nm : float
    chi2 : (n_p,)
        ``y' C^-1 y`` of each target at its most probable ``(alpha, sigma)``: how
        far its responses are from any reflectance Eq. 1 can give
        (:func:`~tunespec.core.plausibility.check_response_consistency`).

    References
    ----------
    D. J. C. MacKay, "Bayesian interpolation" (1992) (maximum evidence);
    Rasmussen and Williams, *Gaussian Processes for Machine Learning* (2006), Eq. 4.17
    (Matern 3/2 kernel).
    """
    y = rgb - F @ mean
    # a target with a non-finite response keeps a NaN likelihood (as a solve with
    # it gave), without making its chunk's bordered factorisation fail
    finite = np.isfinite(y).all(axis=1)
    y_border = np.where(finite[:, None], y, 0.0)
    base = F @ K @ F.T
    n_p, m = rgb.shape
    grid = [(a, sg) for a in GENERIC_ALPHAS for sg in GENERIC_SIGMAS]
    best_total = np.inf
    best = (np.ones(n_p), np.zeros(n_p), GENERIC_LENGTHS_NM[0], np.full(n_p, np.nan))
    for length in GENERIC_LENGTHS_NM:
        FMF = F @ matern32(wavelength_nm, length) @ F.T
        nll = np.full((len(grid), n_p), np.inf)
        chi2 = np.full((len(grid), n_p), np.nan)
        for j, (alpha, sigma) in enumerate(grid):
            for lo in range(0, n_p, _CHUNK):
                hi = min(lo + _CHUNK, n_p)
                # C bordered by y: the Cholesky factor's last row is then
                # z = L_C^-1 y (the forward substitution inside the factorisation,
                # half the cost of a separate solve); the corner only has to keep
                # the bordered matrix positive definite and does not enter z
                aug = np.empty((hi - lo, m + 1, m + 1))
                C = aug[:, :m, :m]
                np.multiply(alpha**2, base[None], out=C)
                C += sigma**2 * FMF[None]
                C += noise[lo:hi]
                aug[:, m, :m] = y_border[lo:hi]
                aug[:, :m, m] = y_border[lo:hi]
                aug[:, m, m] = _BORDER_CORNER
                try:
                    La = np.linalg.cholesky(aug)
                except np.linalg.LinAlgError:
                    continue
                z = La[:, m, :m]
                chi2[j, lo:hi] = np.where(finite[lo:hi], np.sum(z**2, axis=1), np.nan)
                nll[j, lo:hi] = np.where(
                    finite[lo:hi],
                    chi2[j, lo:hi]
                    + 2.0
                    * np.sum(
                        np.log(np.diagonal(La[:, :m, :m], axis1=1, axis2=2)), axis=1
                    ),
                    np.nan,
                )
        # posterior over the (alpha, sigma) grid (flat prior on it): the error
        # covariance is linear in alpha^2 and sigma^2, so their posterior means
        # carry the hyper-parameters' own uncertainty (a point estimate would not)
        low = np.min(nll, axis=0)
        post = np.exp(-0.5 * (nll - low[None]))
        evidence = low - 2.0 * np.log(np.sum(post, axis=0) / len(grid))
        total = float(np.sum(evidence))
        if total < best_total:
            post /= np.sum(post, axis=0, keepdims=True)
            g = np.array(grid)
            best_total = total
            best = (
                np.sqrt(post.T @ g[:, 0] ** 2),
                np.sqrt(post.T @ g[:, 1] ** 2),
                float(length),
                chi2[
                    np.argmin(np.where(np.isnan(nll), np.inf, nll), axis=0),
                    np.arange(n_p),
                ],
            )
    return best


def fit_target_priors(
    wiener: WienerEstimate,
    responses: Responses,
    rgb: NDArray[np.float64],
    noise: NDArray[np.float64],
) -> TargetPriors:
    """:func:`fit_generic_prior` on the estimate's responses ``rgb`` (n_p, m) with
    their error model ``noise``, saturated responses left out as the estimate leaves
    them: each target's prior, with its chi-square per response."""
    F, K, mean = wiener.lighting, wiener.prior_covariance, wiener.prior_mean
    assert F is not None and K is not None and mean is not None
    wl = wiener.reflectance.wavelength_nm
    noise_fit = checked_noise_covariance(noise, responses, F.shape[0])
    alpha, sigma, length, chi2 = fit_generic_prior(F, K, mean, rgb, noise_fit, wl)
    dof = np.sum(np.isfinite(rgb) & ~np.repeat(responses.clipped, 3, axis=1), axis=1)
    return TargetPriors(
        alpha, sigma, matern32(wl, length), length, chi2 / np.maximum(dof, 1)
    )
