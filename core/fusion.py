"""Fusion: spectra at every geometry from dense single-shot XYZ and sparse spectral data.

A gonio-imager captures the full 22-LED sequence (Eq. 5-6: spectra) at a few
geometries and one RGB shot under the D50-matched mix (single-shot XYZ) at every
geometry. The dense spectral BRDF is computed from both, "subject to a high
colorimetric accuracy for the considered illuminant" (the paper's conclusion).

For a patch of a dielectric material (a body reflectance under a spectrally flat
surface reflection, :func:`tunespec.devices.sim.gonio.brdf_reflectance_factor`) every
reflectance factor lies close to ``span{rho, 1}``: the body's spectrum, scaled by the
Fresnel transmission, plus a flat specular part. So at a single-shot geometry:

1. a *prior spectrum* ``R0 = a rho_hat + b`` is fitted to the patch's camera
   responses there, by least squares through Eq. 1 (``rgb = S diag(i) R``), with
   ``rho_hat`` the patch's least specular spectral estimate;
2. it is then corrected to reproduce the measured XYZ exactly, with the smallest
   change in the metric of a covariance spanned by the patch's spectral estimates and
   the flat vector (the constrained least-squares / Lagrange solution)::

       R = R0 + C W (W^T C W)^-1 (XYZ - W^T R0),     C = B B^T + eps I

   ``W`` the D50 weighting table (ASTM E308), ``B`` = [spectral estimates, flat].

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), introduction and conclusion (single-shot XYZ and sparse
spectral captures for a dense spectral BRDF), Eq. 1; ASTM E308-15 (weights);
R. L. Cook, K. E. Torrance (1982) (body + surface reflection of dielectrics).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.colorimetry import astm_e308_weights_d50
from tunespec.core.errors import InputError

__all__ = ["FusedSpectra", "fuse_patch", "fused_covariance", "material_prior"]

#: Relative ridge of the correction covariance (keeps it positive definite).
_EPS = 1e-6


@dataclass(frozen=True, eq=False)
class FusedSpectra:
    """One patch's fused spectrum at one geometry.

    ``reflectance`` (n_wl,); ``prior`` the spectrum before the XYZ constraint;
    ``coefficients`` ``(a, b)`` of the prior fit; ``xyz_residual`` what the constraint
    removed (XYZ of the prior minus the measured XYZ).
    """

    reflectance: NDArray[np.float64]
    prior: NDArray[np.float64]
    coefficients: tuple[float, float]
    xyz_residual: NDArray[np.float64]


def material_prior(
    spectral: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``rho_hat`` (the least specular spectral estimate) and the basis ``B``.

    Parameters
    ----------
    spectral : (n_s, n_wl)
        The patch's reflectance-factor estimates at the spectral geometries.

    Returns
    -------
    rho_hat : (n_wl,)
    basis : (n_wl, n_s + 1)
        The estimates and a flat vector (the specular direction).
    """
    R = np.atleast_2d(np.asarray(spectral, dtype=np.float64))
    if R.shape[0] < 1 or not np.all(np.isfinite(R)):
        raise InputError("fusion needs at least one finite spectral estimate per patch")
    rho = R[int(np.argmin(R.mean(axis=1)))]
    return rho, np.column_stack([R.T, np.ones(R.shape[1])])


def fuse_patch(
    rgb: ArrayLike,
    xyz: ArrayLike,
    spectral: ArrayLike,
    camera_matrix: ArrayLike,
    wavelength_nm: ArrayLike,
    *,
    rgb_var: ArrayLike | None = None,
) -> FusedSpectra:
    """The fused spectrum of one patch at one single-shot geometry.

    Parameters
    ----------
    rgb : (3,)
        The patch's responses under the mix at this geometry.
    xyz : (3,)
        Its measured XYZ (D50, white Y = 100; the single-shot transform's output).
    spectral : (n_s, n_wl)
        The patch's spectral estimates at the spectral geometries.
    camera_matrix : (3, n_wl)
        ``S diag(i) dl`` of the mix at this geometry (Eq. 1), so ``rgb = M R``.
    wavelength_nm : (n_wl,)
    rgb_var : (3,), optional
        Noise variances weighting the prior fit.

    Returns
    -------
    FusedSpectra
        Reproduces ``xyz`` (to rounding) with ``W`` of ASTM E308 on this grid.
    """
    c = np.asarray(rgb, dtype=np.float64)
    target = np.asarray(xyz, dtype=np.float64)
    M = np.asarray(camera_matrix, dtype=np.float64)
    W = astm_e308_weights_d50(wavelength_nm)
    rho, B = material_prior(spectral)
    if M.shape != (3, rho.size) or c.shape != (3,) or target.shape != (3,):
        raise InputError(
            f"fusion: rgb (3,), xyz (3,), camera matrix (3, {rho.size}) expected"
        )
    w = (
        1.0 / np.sqrt(np.maximum(np.asarray(rgb_var, dtype=np.float64), 1e-30))
        if rgb_var is not None
        else np.ones(3)
    )
    from scipy.optimize import lsq_linear

    A = np.column_stack([M @ rho, M @ np.ones(rho.size)]) * w[:, None]
    # a >= 0 and the prior non-negative where rho is smallest: b >= -a min(rho)
    # is enforced through b >= -min(rho) * a_ls (one pass is enough here)
    a, b = lsq_linear(A, c * w, bounds=([0.0, -np.inf], [np.inf, np.inf])).x
    b = max(b, -a * float(rho.min()))
    R0 = a * rho + b
    CW = _correction_cov(B) @ W
    resid = W.T @ R0 - target
    R = R0 - CW @ np.linalg.solve(W.T @ CW, resid)
    if R.min() < 0.0:
        R = _nonnegative(R0, B, W, target)
    return FusedSpectra(R, R0, (float(a), float(b)), resid)


def _correction_gain(
    B: NDArray[np.float64], W: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``G = C W (W^T C W)^-1`` (n_wl, 3): how the fused spectrum moves with the
    measured XYZ (``R = R0 + G (XYZ - W^T R0)``)."""
    CW = _correction_cov(B) @ W
    return CW @ np.linalg.inv(W.T @ CW)


def _correction_cov(B: NDArray[np.float64]) -> NDArray[np.float64]:
    """``C = B B^T + eps I``, the metric of the smallest correction."""
    C = B @ B.T
    C += _EPS * np.trace(C) / B.shape[0] * np.eye(B.shape[0])
    return C


def fused_covariance(
    spectral: ArrayLike,
    wavelength_nm: ArrayLike,
    xyz_cov: ArrayLike,
    prior_cov: ArrayLike,
) -> NDArray[np.float64]:
    """Covariance of a fused spectrum (:func:`fuse_patch`), first order.

    The fused spectrum is ``R = P R0 + G XYZ`` with ``G = C W (W^T C W)^-1`` and
    ``P = I - G W^T``: the measured XYZ sets what the D50 colour matching functions
    see, the prior spectrum ``R0 = a rho_hat + b`` the rest. So (GUM, law of
    propagation, the two inputs independent)::

        cov(R) = G cov(XYZ) G^T + P cov(R0) P^T

    and ``W^T cov(R) W = cov(XYZ)`` exactly: the fused spectrum's colour is as
    uncertain as the single shot's.

    Parameters
    ----------
    spectral : (n_s, n_wl)
        The patch's spectral estimates (as given to :func:`fuse_patch`).
    wavelength_nm : (n_wl,)
    xyz_cov : (3, 3)
        Covariance of the measured XYZ (white Y = 100).
    prior_cov : (n_wl, n_wl) or (n_wl,)
        Covariance (or variances) of the prior spectrum ``R0``: ``a^2`` times that
        of ``rho_hat``, the spectral estimate it is built from.

    Returns
    -------
    (n_wl, n_wl)

    References
    ----------
    JCGM 100:2008 (GUM), section 5.
    """
    W = astm_e308_weights_d50(wavelength_nm)
    _, B = material_prior(spectral)
    G = _correction_gain(B, W)
    P = np.eye(G.shape[0]) - G @ W.T
    K0 = np.asarray(prior_cov, dtype=np.float64)
    if K0.ndim == 1:
        K0 = np.diag(K0)
    Kx = np.asarray(xyz_cov, dtype=np.float64)
    if K0.shape != (G.shape[0],) * 2 or Kx.shape != (3, 3):
        raise InputError(
            f"fusion covariance: XYZ (3, 3) and prior ({G.shape[0]},) or "
            f"({G.shape[0]}, {G.shape[0]}) expected"
        )
    return G @ Kx @ G.T + P @ K0 @ P.T


#: XYZ (white Y = 100) the non-negative correction must reproduce to.
_XYZ_TOL = 1e-6


def _nonnegative(
    R0: NDArray[np.float64],
    B: NDArray[np.float64],
    W: NDArray[np.float64],
    target: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The smallest correction ``B c`` with ``W^T (R0 + B c) = XYZ`` and ``R >= 0``.

    A small quadratic programme (SLSQP over the basis coefficients); used when the
    closed-form correction goes negative (a saturated colour's far end). Where the
    basis cannot reach ``XYZ`` without going negative, the nearest non-negative
    spectrum to ``R0`` on the whole grid that reproduces it (SLSQP with bounds).
    """
    from scipy.optimize import minimize

    scale = np.linalg.norm(B, axis=0)
    Bn = B / scale
    res = minimize(
        lambda x: float(x @ x),
        np.zeros(B.shape[1]),
        jac=lambda x: 2.0 * x,
        method="SLSQP",
        constraints=[
            {"type": "eq", "fun": lambda x: (W.T @ (R0 + Bn @ x) - target) / 100.0},
            {"type": "ineq", "fun": lambda x: R0 + Bn @ x},
        ],
        options={"maxiter": 200, "ftol": 1e-12},
    )
    R = np.maximum(R0 + Bn @ res.x, 0.0)
    if np.abs(W.T @ R - target).max() <= _XYZ_TOL:
        return R
    # the basis cannot reach the XYZ with R >= 0: the nearest non-negative spectrum
    # on the full grid that does (exists for any XYZ inside the spectral-locus cone)
    full = minimize(
        lambda r: float((r - R0) @ (r - R0)),
        np.maximum(R0, 0.0),
        jac=lambda r: 2.0 * (r - R0),
        method="SLSQP",
        bounds=[(0.0, None)] * R0.size,
        constraints=[{"type": "eq", "fun": lambda r: (W.T @ r - target) / 100.0,
                      "jac": lambda r: W.T / 100.0}],
        options={"maxiter": 500, "ftol": 1e-14},
    )  # fmt: skip
    return np.maximum(full.x, 0.0)
