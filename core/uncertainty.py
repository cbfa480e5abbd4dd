"""Standard uncertainty of estimated reflectances and their D50 colorimetry.

Three sources of error reach a Wiener estimate ``r = m + W (c - F m)``,
``W = K F' (F K F' + K_e)^-1`` (Eq. 5):

1. what the responses cannot see: the part of the reflectance outside what the
   camera and the LEDs resolve, drawn from the prior (mean ``m``, covariance ``K``);
2. the noise of the responses: photon and read noise of the ROI mean
   (``rgb_std^2 / n_pixels``), the flat-field residual of Eq. 2
   (:data:`FLAT_FIELD_RESIDUAL` of the response) and the systematic errors that the
   calibration's residuals showed beyond them (stray light, cross-talk,
   non-linearity: :mod:`tunespec.core.excess`), part of them shared by all of a
   patch's responses;
3. the calibration: the joint covariance ``Sigma`` of the sensitivities and the
   light-source corrections (:attr:`SensitivityEstimate.covariance`) moves the
   responses by ``J Sigma J'`` with ``J = d c / d theta`` at the estimate (Eq. 1
   differentiated), and the light's reading noise moves them by what the
   calibration's replicates with the readings drawn anew show
   (:func:`readings_response_covariance`, :mod:`tunespec.core.readings`; in ``N``
   only, not in the estimate's ``K_e``).

For the linear estimator actually used (whatever ``K_e`` Eq. 6 gave it), the error
covariance is the sandwich::

    E = (I - W F) K (I - W F)' + W N W' + D Sigma D'

with ``N`` the true response noise covariance and ``D`` the derivative of the
estimate with respect to the calibration: an error ``dF`` of Eq. 1's matrix moves
the responses' prediction (``W dF r``) and Eq. 5's gain ``W`` as well, which adds
``-(I - W F) K dF' A^-1 (c - F m)`` (:class:`_MovesOfF`; the readings' replicates
likewise). Without the gain's part the calibration's reflectance variance was off
by up to a factor 3.2 where the camera sees little (by central differences,
``tests/core/test_sensitivity_bayes.py``); in L*a*b* the two terms' variances moved
by 0.8 % and 4 % at most (one session of ``benchmarks/generalisation.py``).

``E`` is propagated to CIE XYZ (D50, ASTM E308 weights, exactly linear) and to
CIELAB by the Jacobian of the CIELAB formulas (first order, as GUM Supplement 2 /
JCGM 102 allows for small uncertainties).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Eq. 1, 5 and 6. JCGM 100:2008 (GUM), Sec. 5 (law of propagation
of uncertainty); JCGM 102:2011 (GUM Supplement 2, multivariate models).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tunespec.core.colorimetry import astm_e308_weights_d50, xyz_to_lab_d50
from tunespec.core.errors import InputError
from tunespec.core.excess import FLAT_FIELD_RESIDUAL, flat_field_residual, led_blocks
from tunespec.core.led_correction import _corrected
from tunespec.core.metering import as_calibrated
from tunespec.core.responses import Responses
from tunespec.core.sensitivity import SensitivityEstimate
from tunespec.core.spectra import Grid, Spectra, resampling_matrix
from tunespec.core.target_prior import fit_target_priors
from tunespec.core.wiener import (
    WienerEstimate,
    checked_noise_covariance,
    prior_gram,
    prior_on_support,
    reflectance_basis,
    sample_indices,
    solve_with_noise,
    wiener_reflectance,
    with_target_priors,
)

__all__ = [
    "BLIND_EDGE_SCALE",
    "BUDGET_TERMS",
    "FLAT_FIELD_RESIDUAL",
    "PRIOR_MISMATCH_SCALE",
    "ReflectanceUncertainty",
    "blind_edge_factor",
    "budget_summary",
    "calibration_response_covariance",
    "lab_covariance",
    "reflectance_uncertainty",
    "wiener_with_uncertainty",
]

#: ``kappa`` of :func:`reflectance_uncertainty`: the prior-mismatch term's standard
#: deviation relative to what a target's own responses support. The responses
#: cannot show what a target does where camera and LEDs are blind (the red edge of
#: foliage past an IR cut), so the fitted term is too narrow by a factor no single
#: target reveals. Chosen with :data:`BLIND_EDGE_SCALE` by
#: ``benchmarks/generalisation.py --tune-edge`` (with the estimate of
#: :func:`wiener_with_uncertainty`; ``tune_prior_scales``' criterion: the coverage
#: of the 95 % intervals of the reflectance at every wavelength and of L*, a*, b*
#: closest to 95 %) under issue 23's conditions (10 nm readings with 0.1 % noise,
#: stray light, cross-talk, non-linearity; one camera per family, the CAL1 model,
#: 400:700:10) on four reflectance collections, seeds 0-2: on all four (1.10, 0.75),
#: (1.10, 0.75), (1.15, 0.75); with each left out in turn kappa 1.00-1.30, gamma
#: 0.25-1.50. With the estimate solved past the reported range
#: (:func:`~tunespec.core.wiener.support_grid`) the same runs give (1.10, 0.50),
#: (1.15, 0.50), (1.10, 1.00): gamma's spread holds 0.75, left as it is. It was
#: (1.10, 0.50) while the non-linearity was carried in the error
#: bars instead of undone (:func:`~tunespec.core.excess.linearise`), (1.05, 0.50)
#: while Eq. 5 took the prior set's covariance unscaled
#: (:func:`~tunespec.core.wiener.with_target_priors`), and (1.15, 0.25) while a
#: phosphor white's cleaning cut its tails.
PRIOR_MISMATCH_SCALE = 1.10
#: ``gamma``: at a wavelength where Eq. 1 sees nothing (:func:`blind_edge_factor`)
#: the prior-mismatch term's standard deviation is ``1 + gamma`` times the rest's:
#: there the estimate is the prior's extrapolation alone, and surfaces depart from
#: the prior set's correlations (a paper's UV edge against the SG's) more than the
#: fitted term can show. Chosen with :data:`PRIOR_MISMATCH_SCALE` (above).
BLIND_EDGE_SCALE = 0.75
#: Visibility (the noise-weighted column norm of Eq. 1's ``F`` relative to its
#: largest) below which a wavelength counts as blind, linearly: fully at 0.
BLIND_VISIBILITY = 0.1

#: Targets whose error covariances are formed at once.
_CHUNK = 256
#: Targets whose moves (n_est x the calibration's parameters each: 1 nm estimates and
#: a 2 nm calibration, 400 x 572) are formed at once.
_MOVES_CHUNK = 32


@dataclass(frozen=True, eq=False)
class ReflectanceUncertainty:
    """Uncertainties of a :class:`~tunespec.core.wiener.WienerEstimate`.

    ``covariance`` (n_p, n_wl, n_wl) of the reflectance error; ``reflectance_std``
    (n_p, n_wl) its diagonal's root; ``xyz``, ``lab`` (n_p, 3) of the (clipped)
    estimate under D50 and ``xyz_std``, ``lab_std`` (n_p, 3) their standard
    uncertainties; ``lab_covariance`` (n_p, 3, 3); ``prior_part_variance`` (n_p,
    n_wl) and ``lab_prior_part_variance`` (n_p, 3) the prior-mismatch term's share of
    the reflectance and CIELAB variances (scaled by ``prior_scale`` squared);
    ``budget`` each term of :data:`BUDGET_TERMS` that applies as ``(reflectance
    variance (n_p, n_wl), CIELAB variance (n_p, 3))``: the uncertainty budget (the
    terms add up to the total, both are first order); ``chi2_per_response`` (n_p,) each
    target's chi-square per response against Eq. 1 and ``misfit_by_light``
    (n_i,) the estimate's mean squared standardised residual under each light
    (:func:`~tunespec.core.plausibility.check_response_consistency`).
    """

    covariance: NDArray[np.float64]
    reflectance_std: NDArray[np.float64]
    xyz: NDArray[np.float64]
    xyz_std: NDArray[np.float64]
    lab: NDArray[np.float64]
    lab_std: NDArray[np.float64]
    lab_covariance: NDArray[np.float64]
    generic_sigma: NDArray[np.float64] | None = None
    generic_length_nm: float = 0.0
    prior_part_variance: NDArray[np.float64] | None = None
    lab_prior_part_variance: NDArray[np.float64] | None = None
    budget: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]] = field(
        default_factory=dict
    )
    chi2_per_response: NDArray[np.float64] | None = None
    misfit_by_light: NDArray[np.float64] | None = None


def _hold_resample(
    wl_from: NDArray[np.float64],
    values: NDArray[np.float64],
    wl_to: NDArray[np.float64],
    *,
    average: bool = False,
) -> NDArray[np.float64]:
    """Onto ``wl_to`` (end values held), as :meth:`Spectra.resample` does."""
    return values @ resampling_matrix(wl_from, wl_to, average=average).T


class _CalibrationJacobian:
    """Eq. 1 differentiated with respect to the calibration's parameters ``theta``
    (the sensitivities, the LEDs' log gains and their wavelength offsets), with its
    covariance factored as ``Sigma = U U'``: the factors ``J U`` of the responses and
    ``(dF U)' u`` of Eq. 1's matrix seen through response weights ``u``."""

    def __init__(self, calibration: SensitivityEstimate, illuminants: Spectra) -> None:
        cov = calibration.covariance
        if cov is None:
            raise InputError(
                f"the {calibration.method!r} calibration carries no uncertainty; "
                "calibrate with method 'bayes'"
            )
        sens = calibration.sensitivity
        self.wavelength_nm = wl = sens.wavelength_nm
        self.step = sens.step_nm
        n = wl.size
        # the corrections apply to the spectra as the calibration saw them
        rep = as_calibrated(illuminants, sens.grid).values
        rows, gains, shifts = calibration.corrections_for(illuminants.names)
        self.Lc, self.dL = _corrected(wl, rep, gains, shifts)
        self.S = sens.values
        self.n_responses = 3 * len(illuminants.names)
        # Sigma = U U' (U from the eigen-decomposition, rank <= its size).
        e, V = np.linalg.eigh(cov)
        keep = e > e.max() * 1e-14
        U = V[:, keep] * np.sqrt(e[keep])
        self.U_sens = U[: 3 * n].reshape(3, n, -1)
        # each spectrum's rows of U for its log gain and its offset (0: not fitted)
        corr = calibration.led_correction
        n_led = len(corr.names) if corr is not None else 0
        self.U_gain = np.zeros((rows.size, U.shape[1]))
        self.U_shift = np.zeros((rows.size, U.shape[1]))
        fitted = np.flatnonzero(rows >= 0) if cov.shape[0] > 3 * n else []
        self.U_gain[fitted] = U[3 * n + rows[fitted]]
        self.U_shift[fitted] = U[3 * n + n_led + rows[fitted]]

    def responses(self, R: NDArray[np.float64]) -> NDArray[np.float64]:
        """``J U`` (P, 3 n_i, N) at reflectances ``R`` (P, n) on the calibration's
        grid; rows illuminant-major as Eq. 5's ``c``."""
        A = R[:, None, :] * self.Lc[None] * self.step  # (P, n_i, n)
        dA = R[:, None, :] * self.dL[None] * self.step
        S = self.S
        pred = np.einsum("pil,kl->pik", A, S)
        dpred = np.einsum("pil,kl->pik", dA, S)
        JU = np.stack([A @ U for U in self.U_sens], axis=2)  # (P, n_i, 3, N)
        JU += pred[..., None] * self.U_gain[None, :, None, :]
        JU += dpred[..., None] * self.U_shift[None, :, None, :]
        return JU.reshape(R.shape[0], -1, JU.shape[-1])

    def matrix(
        self, u: NDArray[np.float64], basis: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """``(dF U)' u`` (P, n_est, N): for every column of ``U``, the transposed
        change of Eq. 5's ``F = F_cal Phi`` (``basis`` ``Phi`` (n, n_est),
        :func:`~tunespec.core.wiener.reflectance_basis`) applied to response weights
        ``u`` (P, 3 n_i)."""
        w = u.reshape(u.shape[0], -1, 3) * self.step  # (P, n_i, 3)
        Q = np.einsum("pic,il->pcl", w, self.Lc)
        out = sum(
            (Q[:, c, None, :] * basis.T[None]) @ U for c, U in enumerate(self.U_sens)
        )
        V = np.einsum("pic,cl->pil", w, self.S)
        out += (basis.T[None] @ (V * self.Lc[None]).transpose(0, 2, 1)) @ self.U_gain
        out += (basis.T[None] @ (V * self.dL[None]).transpose(0, 2, 1)) @ self.U_shift
        return out


def _on_calibration_grid(
    reflectance: Spectra, wavelength_nm: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The reflectances between their samples as Eq. 5's ``F`` has them."""
    return (
        reflectance.values
        @ reflectance_basis(reflectance.wavelength_nm, wavelength_nm).T
    )


def calibration_response_covariance(
    calibration: SensitivityEstimate,
    illuminants: Spectra,
    reflectance: Spectra,
) -> NDArray[np.float64]:
    """Covariance of the responses that the calibration's uncertainty causes.

    ``J Sigma J'`` per sample, with ``J`` the derivative of Eq. 1 with respect to
    the sensitivities, the LEDs' log gains and their wavelength offsets, at the
    given reflectances.

    Parameters
    ----------
    calibration
        With :attr:`~SensitivityEstimate.covariance` (method ``"bayes"``).
    illuminants : Spectra, (n_i, n_wl')
        The target capture's spectra as the light source reported them (not
        corrected; their noise floor goes first, as in
        :meth:`SensitivityEstimate.correct_illuminants`), any grid covering the
        calibration's.
    reflectance : Spectra, (n_p, n_wl'')
        The (estimated) reflectances, any grid; between samples as
        :func:`~tunespec.core.wiener.reflectance_basis` has them.

    Returns
    -------
    (n_p, 3 n_i, 3 n_i)
        Rows illuminant-major ``(i1 R, i1 G, i1 B, i2 R, ...)`` as Eq. 5's ``c``.

    Raises
    ------
    InputError
        If the calibration carries no covariance.
    """
    return _response_covariance(
        _CalibrationJacobian(calibration, illuminants), reflectance
    )


def _response_covariance(
    jac: _CalibrationJacobian | _ReadingsJacobian, reflectance: Spectra
) -> NDArray[np.float64]:
    """``sum_k (J u_k)(J u_k)'`` over the factors of ``jac`` at ``reflectance``."""
    R = _on_calibration_grid(reflectance, jac.wavelength_nm)
    out = np.empty((R.shape[0], jac.n_responses, jac.n_responses))
    for lo in range(0, R.shape[0], _CHUNK):
        JU = jac.responses(R[lo : lo + _CHUNK])
        out[lo : lo + _CHUNK] = JU @ JU.transpose(0, 2, 1)
    return out


def readings_response_covariance(
    calibration: SensitivityEstimate,
    illuminants: Spectra,
    reflectance: Spectra,
) -> NDArray[np.float64]:
    """Covariance of the responses that the light's reading noise causes.

    The errors-in-variables term (:mod:`tunespec.core.readings`): Eq. 1 at the given
    reflectances under each of the calibration's replicates (its sensitivities and
    LED corrections, the readings with the replicate's noise: the calibration's
    draw where they are the readings it saw, else one of their own), about Eq. 1
    with the calibration itself; the mean of the deviations' outer products (a
    bootstrap's estimate of the error's covariance about the truth).

    Parameters
    ----------
    calibration
        With :attr:`~SensitivityEstimate.readings`.
    illuminants : Spectra, (n_i, n_wl')
        The target capture's spectra as reported (uncorrected), a grid the
        readings can be resampled onto.
    reflectance : Spectra, (n_p, n_wl'')
        The (estimated) reflectances, any grid.

    Returns
    -------
    (n_p, 3 n_i, 3 n_i)
        Rows illuminant-major, as Eq. 5's ``c``.
    """
    return _response_covariance(
        _ReadingsJacobian(calibration, illuminants), reflectance
    )


class _ReadingsJacobian:
    """The calibration's replicates (:mod:`tunespec.core.readings`) as
    :class:`_CalibrationJacobian`'s factors: column ``k`` is replicate ``k``'s change
    of Eq. 1's ``F`` (its sensitivities, corrections and readings) over
    ``sqrt(K)``, so that the factors' outer products are the replicates' mean."""

    def __init__(self, calibration: SensitivityEstimate, illuminants: Spectra) -> None:
        reps = calibration.readings
        if reps is None:
            raise InputError("the calibration carries no reading replicates")
        self.wavelength_nm = wl = reps.wavelength_nm
        cleaned = as_calibrated(
            illuminants, Grid(float(wl[0]), float(wl[-1]), float(wl[1] - wl[0]))
        )
        sens = calibration.sensitivity
        self.dF = reps.lighting_deviations(
            cleaned,
            _hold_resample(sens.wavelength_nm, sens.values, wl),
            calibration.corrections_for(cleaned.names),
        ) / np.sqrt(reps.n_replicates)  # (K, 3 n_i, n)
        self.n_responses = self.dF.shape[1]

    def responses(self, R: NDArray[np.float64]) -> NDArray[np.float64]:
        """(P, 3 n_i, K) at reflectances ``R`` (P, n) on the readings' grid."""
        return np.einsum("kml,pl->pmk", self.dF, R)

    def matrix(
        self, u: NDArray[np.float64], basis: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """(P, n_est, K), as :meth:`_CalibrationJacobian.matrix`."""
        return basis.T[None] @ np.einsum("kml,pm->plk", self.dF, u)


def lab_covariance(
    xyz: NDArray[np.float64], xyz_cov: NDArray[np.float64]
) -> NDArray[np.float64]:
    """CIELAB (ICC D50 white) covariance from an XYZ covariance, first order.

    The Jacobian of :func:`~tunespec.core.colorimetry.xyz_to_lab_d50` is taken by
    central differences (step 1e-4 of Y = 100), which is exact to ~1e-8 for these
    smooth formulas.

    Parameters
    ----------
    xyz : (n, 3)
    xyz_cov : (n, 3, 3)

    Returns
    -------
    (n, 3, 3)

    References
    ----------
    JCGM 100:2008 (GUM), section 5 (law of propagation of uncertainty, first
    order); CIE 015:2018 (CIELAB).
    """
    h = 1e-4
    J = np.empty((xyz.shape[0], 3, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = h
        J[:, :, j] = (xyz_to_lab_d50(xyz + d) - xyz_to_lab_d50(xyz - d)) / (2 * h)
    return J @ xyz_cov @ J.transpose(0, 2, 1)


#: The terms of the uncertainty budget (:attr:`ReflectanceUncertainty.budget`).
BUDGET_TERMS = (
    "prior mismatch",
    "response noise",
    "flat field",
    "systematic",
    "calibration",
    "readings",
)


_FJacobians = dict[str, _CalibrationJacobian | _ReadingsJacobian]


def _f_jacobians(
    calibration: SensitivityEstimate,
    responses: Responses,
    illuminants: Spectra,
    *,
    readings: bool = True,
) -> _FJacobians:
    """The budget's terms that are errors of Eq. 1's ``F``, by name, for the
    responses' lights: the calibration's covariance and, unless ``readings`` is
    false, its reading replicates (none without a ``"bayes"`` calibration)."""
    if calibration.covariance is None:
        return {}
    chosen = illuminants.select(responses.illuminants)
    out: _FJacobians = {"calibration": _CalibrationJacobian(calibration, chosen)}
    if readings and calibration.readings is not None:
        out["readings"] = _ReadingsJacobian(calibration, chosen)
    return out


def _response_error_terms(
    responses: Responses,
    illuminants: Spectra,
    calibration: SensitivityEstimate,
    reflectance: Spectra,
    jacobians: _FJacobians | None = None,
    *,
    readings: bool = True,
) -> dict[str, NDArray[np.float64]]:
    """The true error covariance of every patch's stacked responses, (n_p, m, m),
    term by term: the noise of the ROI means (``rgb_std**2 / n_pixels``), the
    flat-field residual (:attr:`ExcessVariance.flat_field_relative`, fitted to the
    calibration's residuals, or :data:`FLAT_FIELD_RESIDUAL` without them: one error of
    the irradiance under each LED, shared by its three channels; none for saturated
    responses),
    the systematic errors the calibration's residuals showed
    (:attr:`SensitivityEstimate.excess`) and, with a ``"bayes"`` calibration, its
    response covariance at the estimate (:func:`calibration_response_covariance`).
    A term the inputs do not carry is left out; the light's reading noise
    (:func:`readings_response_covariance`) comes with the calibration's covariance
    unless ``readings`` is false (Eq. 5's ``K_e`` goes without it). ``jacobians``:
    :func:`_f_jacobians`' already built."""
    n_p, m_rows = len(responses.patches), 3 * len(responses.illuminants)
    rgb = responses.rgb.reshape(n_p, m_rows)
    keep = ~np.repeat(responses.clipped, 3, axis=1)  # (n_p, m_rows)
    idx = np.arange(m_rows)

    def diagonal(var: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.zeros((n_p, m_rows, m_rows))
        out[:, idx, idx] = np.where(keep, var, 0.0)
        return out

    # one irradiance error per patch and LED: shared by that LED's three channels;
    # its size as the calibration's residuals showed it (else the nominal one)
    flat = flat_field_residual(calibration.excess)
    terms = {"flat field": led_blocks(flat * np.where(keep, rgb, 0.0))}
    if responses.rgb_std is not None:
        n_pix = (
            responses.n_pixels
            if responses.n_pixels is not None
            else np.ones(responses.rgb.shape[:2])
        )
        terms["response noise"] = diagonal(
            (responses.rgb_std**2 / n_pix[..., None]).reshape(n_p, m_rows)
        )
    if calibration.excess is not None:
        terms["systematic"] = calibration.excess.covariance(
            np.where(keep, rgb, 0.0),
            log_reference=_log_reference(calibration, tuple(responses.illuminants)),
        )
    if jacobians is None:
        jacobians = _f_jacobians(calibration, responses, illuminants, readings=readings)
    physical = _physical(reflectance)
    for t, jac in jacobians.items():
        terms[t] = _response_covariance(jac, physical)
    return terms


def _physical(reflectance: Spectra) -> Spectra:
    """The estimate as Eq. 1's derivatives take it: within what a surface reflects
    (an unclipped estimate can ring below 0 where the LEDs see little)."""
    values = np.clip(reflectance.values, 0.0, 1.5)
    return Spectra(reflectance.wavelength_nm, values, reflectance.names)


def _log_reference(
    calibration: SensitivityEstimate, illuminants: tuple[str, ...]
) -> NDArray[np.float64] | None:
    """The chart's mean log response under each of the target's LEDs and channels
    (:attr:`ExcessVariance.log_reference_by_response`, matched by the LEDs' names in
    the calibration's order; one not among them gets the overall mean), or None to
    leave it to :meth:`ExcessVariance.covariance`."""
    excess, corr = calibration.excess, calibration.led_correction
    assert excess is not None
    by = excess.log_reference_by_response
    if corr is None or len(by) != 3 * len(corr.names):
        return None
    rows, _, _ = corr.lookup(illuminants)
    out = np.full((len(illuminants), 3), excess.log_reference)
    for i, j in enumerate(rows):
        if j >= 0:
            out[i] = by[3 * j : 3 * j + 3]
    return out.reshape(-1)


class _MovesOfF:
    """The budget's terms that are errors ``dF`` of Eq. 1's matrix (the
    calibration's, the readings'), as moves of Eq. 5's estimate.

    To first order ``dF`` moves ``r_hat = m + W (c - F m)`` by
    ``W dF r_hat - (I - W F) K dF' u`` with ``u = A^-1 (c - F m)``: the gain
    ``W = K F' A^-1`` (``A = F K F' + K_e``) depends on ``F`` too,
    ``dW = (I - W F) K dF' A^-1 - W dF W``. The second part lies where the responses
    see little (``I - W F``): it is the reflectance's, hardly the colour's.
    """

    def __init__(
        self, wiener: WienerEstimate, responses: Responses, jacobians: _FJacobians
    ) -> None:
        self.jacobians = jacobians
        refl, wl = _physical(wiener.reflectance), wiener.reflectance.wavelength_nm
        self.at = {
            t: (
                _on_calibration_grid(refl, jac.wavelength_nm),
                reflectance_basis(wl, jac.wavelength_nm),
            )
            for t, jac in self.jacobians.items()
        }
        F, mean = wiener.lighting, wiener.prior_mean
        assert F is not None and mean is not None
        n_p = len(responses.patches)
        self.innovation = np.nan_to_num(responses.rgb.reshape(n_p, -1) - F @ mean)

    def weights(
        self, G: NDArray[np.float64], used: NDArray[np.float64], rows: slice
    ) -> NDArray[np.float64] | None:
        """``u = A^-1 (c - F m)`` of the targets ``rows`` (None: no such term)."""
        if not self.jacobians:
            return None
        return solve_with_noise(G, used, self.innovation[rows, :, None])[..., 0]

    def covariance(
        self,
        term: str,
        N: NDArray[np.float64],
        rows: slice,
        W: NDArray[np.float64],
        posterior: NDArray[np.float64],
        u: NDArray[np.float64] | None,
    ) -> NDArray[np.float64]:
        """The estimate's covariance from ``term`` for the targets ``rows``: its
        response covariance ``N`` through ``W`` where it is no error of ``F``, else
        its moves' (``posterior`` ``(I - W F) K``)."""
        if term not in self.jacobians:
            return W @ N @ W.transpose(0, 2, 1)
        assert u is not None
        jac, (R, basis) = self.jacobians[term], self.at[term]
        R = R[rows]
        out = np.empty((W.shape[0], W.shape[1], W.shape[1]))
        for a in range(0, len(out), _MOVES_CHUNK):
            b = slice(a, a + _MOVES_CHUNK)
            D = W[b] @ jac.responses(R[b]) - posterior[b] @ jac.matrix(u[b], basis)
            out[b] = D @ D.transpose(0, 2, 1)
        return out


def reflectance_uncertainty(
    wiener: WienerEstimate,
    responses: Responses,
    illuminants: Spectra,
    calibration: SensitivityEstimate,
    *,
    prior_scale: float | None = None,
    edge_scale: float = BLIND_EDGE_SCALE,
) -> ReflectanceUncertainty:
    """Error covariance of a Wiener estimate, with the calibration's uncertainty.

    The error of Eq. 5's estimate ``r_hat = m + W (c - F m)`` is
    ``E = (I - W F) K_mis (I - W F)^T + W K_e W^T`` (the Wiener error covariance,
    Haneishi et al., Applied Optics 39(35), 2000):
    ``K_e`` the responses' true error covariance (noise, flat field, and the
    calibration's covariance propagated through Eq. 1), ``K_mis`` the prior
    mismatch fitted to this target's responses, scaled by ``prior_scale`` and
    widened where Eq. 1 is blind (:func:`blind_edge_factor`).

    Parameters
    ----------
    wiener
        The estimate (:func:`wiener_with_uncertainty`, or
        :func:`~tunespec.core.wiener.wiener_reflectance` with the calibration's).
    responses
        The responses it was computed from (``rgb_std`` and ``n_pixels`` give the
        noise; without them only the calibration and prior terms count).
    illuminants
        The target capture's spectra as reported (uncorrected), any grid covering
        the calibration's.
    calibration
        The sensitivity estimate; its covariance (``"bayes"``) adds the
        calibration term, else that term is left out.
    prior_scale, edge_scale
        ``kappa``: the prior-mismatch term's standard deviation is ``kappa`` times
        what the target's own responses support (default
        :data:`PRIOR_MISMATCH_SCALE`); ``gamma`` of :func:`blind_edge_factor`.

    Returns
    -------
    ReflectanceUncertainty
        On ``wiener``'s samples, formed on its ``support`` where it has one.
    """
    whole = wiener.support or wiener
    refl = whole.reflectance
    wl = refl.wavelength_nm
    report = sample_indices(wl, wiener.reflectance.wavelength_nm)
    # F and the prior exactly as the estimate used them (integrated_lighting_matrix)
    F, K = whole.lighting, whole.prior_covariance
    assert F is not None and K is not None
    m_rows = F.shape[0]
    n_p = len(responses.patches)
    diag, used = whole.noise_variance.reshape(n_p, m_rows), whole.k_e
    rgb = responses.rgb.reshape(n_p, m_rows)
    jacobians = _f_jacobians(calibration, responses, illuminants)
    terms = _response_error_terms(responses, illuminants, calibration, refl, jacobians)
    noise_all = sum(terms.values())
    # each target's prior as the estimate used it, or (an estimate with the prior
    # set's for all) fitted here for the mismatch term alone
    priors = whole.target_priors or fit_target_priors(whole, responses, rgb, noise_all)
    n = wl.size
    kappa2 = float(PRIOR_MISMATCH_SCALE if prior_scale is None else prior_scale) ** 2
    cov, cov_prior = np.empty((n_p, n, n)), np.empty((n_p, n, n))
    edge = blind_edge_factor(F, diag, edge_scale)
    # each term's share of every reflectance variance, and its XYZ covariance
    term_var = {t: np.empty((n_p, n)) for t in terms}
    term_xyz = {t: np.empty((n_p, 3, 3)) for t in terms}
    T = np.zeros((n, 3))  # XYZ = r @ T: the colour of the reported samples
    T[report] = astm_e308_weights_d50(wl[report])
    moves = _MovesOfF(whole, responses, jacobians)
    for lo in range(0, n_p, _CHUNK):
        hi = min(lo + _CHUNK, n_p)
        rows = slice(lo, hi)
        Kp = priors.covariance(K, rows)
        # W' = A^-1 F K with A = F K F' + K_e and K as the estimate used them
        Ku = K if whole.target_priors is None else priors.scaled(K, rows)
        FK, G = prior_gram(F, Ku)
        W = solve_with_noise(G, used[rows], FK).transpose(0, 2, 1)
        IWF = np.eye(n) - W @ F
        P = IWF @ (kappa2 * Kp) @ IWF.transpose(0, 2, 1)
        P *= edge[rows, :, None] * edge[rows, None, :]
        E = P.copy()  # + W N W' term by term: the budget's parts add up to it
        u, posterior = moves.weights(G, used[rows], rows), IWF @ Ku
        for t, N in terms.items():
            Et = moves.covariance(t, N[lo:hi], slice(lo, hi), W, posterior, u)
            E += Et
            term_var[t][lo:hi] = np.diagonal(Et, axis1=1, axis2=2)
            term_xyz[t][lo:hi] = T.T[None] @ Et @ T[None]
        cov[lo:hi] = 0.5 * (E + E.transpose(0, 2, 1))
        cov_prior[lo:hi] = 0.5 * (P + P.transpose(0, 2, 1))
    xyz = refl.values @ T
    xyz_cov = T.T[None] @ cov @ T[None]
    lab = xyz_to_lab_d50(xyz)
    lab_cov = lab_covariance(xyz, xyz_cov)
    lab_cov_prior = lab_covariance(xyz, T.T[None] @ cov_prior @ T[None])
    prior_var = np.diagonal(cov_prior, axis1=1, axis2=2).copy()
    lab_prior_var = np.diagonal(lab_cov_prior, axis1=1, axis2=2).copy()
    budget = {"prior mismatch": (prior_var, lab_prior_var)}
    budget |= _budget_terms(xyz, term_var, term_xyz)
    cov, budget = _reported(report, cov, budget)
    # A reflectance factor lies in [0, 1] (as the clipped estimate does), so its
    # standard deviation cannot exceed 0.5 (Popoviciu's inequality); the linear
    # model can claim more where the LEDs see nothing.
    std = np.minimum(np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0)), 0.5)
    return ReflectanceUncertainty(
        covariance=cov,
        reflectance_std=std,
        xyz=xyz,
        xyz_std=np.sqrt(np.maximum(np.diagonal(xyz_cov, axis1=1, axis2=2), 0.0)),
        lab=lab,
        lab_std=np.sqrt(np.maximum(np.diagonal(lab_cov, axis1=1, axis2=2), 0.0)),
        lab_covariance=lab_cov,
        generic_sigma=priors.sigma,
        generic_length_nm=priors.length_nm,
        prior_part_variance=budget["prior mismatch"][0],
        lab_prior_part_variance=lab_prior_var,
        budget=budget,
        chi2_per_response=priors.chi2_per_response,
        misfit_by_light=_misfit_by_light(whole, responses, rgb, noise_all),
    )


def _reported(
    report: NDArray[np.intp],
    cov: NDArray[np.float64],
    budget: dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]],
) -> tuple[NDArray[np.float64], dict[str, tuple[NDArray[np.float64], ...]]]:
    """The covariances and the budget's reflectance variances on the reported
    samples ``report`` of Eq. 5's (all of them: as they are)."""
    if report.size == cov.shape[1]:
        return cov, budget
    cut = {t: (r[:, report], lab) for t, (r, lab) in budget.items()}
    return cov[:, report][:, :, report], cut


def _misfit_by_light(
    wiener: WienerEstimate,
    responses: Responses,
    rgb: NDArray[np.float64],
    noise: NDArray[np.float64],
) -> NDArray[np.float64]:
    """To say where a misfit is: the estimate's mean squared standardised residual
    under each light (n_i,), saturated responses left out."""
    F = wiener.lighting
    assert F is not None
    noise_fit = checked_noise_covariance(noise, responses, F.shape[0])
    residual = rgb - wiener.reflectance.values @ F.T
    z2 = residual**2 / np.diagonal(noise_fit, axis1=1, axis2=2)
    return np.nanmean(z2.reshape(rgb.shape[0], -1, 3), axis=(0, 2))


def wiener_with_uncertainty(
    responses: Responses,
    illuminants_fine: Spectra,
    sensitivity_fine: Spectra,
    prior: Spectra,
    illuminants: Spectra,
    calibration: SensitivityEstimate | None,
    *,
    noise_std: float | None = None,
    center_prior: bool = True,
    clip: bool = True,
    grid: Grid | None = None,
) -> tuple[WienerEstimate, ReflectanceUncertainty | None]:
    """Eq. 5 with the responses' whole error model as ``K_e``, and its uncertainty.

    Eq. 6 takes ``K_e`` from the ROI's per-pixel variance, a regulariser that
    knows nothing of the errors a patch's responses share. With a calibration that
    carries its covariance (``"bayes"``) the error model is known: the ROI means'
    noise, the flat-field residual and the systematic errors the chart's residuals
    showed (:mod:`tunespec.core.excess`), and the calibration's own uncertainty
    through Eq. 1 (:func:`_response_error_terms`). Used as ``K_e``, Eq. 5 is the
    linear minimum-variance estimate under that model with the prior set's
    covariance (Kay, *Fundamentals of Statistical Signal Processing I*, 1993, ch.
    12). On ``benchmarks/generalisation.py`` under issue 23's conditions it lowers
    the mean CIEDE2000 of every family (see docs/validation.md). The model is
    evaluated at a first, Eq. 6 estimate (the calibration term depends on the
    reflectance through Eq. 1). Then each target's prior is fitted to its responses
    (:func:`~tunespec.core.target_prior.fit_target_priors`) and Eq. 5 solved again
    with the prior set's covariance scaled to it
    (:func:`~tunespec.core.wiener.with_target_priors`).

    Without such a calibration, without per-pixel deviations, or with one noise
    level for all (``noise_std``) the first two steps are Eq. 5-6 as the paper has
    it.

    With a reporting ``grid`` the reflectance is solved for on
    :func:`~tunespec.core.wiener.support_grid`'s samples (the whole range the light
    covers, where the prior is known) and reported on ``grid``'s, its colour theirs.

    Parameters
    ----------
    responses, noise_std, center_prior, clip
        As :func:`~tunespec.core.wiener.wiener_reflectance` takes them.
    prior
        The prior's reflectances: on the estimation grid (without ``grid``), or on
        any grid that covers it (resampled to its support here).
    illuminants_fine, sensitivity_fine
        Eq. 1's illuminants (corrected as the calibration found) and sensitivities
        on the integration grid (:func:`~tunespec.core.wiener.on_integration_grid`).
    illuminants
        The target capture's spectra as reported (uncorrected), as
        :func:`reflectance_uncertainty` takes them.
    calibration
        The sensitivity estimate (None: no uncertainty).
    grid
        Where the reflectance is reported (default: the prior's grid, solved for
        alone).

    Returns
    -------
    (WienerEstimate, ReflectanceUncertainty or None)
        On ``grid`` (:meth:`~tunespec.core.wiener.WienerEstimate.restricted`).
    """
    kw = {"noise_std": noise_std, "center_prior": center_prior, "clip": clip}
    if grid is not None:
        prior = prior_on_support(prior, grid, illuminants_fine.wavelength_nm)

    def reported(estimate: WienerEstimate) -> WienerEstimate:
        return estimate if grid is None else estimate.restricted(grid)

    first = wiener_reflectance(
        responses, illuminants_fine, sensitivity_fine, prior, **kw
    )
    if calibration is None or calibration.covariance is None:
        return reported(first), None
    est = first
    if noise_std is None and responses.rgb_std is not None:
        # the readings' term enters the uncertainty only: a sample covariance of a
        # few replicates, as K_e (whole, or its diagonal) it moved the IR-cut
        # camera's estimate 0.100 -> 0.110-0.116 mean dE00
        # (benchmarks/generalisation.py, 0.3 % readings, --systematic)
        terms = _response_error_terms(
            responses, illuminants, calibration, first.reflectance, readings=False
        )
        est = wiener_reflectance(
            responses, illuminants_fine, sensitivity_fine, prior, **kw,
            noise_covariance=sum(terms.values()),
        )  # fmt: skip
    # each target's own prior, fitted to its responses with their whole error model
    # at this estimate, and Eq. 5 again with it
    noise_all = sum(
        _response_error_terms(responses, illuminants, calibration, est.reflectance)
        .values()
    )  # fmt: skip
    n_p = len(responses.patches)
    rgb = responses.rgb.reshape(n_p, -1)
    est = reported(
        with_target_priors(
            est, responses, fit_target_priors(est, responses, rgb, noise_all)
        )
    )
    return est, reflectance_uncertainty(est, responses, illuminants, calibration)


def blind_edge_factor(
    F: NDArray[np.float64],
    noise_variance: NDArray[np.float64],
    scale: float = BLIND_EDGE_SCALE,
) -> NDArray[np.float64]:
    """Per target and wavelength, ``1 + gamma b`` (``scale``, default
    :data:`BLIND_EDGE_SCALE`): ``b`` is 1 where Eq. 1 sees nothing of the wavelength
    and falls linearly to 0 at the visibility :data:`BLIND_VISIBILITY`.

    The visibility of wavelength ``l`` for a target is ``sqrt(sum_j F_jl^2 / v_j)``
    (``v_j`` its responses' noise variances as Eq. 5 used them) relative to its
    largest over the wavelengths: what one unit of reflectance there adds to the
    responses, in units of their noise. (n_p, n_wl)."""
    vis = np.sqrt(
        np.einsum("jl,pj->pl", F**2, 1.0 / np.maximum(noise_variance, 1e-300))
    )
    vis /= np.maximum(vis.max(axis=1, keepdims=True), 1e-300)
    blind = np.clip(1.0 - vis / BLIND_VISIBILITY, 0.0, 1.0)
    return 1.0 + scale * blind


def _budget_terms(
    xyz: NDArray[np.float64],
    term_var: dict[str, NDArray[np.float64]],
    term_xyz: dict[str, NDArray[np.float64]],
) -> dict[str, tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The response terms of the budget, in :data:`BUDGET_TERMS` order: each
    one's reflectance variance and its CIELAB variance (from its XYZ covariance)."""
    return {
        t: (
            term_var[t],
            np.diagonal(lab_covariance(xyz, term_xyz[t]), axis1=1, axis2=2).copy(),
        )
        for t in BUDGET_TERMS[1:]
        if t in term_var
    }


def budget_summary(unc: ReflectanceUncertainty) -> dict[str, dict[str, float]]:
    """The uncertainty budget of a set of estimates, term by term.

    For every term of :attr:`ReflectanceUncertainty.budget`: ``share_L`` its share
    of the variance of L* and ``share_reflectance`` of the reflectances' variance
    (both summed over the patches, and over the wavelengths, before the ratio: the
    shares add up to 1), and ``u_L_median`` the median over the patches of the
    standard uncertainty of L* it alone would give.
    """
    if not unc.budget:
        return {}
    total_l = sum(float(np.sum(lab[:, 0])) for _, lab in unc.budget.values())
    total_r = sum(float(np.sum(r)) for r, _ in unc.budget.values())
    return {
        term: {
            "share_L": float(np.sum(lab[:, 0])) / total_l if total_l > 0 else 0.0,
            "share_reflectance": float(np.sum(r)) / total_r if total_r > 0 else 0.0,
            "u_L_median": float(np.median(np.sqrt(np.maximum(lab[:, 0], 0.0)))),
        }
        for term, (r, lab) in unc.budget.items()
    }
