"""Wiener estimation of spectral reflectance from multi-illuminant RGB, Eq. 5 and 6.

A patch imaged under ``n_i`` illuminants gives the ``3 n_i`` responses
``c = F r + e`` (Eq. 1 stacked, :func:`~tunespec.core.forward_model.lighting_matrix`).
With a prior on the reflectances (mean ``m``, covariance ``K``, from a training set such
as the ColorChecker SG) and a noise covariance ``K_e`` the linear minimum mean square
error estimate is (Eq. 5)::

    r = m + K F^T (F K F^T + K_e)^-1 (c - F m)

``m = 0`` and ``K = E[r r^T]`` give the classic uncentred form of the paper. The noise
covariance is diagonal and computed for each patch from the per-pixel standard
deviations of its responses (Eq. 6), which the paper reports as the step that
"dramatically improves the reconstruction results".

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source: Setup, Characterization
and Reflectance Estimation (``shared/reference/paper-trichromatic-reflectance-capture``),
Eq. 1, 5 and 6.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import (
    InputError,
    SingularSystemError,
    check_names,
    shown_names,
)
from tunespec.core.forward_model import lighting_matrix
from tunespec.core.responses import CHANNELS, Responses
from tunespec.core.spectra import (
    CALIBRATION_MAX_STEP_NM,
    Grid,
    Spectra,
    spline_matrix,
)

__all__ = [
    "NOISE_SOURCES",
    "RIDGE_RELATIVE",
    "TargetPriors",
    "WienerEstimate",
    "checked_noise_covariance",
    "integrated_lighting_matrix",
    "integration_grid",
    "on_integration_grid",
    "prior_gram",
    "prior_on_support",
    "reflectance_basis",
    "sample_indices",
    "solve_with_noise",
    "support_grid",
    "wiener_reflectance",
    "with_target_priors",
]

#: Accepted values of ``noise_from``: the per-pixel standard deviation as Eq. 6 uses it,
#: or the standard error of the ROI mean (per-pixel variance / ``n_pixels``).
NOISE_SOURCES = ("pixel", "mean")

#: Relative noise-variance floor, as a fraction of the mean diagonal of ``F K F^T``.
#: Noise-free (simulated) responses give ``K_e = 0`` and ``F K F^T`` alone is
#: singular: its rank is at most rank(K), 36 for the ColorChecker SG at 5 nm, against
#: 66 rows for 22 illuminants (condition number 1e16). Flooring the noise variances
#: at this level is a tiny ridge that makes the system solvable; on responses in units
#: of full scale it corresponds to a noise std of about 1e-6, well under the 16-bit
#: quantisation step, so measured (noisy) data never reach it.
RIDGE_RELATIVE = 1e-10
#: Noise variance given to saturated responses (full scale^2): effectively ignored.
SATURATED_VARIANCE = 1e6

_WL_TOL_NM = 1e-6
#: Relative spread below which a prior counts as having no variance at all.
_PRIOR_VAR_REL = 1e-20
#: Patches solved per batched LAPACK call; bounds the (chunk, 3 n_i, 1 + n_wl) work
#: arrays (about 10 MB each for 22 illuminants at 5 nm) for images with many pixels.
_CHUNK = 256


@dataclass(frozen=True, eq=False)
class TargetPriors:
    """Each target's own prior covariance, ``alpha_p^2 K + sigma_p^2 M``: the prior
    set's ``K`` scaled, plus a generic component ``M`` for shapes the prior set
    lacks, as :func:`tunespec.core.target_prior.fit_generic_prior` fits them to the
    target's responses (:func:`tunespec.core.target_prior.fit_target_priors`).

    ``alpha``, ``sigma`` (n_p,); ``generic`` ``M`` (n_wl, n_wl) and ``length_nm``
    its correlation length; ``chi2_per_response`` (n_p,) each target's chi-square
    per response at its most probable prior.
    """

    alpha: NDArray[np.float64]
    sigma: NDArray[np.float64]
    generic: NDArray[np.float64]
    length_nm: float
    chi2_per_response: NDArray[np.float64]

    def scaled(self, K: NDArray[np.float64], rows: slice) -> NDArray[np.float64]:
        """``alpha_p^2 K`` of the targets ``rows``, (k, n_wl, n_wl): the prior set's
        covariance scaled to each, the prior Eq. 5 takes (:func:`with_target_priors`)."""
        return self.alpha[rows, None, None] ** 2 * K[None]

    def covariance(self, K: NDArray[np.float64], rows: slice) -> NDArray[np.float64]:
        """The whole prior covariances of the targets ``rows``, (k, n_wl, n_wl)."""
        generic = self.sigma[rows, None, None] ** 2 * self.generic[None]
        return self.scaled(K, rows) + generic


@dataclass(frozen=True, eq=False)
class WienerEstimate:
    """Result of :func:`wiener_reflectance`.

    Parameters
    ----------
    reflectance : Spectra, (n_p, n_wl)
        Estimated reflectance factors, one spectrum per patch, named by patch and on
        the prior's wavelength grid; limited to [0, 1] if ``clip`` was set.
    clipped : tuple of str
        Patches with at least one sample that was clipped to [0, 1].
    n_clipped_samples : int
        Number of (patch, wavelength) samples that were clipped.
    variance : (n_p, n_wl)
        Diagonal of the estimation error covariance ``K - K F^T A^-1 F K`` with
        ``A = F K F^T + K_e`` (the posterior covariance under the Gaussian prior),
        i.e. the squared uncertainty of each reflectance sample. It describes the
        unclipped estimate and is only as good as the prior and ``K_e``.
    noise_variance : (n_p, n_i, 3)
        The diagonal of ``K_e`` that was used (Eq. 6, or of ``noise_covariance``),
        after the ridge floor.
    ridge : float
        The noise-variance floor ``RIDGE_RELATIVE * mean(diag(F K F^T))`` applied to
        entries of ``K_e`` below it, or 0.0 when no entry needed it.
    params : dict
        The settings used: ``noise`` (``"patch"`` or ``"global"``), ``noise_from``,
        ``center_prior``, ``clip``, ``n_prior``, ``n_ridged`` (entries floored).
    lighting : (3 n_i, n_wl)
        ``F`` of Eq. 5 as used (:func:`integrated_lighting_matrix`).
    prior_mean, prior_covariance : (n_wl,), (n_wl, n_wl)
        ``m`` and ``K`` of the prior as used.
    noise_covariance : (n_p, 3 n_i, 3 n_i) or None
        The whole ``K_e`` of each patch where one was given (its diagonal is
        ``noise_variance``), else None (diagonal, Eq. 6).
    target_priors : TargetPriors or None
        Each target's own prior where Eq. 5 used one (:func:`with_target_priors`),
        else None (``prior_covariance`` for all).
    support : WienerEstimate or None
        Where this estimate is the part of a wider one on the samples it is reported
        on (:meth:`restricted`): the estimate on every sample Eq. 5 solved for
        (:func:`support_grid`); the other fields are its rows and columns of those
        samples. None: Eq. 5 solved for these samples alone.
    """

    reflectance: Spectra
    clipped: tuple[str, ...]
    n_clipped_samples: int
    variance: NDArray[np.float64]
    noise_variance: NDArray[np.float64]
    ridge: float
    params: dict[str, object] = field(default_factory=dict)
    lighting: NDArray[np.float64] | None = None
    prior_mean: NDArray[np.float64] | None = None
    prior_covariance: NDArray[np.float64] | None = None
    noise_covariance: NDArray[np.float64] | None = None
    target_priors: TargetPriors | None = None
    support: WienerEstimate | None = None

    def restricted(self, grid: Grid) -> WienerEstimate:
        """This estimate on the samples of ``grid`` (its own, or some of them: the
        reported range of :func:`support_grid`'s samples), the whole kept as
        ``support``. The clipping report counts the samples kept (a clipped sample
        is at 0 or 1 exactly)."""
        wl = self.reflectance.wavelength_nm
        keep = sample_indices(wl, grid.wavelength_nm)
        if keep.size == wl.size:
            return self
        refl = self.reflectance
        values = refl.values[:, keep]
        out = (values <= 0.0) | (values >= 1.0)
        if not self.params.get("clip", True):
            out[:] = False
        F, K, mean, tp = (
            self.lighting, self.prior_covariance, self.prior_mean, self.target_priors,
        )  # fmt: skip
        return replace(
            self,
            reflectance=Spectra(wl[keep], values, refl.names, refl.meta),
            clipped=tuple(refl.names[i] for i in np.flatnonzero(out.any(axis=1))),
            n_clipped_samples=int(np.count_nonzero(out)),
            variance=self.variance[:, keep],
            lighting=None if F is None else F[:, keep],
            prior_mean=None if mean is None else mean[keep],
            prior_covariance=None if K is None else K[np.ix_(keep, keep)],
            target_priors=None
            if tp is None
            else replace(tp, generic=tp.generic[np.ix_(keep, keep)]),
            support=self,
        )

    @property
    def k_e(self) -> NDArray[np.float64]:
        """``K_e`` as Eq. 5 used it: each patch's diagonal (n_p, 3 n_i), or its whole
        covariance (n_p, 3 n_i, 3 n_i) where one was given."""
        if self.noise_covariance is not None:
            return self.noise_covariance
        return self.noise_variance.reshape(self.noise_variance.shape[0], -1)

    @property
    def std(self) -> NDArray[np.float64]:
        """Posterior standard deviation of each reflectance sample, (n_p, n_wl)."""
        return np.sqrt(self.variance)


def wiener_reflectance(
    responses: Responses,
    illuminants: Spectra,
    sensitivity: Spectra,
    prior: Spectra | None = None,
    *,
    noise_std: float | None = None,
    noise_from: Literal["pixel", "mean"] = "pixel",
    center_prior: bool = True,
    clip: bool = True,
    noise_covariance: NDArray[np.float64] | None = None,
) -> WienerEstimate:
    """Estimate reflectances from multi-illuminant RGB responses by Wiener estimation.

    Implements Eq. 5 with the patch-wise noise covariance of Eq. 6 and solves all
    patches in batched linear solves (no inverse is formed).

    Parameters
    ----------
    responses : Responses
        ``rgb`` (n_p, n_i, 3) in units of full scale; ``rgb_std`` (n_p, n_i, 3), the
        per-pixel standard deviation in the ROI, gives ``K_e`` per patch;
        ``n_pixels`` (n_p, n_i) is needed for ``noise_from="mean"``.
    illuminants : Spectra, (>= n_i, n_wl)
        Spectral power of the illuminants, named as ``responses.illuminants`` (extra
        spectra are ignored); the same power scale as used for ``sensitivity``.
    sensitivity : Spectra, (3, n_wl)
        Camera sensitivities named ``R``, ``G``, ``B`` on the illuminants' grid, in
        response per (power unit x nm) so that
        :func:`~tunespec.core.forward_model.render_rgb` predicts ``responses``.
    prior : Spectra, (n_train, n_est), optional
        Training reflectances for the prior; default the ColorChecker SG (140 patches,
        as the paper) on the illuminants' grid. Its grid is the estimation grid: it
        may be coarser than the illuminants' (within their range), Eq. 1 is then
        integrated on theirs (:func:`integrated_lighting_matrix`).
    noise_std : float, optional
        One noise standard deviation (full-scale units) for every response of every
        patch. Given, it overrides ``responses.rgb_std`` (a single global ``K_e``);
        it is required when the responses carry no standard deviations.
    noise_from : {"pixel", "mean"}
        ``"pixel"`` uses the per-pixel variance as Eq. 6 does (which over-states the
        noise of an ROI mean and so regularises more); ``"mean"`` divides it by
        ``responses.n_pixels``, the variance of the ROI mean.
    center_prior : bool
        True: ``m`` is the prior mean and ``K`` the covariance about it (ddof=1).
        False: ``m = 0`` and ``K = E[r r^T]``, the uncentred correlation matrix of the
        classic Wiener estimate.
    clip : bool
        Limit the estimate to the physical range [0, 1].
    noise_covariance : (n_p, 3 n_i, 3 n_i), optional
        Each patch's whole response error covariance, stacked illuminant-major (the
        error model of :func:`tunespec.core.uncertainty.wiener_with_uncertainty`):
        used as ``K_e`` instead of Eq. 6's diagonal (saturated responses are still
        removed, small variances still floored).

    Returns
    -------
    WienerEstimate
        Reflectances named by patch, clipping report, posterior variance.

    Raises
    ------
    InputError
        Illuminants or channels missing (naming the spectra's ``meta["source"]``),
        wavelength grids that differ, non-finite values, negative standard deviations,
        no noise level, fewer than 2 prior spectra for a centred prior.
    SingularSystemError
        When ``F K F^T`` is zero (dark illuminants, zero sensitivity or a prior without
        variance) or the solve fails.

    Notes
    -----
    ``F K F^T + K_e`` is solved rather than inverted. Noise variances below
    ``RIDGE_RELATIVE * mean(diag(F K F^T))`` are raised to that floor (see
    :data:`RIDGE_RELATIVE`) so noise-free responses remain solvable; the estimate then
    tends to the noise-free Wiener limit.

    References
    ----------
    Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
    ``shared/reference``), Eq. 5 and 6; H. Haneishi et al., "System design for
    accurately estimating the spectral reflectance of art paintings", Applied Optics
    39(35), 6621-6632 (2000), doi:10.1364/AO.39.006621 (Wiener estimation).

    Examples
    --------
    >>> import numpy as np
    >>> from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
    >>> from tunespec.core.forward_model import render_rgb
    >>> led, cam, sg = load_led_set(), load_camera(), load_colorchecker_sg()
    >>> rgb = render_rgb(sg.values[:2], led.values, cam.values, led.step_nm) / 40
    >>> resp = Responses(sg.names[:2], led.names, rgb)
    >>> est = wiener_reflectance(resp, led.with_values(led.values / 40), cam, sg,
    ...                          noise_std=1e-4)
    >>> bool(np.abs(est.reflectance.values - sg.values[:2]).max() < 0.02)
    True
    """
    wl, F, mean, K, prior = _wiener_system(
        responses, illuminants, sensitivity, prior, noise_from, center_prior
    )
    m_rows = F.shape[0]
    FK, G, scale = _gram(F, K)
    patches, n_p = responses.patches, len(responses.patches)
    var, noise, ridge_floor, n_ridged = _k_e(
        responses, noise_std, noise_from, noise_covariance, m_rows, scale
    )
    resid, shared = responses.rgb.reshape(n_p, m_rows) - F @ mean, (G, FK, np.diag(K))
    est, post_var = _solve_patchwise(lambda _: shared, mean, resid, noise, patches)
    est, clipped, n_clipped = _clip_estimate(est, patches, clip)
    kind = "covariance" if noise_covariance is not None else "patch"
    params = {"noise": "global" if noise_std is not None else kind,
              "noise_from": noise_from, "center_prior": center_prior, "clip": clip,
              "n_prior": len(prior), "n_ridged": n_ridged}  # fmt: skip
    return WienerEstimate(
        reflectance=Spectra(wl, est, patches, {"source": "wiener_reflectance (Eq. 5)"}),
        clipped=clipped, n_clipped_samples=n_clipped, variance=post_var,
        noise_variance=var, ridge=ridge_floor if n_ridged else 0.0, params=params,
        lighting=F, prior_mean=mean, prior_covariance=K,
        noise_covariance=noise if noise_covariance is not None else None,
    )  # fmt: skip


def with_target_priors(
    estimate: WienerEstimate, responses: Responses, priors: TargetPriors
) -> WienerEstimate:
    """Eq. 5 again, each target with the prior set's covariance scaled to it
    (``alpha_p^2 K``, :meth:`TargetPriors.scaled`; the ``K_e``, ``F`` and prior mean
    ``estimate`` used).

    A chart spans fewer spectra than the targets, and its covariance is too
    narrow for a target more extreme than its patches (a saturated print): the
    target's responses say by how much (``alpha_p`` by maximum evidence,
    :func:`tunespec.core.target_prior.fit_generic_prior`), and Eq. 5 with that prior
    is the linear minimum-variance estimate under it (Kay, *Fundamentals of
    Statistical Signal Processing I*, 1993, ch. 12). On
    ``benchmarks/generalisation.py`` under issue 23's conditions it lowers the mean
    CIEDE2000 of the Foveon-type camera 0.137 -> 0.130 and leaves the others within
    0.003 (docs/validation.md). The generic component (``sigma_p``) stays in the
    uncertainty only: in Eq. 5 it let the demo's precise sensor follow its
    calibration's model errors (ripples of +-0.018 on a flat white).
    """
    F, K, mean = estimate.lighting, estimate.prior_covariance, estimate.prior_mean
    assert F is not None and K is not None and mean is not None
    patches, n_p = responses.patches, len(responses.patches)

    def system(rows: slice) -> tuple[NDArray[np.float64], ...]:
        Kp = priors.scaled(K, rows)
        FK, G = prior_gram(F, Kp)
        return G, FK, np.diagonal(Kp, axis1=1, axis2=2)

    resid = responses.rgb.reshape(n_p, F.shape[0]) - F @ mean
    est, post_var = _solve_patchwise(system, mean, resid, estimate.k_e, patches)
    est, clipped, n_clipped = _clip_estimate(
        est, patches, bool(estimate.params.get("clip", True))
    )
    refl = estimate.reflectance
    return replace(
        estimate,
        reflectance=Spectra(refl.wavelength_nm, est, patches, refl.meta),
        clipped=clipped,
        n_clipped_samples=n_clipped,
        variance=post_var,
        params={**estimate.params, "prior": "per target"},
        target_priors=priors,
    )


def _k_e(
    responses: Responses,
    noise_std: float | None,
    noise_from: str,
    noise_covariance: NDArray[np.float64] | None,
    m_rows: int,
    scale: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, int]:
    """``K_e`` of every patch as Eq. 5 uses it: its diagonal (n_p, n_i, 3) floored
    (:func:`_ridged`), the system's noise ((n_p, m) diagonal, or (n_p, m, m) whole
    with that diagonal), the floor and how many entries it raised."""
    n_p = len(responses.patches)
    if noise_covariance is None:
        var = _noise_variance(responses, noise_std, noise_from)
    else:
        full = checked_noise_covariance(noise_covariance, responses, m_rows)
        var = np.diagonal(full, axis1=1, axis2=2).reshape(responses.rgb.shape)
    var, ridge_floor, n_ridged = _ridged(var, scale)
    noise = var.reshape(n_p, m_rows)
    if noise_covariance is not None:
        idx = np.arange(m_rows)
        full[:, idx, idx] = noise
        noise = full
    return var, noise, ridge_floor, n_ridged


def checked_noise_covariance(
    cov: NDArray[np.float64], responses: Responses, m_rows: int
) -> NDArray[np.float64]:
    """A copy of a whole ``K_e`` per patch, its shape and values checked, with
    saturated responses removed as Eq. 6 removes them (:data:`SATURATED_VARIANCE`)."""
    n_p = len(responses.patches)
    full = np.array(cov, dtype=np.float64)
    if full.shape != (n_p, m_rows, m_rows) or not np.all(np.isfinite(full)):
        raise InputError(
            f"noise covariance: expected finite ({n_p}, {m_rows}, {m_rows}) "
            f"values, got shape {full.shape}"
        )
    rows = np.repeat(responses.clipped, 3, axis=1)  # (n_p, m_rows)
    full[rows[:, :, None] | rows[:, None, :]] = 0.0
    p, r = np.nonzero(rows)
    full[p, r, r] = SATURATED_VARIANCE
    return full


def _default_prior(wl: NDArray[np.float64]) -> Spectra:
    """The default prior of :func:`wiener_reflectance`: the ColorChecker SG on ``wl``."""
    from tunespec.core.datasets import load_colorchecker_sg

    return load_colorchecker_sg(Grid(float(wl[0]), float(wl[-1]), _step(wl)))


def _gram(
    F: NDArray[np.float64], K: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """``F K``, ``G = F K F^T`` of Eq. 5 (exactly symmetric) and its mean diagonal."""
    FK, G = prior_gram(F, K)
    scale = float(np.trace(G)) / F.shape[0]
    if not (np.isfinite(scale) and scale > 0.0):
        raise SingularSystemError(
            "F K F^T is zero: the illuminants are dark, the sensitivity is zero or "
            "the prior varies only where the camera sees nothing"
        )
    return FK, G, scale


def prior_gram(
    F: NDArray[np.float64], K: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``F K`` and ``F K F^T`` of Eq. 5, the latter exactly symmetric (rounding made
    it inexact; the solver needs it so), for one prior covariance ``K`` (n_wl, n_wl)
    or one per target (k, n_wl, n_wl)."""
    FK = F @ K  # (..., 3 n_i, n_wl) = (K F^T)^T, K symmetric
    G = FK @ F.T
    return FK, 0.5 * (G + np.swapaxes(G, -1, -2))


def _ridged(
    var: NDArray[np.float64], scale: float
) -> tuple[NDArray[np.float64], float, int]:
    """Noise variances floored at ``RIDGE_RELATIVE * scale``, the floor, how many."""
    ridge_floor = RIDGE_RELATIVE * scale
    low = var < ridge_floor
    return np.where(low, ridge_floor, var), ridge_floor, int(np.count_nonzero(low))


def _wiener_system(
    responses: Responses,
    illuminants: Spectra,
    sensitivity: Spectra,
    prior: Spectra | None,
    noise_from: str,
    center_prior: bool,
) -> tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    Spectra,
]:
    """Checked inputs of Eq. 5: the grid, ``F`` (Eq. 1/5), the prior's mean and
    covariance ``K``, and the prior (default the ColorChecker SG)."""
    if noise_from not in NOISE_SOURCES:
        raise InputError(
            f"noise_from={noise_from!r}: expected one of {', '.join(NOISE_SOURCES)}"
        )
    wl_int = illuminants.wavelength_nm
    L = _select(illuminants, responses.illuminants, "illuminant spectra").values
    S = _select(sensitivity, CHANNELS, "camera sensitivity").values
    _check_grid(sensitivity, wl_int, "camera sensitivity")
    if prior is None:
        prior = _default_prior(wl_int)
    wl = prior.wavelength_nm
    _check_within(prior, wl_int)
    for spectra, values, names, role in (
        (illuminants, L, responses.illuminants, "illuminant spectra"),
        (sensitivity, S, CHANNELS, "camera sensitivity"),
        (prior, prior.values, prior.names, "prior reflectances"),
    ):
        _check_finite(values, names, role, _source(spectra))
    rgb = responses.rgb
    _check_responses_finite(responses, rgb, "rgb")

    F = integrated_lighting_matrix(L, S, wl_int, wl)
    mean, K = _prior_moments(prior.values, center_prior)
    return wl, F, mean, K, prior


def integration_grid(
    sensitivity: Spectra, estimate: Grid, illuminants: Spectra | None = None
) -> Grid:
    """Where Eq. 1 is integrated for estimates on ``estimate``.

    Where the sensitivities (and the illuminants, if given) are known, at least the
    estimation range, at the finer of the two steps and at most
    :data:`~tunespec.core.spectra.CALIBRATION_MAX_STEP_NM`: the calibration's
    resolution is kept (a sensitivity calibrated at 2 nm resolves an IR-cut edge a
    10 nm estimation grid cannot), an LED 20 nm wide is not integrated on a few
    samples when the sensitivities come coarser (the demo's calibration as rawtoaces
    JSON at 5 nm: Table 2's mean dE00 0.070 integrated at 5 nm, 0.061 at 2 nm, 0.029
    from the 2 nm CSV), and light beyond the estimation range still counts (the
    reflectance solved for there where the prior reaches, :func:`support_grid`,
    else held at its end value, :func:`reflectance_basis`).
    """
    lo, hi = float(sensitivity.wavelength_nm[0]), float(sensitivity.wavelength_nm[-1])
    if illuminants is not None:
        lo = max(lo, float(illuminants.wavelength_nm[0]))
        hi = min(hi, float(illuminants.wavelength_nm[-1]))
    lo, hi = min(lo, estimate.start_nm), max(hi, estimate.end_nm)
    step = min(sensitivity.step_nm, estimate.step_nm, CALIBRATION_MAX_STEP_NM)
    n = max(int(np.floor((hi - lo) / step + 1e-6)), 1)
    return Grid(lo, lo + n * step, step)


def support_grid(
    report: Grid, integration_nm: NDArray[np.float64], prior_nm: NDArray[np.float64]
) -> Grid:
    """The samples Eq. 5 solves for to report a reflectance on ``report``: its step,
    extended by whole steps below and above it as far as Eq. 1 integrates
    (``integration_nm``, :func:`integration_grid`) and the prior is known
    (``prior_nm``).

    The light a camera sees beyond a reported range still enters its responses.
    With the reflectance held at the range's end value there
    (:func:`reflectance_basis`), surfaces that rise past 700 nm (foliage, red
    paints) misfit a deep-red LED with half its light above 700 nm by 13 standard
    deviations on a camera whose red channel sees there, and the estimate on the
    range followed that misfit (docs/validation.md, "The reflectance beyond the
    reported range": the broad-band family 0.085 -> 0.081 mean dE00). Solved on the
    whole range the light covers and reported on ``report``
    (:meth:`WienerEstimate.restricted`), the estimate and its uncertainty count it.

    Examples
    --------
    >>> str(support_grid(Grid(400, 700, 10), np.arange(380.0, 731.0, 2), np.arange(380.0, 731.0)))
    '380:730:10'
    >>> str(support_grid(Grid(400, 700, 10), np.arange(380.0, 731.0, 2), np.arange(400.0, 701.0)))
    '400:700:10'
    """
    step = report.step_nm
    lo = max(float(integration_nm[0]), float(prior_nm[0]))
    hi = min(float(integration_nm[-1]), float(prior_nm[-1]))
    below = max(int(np.floor((report.start_nm - lo) / step + 1e-6)), 0)
    above = max(int(np.floor((hi - report.end_nm) / step + 1e-6)), 0)
    return Grid(report.start_nm - below * step, report.end_nm + above * step, step)


def prior_on_support(
    prior: Spectra, report: Grid, integration_nm: NDArray[np.float64]
) -> Spectra:
    """``prior`` on the samples Eq. 5 solves for to report on ``report``
    (:func:`support_grid`)."""
    support = support_grid(report, integration_nm, prior.wavelength_nm)
    return prior.resample(support, source=prior.meta.get("source"))


def sample_indices(
    wl: NDArray[np.float64], samples_nm: NDArray[np.float64]
) -> NDArray[np.intp]:
    """The indices in ``wl`` of ``samples_nm`` (each of them one of its samples)."""
    idx = np.clip(np.searchsorted(wl, samples_nm - _WL_TOL_NM), 0, wl.size - 1)
    if not np.allclose(wl[idx], samples_nm, rtol=0, atol=_WL_TOL_NM):
        raise InputError(
            f"the samples {samples_nm[0]:g}-{samples_nm[-1]:g} nm are not among the "
            f"estimate's ({wl[0]:g}-{wl[-1]:g} nm)"
        )
    return idx


def on_integration_grid(
    illuminants: Spectra, sensitivity: Spectra, estimate: Grid
) -> tuple[Spectra, Spectra, Grid]:
    """Illuminants (band-averaged) and sensitivities on :func:`integration_grid`,
    ready for :func:`wiener_reflectance` with a prior on ``estimate``; and that grid.

    Pass the illuminants already corrected with the calibration's light-source
    corrections (on their own grid), as ``tunespec estimate`` does.

    Raises
    ------
    InputError
        The illuminants or the sensitivities do not reach over ``estimate``.

    References
    ----------
    The paper, Eq. 1 (integrated on the finer grid of the sensitivities).
    """
    for spectra in (sensitivity, illuminants):
        # named with the grid asked for, not the integration grid it widens to; the
        # sensitivities first: corrected illuminants are on their grid
        spectra.check_covers(estimate, source=spectra.meta.get("source"))
    fine = integration_grid(sensitivity, estimate, illuminants)
    return (
        illuminants.resample(fine, source=illuminants.meta.get("source"), average=True),
        sensitivity.resample(fine, source=sensitivity.meta.get("source")),
        fine,
    )


def integrated_lighting_matrix(
    illuminant: NDArray[np.float64],
    sensitivity: NDArray[np.float64],
    wavelength_nm: NDArray[np.float64],
    estimate_nm: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``F`` of Eq. 5 for reflectances sampled on ``estimate_nm``, (3 n_i, n_est).

    Eq. 1 is integrated on the illuminants' and sensitivities' own (finer) grid
    ``wavelength_nm``, with the reflectance between the estimation samples as
    :func:`reflectance_basis` has it: ``F = F_int Phi``. Integrating a narrow LED
    against a steep sensitivity edge on a coarse grid instead misplaces light by
    several per cent (an IR-cut edge within one LED's band), an error no
    reflectance prior can absorb. On one grid ``Phi = I`` and this is
    :func:`~tunespec.core.forward_model.lighting_matrix`.
    """
    F = lighting_matrix(illuminant, sensitivity, _step(wavelength_nm))
    return F @ reflectance_basis(estimate_nm, wavelength_nm)


def reflectance_basis(
    estimate_nm: NDArray[np.float64], wavelength_nm: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``Phi`` (n_fine, n_est): a reflectance sampled on ``estimate_nm`` on the
    integration grid ``wavelength_nm``, the cubic spline through its samples (end
    values held outside; the identity on one grid).

    Surface reflectances are smooth, and a colour computed from samples (ASTM E308's
    weights) assumes as much. With a hat basis (linear interpolation) the samples
    were the hat coefficients of a spectrum that kinks at every one of them, not its
    values: on ``benchmarks/generalisation.py`` at a 10 nm estimation grid (10 nm
    readings with 0.3 % noise, the sensor effects on, one camera) the mean CIEDE2000
    against the targets' colour from their own 10 nm samples was 0.120 and the
    coverage of the 95 % intervals of L*, a*, b* 0.88 / 0.75 / 0.78, where the
    spline gives 0.086 and 0.95 / 0.96 / 0.95 (at 5 nm: 0.085 -> 0.084).
    """
    if estimate_nm.size == wavelength_nm.size and np.allclose(
        estimate_nm, wavelength_nm, rtol=0, atol=_WL_TOL_NM
    ):
        return np.eye(estimate_nm.size)
    return spline_matrix(estimate_nm, wavelength_nm)


def solve_with_noise(
    G: NDArray[np.float64],
    noise: NDArray[np.float64],
    rhs: NDArray[np.float64],
    *,
    where: str = "",
) -> NDArray[np.float64]:
    """``X_k`` with ``(G + diag noise_k) X_k = rhs_k`` for every ``k``: Eq. 5's system
    ``F K F^T + K_e`` with each patch's (or pixel's, or noise bin's) own diagonal
    ``K_e`` (or whole ``K_e``: ``noise`` (k, m, m)), in one batched LAPACK call; no
    inverse is formed.

    ``G`` is (m, m) or (k, m, m), ``noise`` (k, m) or (k, m, m), ``rhs`` (k, m, r) or
    (m, r) for all ``k``.
    A singular system raises :class:`SingularSystemError` (``where`` names it).
    """
    k, m = noise.shape[:2]
    A = np.array(np.broadcast_to(G, (k, m, m)))
    if noise.ndim == 3:
        A += noise
    else:
        idx = np.arange(m)
        A[:, idx, idx] += noise
    try:
        return np.linalg.solve(A, np.broadcast_to(rhs, (k, *rhs.shape[-2:])))
    except np.linalg.LinAlgError as exc:
        raise SingularSystemError(f"F K F^T + K_e is singular{where}: {exc}") from None


def _solve_patchwise(
    system: Callable[
        [slice],
        tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]],
    ],
    mean: NDArray[np.float64],
    resid: NDArray[np.float64],
    noise: NDArray[np.float64],
    patches: tuple[str, ...],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Eq. 5-6 per patch with its own noise ``K_e`` (diagonal, or whole): the
    estimates and the diagonal of their posterior covariance, solved in batches.
    ``system(rows)`` gives ``F K F^T``, ``F K`` and ``diag K`` of the patches
    ``rows``: shared ((m, m), (m, n_wl), (n_wl,)) or their own (with a leading
    axis)."""
    n_p = resid.shape[0]
    est = np.empty((n_p, mean.size))
    post_var = np.empty((n_p, mean.size))
    for lo in range(0, n_p, _CHUNK):
        hi = min(lo + _CHUNK, n_p)
        G, FK, prior_var = system(slice(lo, hi))
        FK = np.broadcast_to(FK, (hi - lo, *FK.shape[-2:]))
        # One batched solve for the data and for F K (the posterior covariance);
        # right-hand sides (chunk, 3 n_i, 1 + n_wl).
        rhs = np.concatenate([resid[lo:hi, :, None], FK], axis=2)
        sol = solve_with_noise(
            G, noise[lo:hi], rhs, where=f" for patches {lo}..{hi - 1}"
        )
        est[lo:hi] = mean + np.einsum("pj,pjl->pl", sol[:, :, 0], FK)
        post_var[lo:hi] = prior_var - np.einsum("pjl,pjl->pl", FK, sol[:, :, 1:])
    if not np.all(np.isfinite(est)):
        bad = [patches[i] for i in np.flatnonzero(~np.isfinite(est).all(1))]
        raise SingularSystemError(
            f"non-finite estimate for {len(bad)} patch(es), e.g. {bad[0]!r}: "
            "F K F^T + K_e is numerically singular"
        )
    # The posterior variance is a difference of nearly equal numbers where the data
    # pin the spectrum down; rounding can make it slightly negative.
    np.maximum(post_var, 0.0, out=post_var)

    return est, post_var


def _clip_estimate(
    est: NDArray[np.float64], patches: tuple[str, ...], clip: bool
) -> tuple[NDArray[np.float64], tuple[str, ...], int]:
    """Reflectances clipped to [0, 1], the patches clipped and the samples clipped."""
    clipped: tuple[str, ...] = ()
    n_clipped = 0
    if clip:
        out = (est < 0.0) | (est > 1.0)
        n_clipped = int(np.count_nonzero(out))
        clipped = tuple(patches[i] for i in np.flatnonzero(out.any(axis=1)))
        est = np.clip(est, 0.0, 1.0)

    return est, clipped, n_clipped


def _prior_moments(
    P: NDArray[np.float64], center: bool
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Prior mean (n_wl,) and covariance or correlation matrix (n_wl, n_wl)."""
    n = P.shape[0]
    if center:
        if n < 2:
            raise InputError(
                f"prior reflectances: {n} spectrum; a centred prior needs at least 2"
            )
        mean = P.mean(axis=0)
        D = P - mean
        K = (D.T @ D) / (n - 1)
    else:
        if n < 1:
            raise InputError("prior reflectances: no spectra")
        mean, K = np.zeros(P.shape[1]), (P.T @ P) / n
    # Identical training spectra leave rounding residue (~1e-34) in K, not zero.
    if not np.trace(K) > _PRIOR_VAR_REL * np.mean(P**2) * P.shape[1]:
        raise SingularSystemError(
            "the prior reflectances have no variance (all spectra identical or zero)"
        )
    return mean, K


def _noise_variance(
    responses: Responses, noise_std: float | None, noise_from: str
) -> NDArray[np.float64]:
    """Diagonal of ``K_e`` per patch (Eq. 6), shape (n_p, n_i, 3)."""
    shape = responses.rgb.shape
    if noise_std is not None:
        level = float(noise_std)
        if not (np.isfinite(level) and 0.0 <= level <= 1e6):  # level**2 stays finite
            raise InputError(
                f"noise_std={noise_std!r} (--noise-std): expected a finite value "
                "in [0, 1e6]"
            )
        var = np.full(shape, level**2)
    elif responses.rgb_std is not None:
        _check_responses_finite(responses, responses.rgb_std, "rgb_std")
        if np.any(responses.rgb_std < 0):
            p, i, _ = np.argwhere(responses.rgb_std < 0)[0]
            raise InputError(
                f"responses: negative standard deviation for patch "
                f"{responses.patches[p]!r} under {responses.illuminants[i]!r}"
            )
        var = responses.rgb_std**2
    else:
        raise InputError(
            "no noise level: the responses carry no per-pixel standard deviations "
            "(R_std, G_std, B_std); give one level with --noise-std"
        )
    if noise_from == "mean":
        n_pix = responses.n_pixels
        if n_pix is None:
            raise InputError(
                "noise_from='mean' needs the responses' n_pixels (pixels per ROI mean)"
            )
        if not np.all(np.isfinite(n_pix) & (n_pix >= 1)):
            raise InputError("responses: n_pixels must be finite and >= 1")
        var = var / n_pix[..., None]
    if responses.saturated is not None:
        # A clipped ROI has a tiny std (every pixel at the white level), so Eq. 6
        # would trust it most; it carries no information about r, so give it a
        # variance that removes it from the estimate instead.
        var = np.where(responses.clipped[..., None], SATURATED_VARIANCE, var)
    return var


def _source(spectra: Spectra) -> str | None:
    return spectra.meta.get("source")


def _select(spectra: Spectra, names: tuple[str, ...], role: str) -> Spectra:
    have = shown_names(spectra.names, 8)
    check_names(
        names,
        spectra.names,
        f"{role}: {{n}} name(s) not found: {{names}} (have {have})",
        path=_source(spectra),
    )
    return spectra.select(names)


def _describe(wl: NDArray[np.float64]) -> str:
    return f"{wl[0]:g}-{wl[-1]:g} nm ({wl.size} samples)"


def _check_grid(spectra: Spectra, wl: NDArray[np.float64], role: str) -> None:
    other = spectra.wavelength_nm
    if other.size != wl.size or not np.allclose(other, wl, rtol=0, atol=_WL_TOL_NM):
        raise InputError(
            f"{role}: wavelength grid {_describe(other)} differs from the illuminant "
            f"spectra's {_describe(wl)}; resample both onto one Grid",
            path=_source(spectra),
        )


def _check_within(prior: Spectra, wl_int: NDArray[np.float64]) -> None:
    """The estimation grid (the prior's) lies within the illuminants' grid."""
    wl = prior.wavelength_nm
    if wl[0] < wl_int[0] - _WL_TOL_NM or wl[-1] > wl_int[-1] + _WL_TOL_NM:
        raise InputError(
            f"prior reflectances: wavelength grid {_describe(wl)} reaches beyond the "
            f"illuminant spectra's {_describe(wl_int)}; resample the prior onto "
            "a grid within it",
            path=_source(prior),
        )


def _step(wl: NDArray[np.float64]) -> float:
    d = np.diff(wl)
    if d.size == 0 or np.ptp(d) > _WL_TOL_NM:
        raise InputError(
            f"illuminant spectra: wavelengths {_describe(wl)} are not equidistant"
        )
    return float(d[0])


def _check_finite(
    values: NDArray[np.float64], names: tuple[str, ...], role: str, source: str | None
) -> None:
    bad = [names[i] for i in np.flatnonzero(~np.isfinite(values).all(axis=1))]
    if bad:
        raise InputError(
            f"{role}: non-finite values in {', '.join(bad[:8])}", path=source
        )


def _check_responses_finite(
    responses: Responses, arr: NDArray[np.float64], what: str
) -> None:
    if not np.all(np.isfinite(arr)):
        p, i, _ = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(
            f"responses: non-finite {what} for patch {responses.patches[p]!r} under "
            f"{responses.illuminants[i]!r}"
        )
