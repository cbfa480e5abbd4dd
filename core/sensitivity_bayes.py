"""Empirical-Bayes camera sensitivities with per-LED self-calibration of the light source.

The model is Eq. 3 of the paper with the light source's metering error made explicit.
The spectroradiometer reports ``i'_j``; the true spectrum of LED ``j`` is taken to be::

    i_j(l) = g_j i'_j(l + d_j),        g_j = exp(gamma_j)

a gain error ``g_j`` and a wavelength offset ``d_j`` per LED (the offsets share a common
part ``d_0``, the instrument's wavelength-scale error). Responses are
``c_k(p, j) = sum_l s_k(l) i_j(l) r_p(l) dl + e`` with ``e ~ N(0, phi_k v_pjk)``,
``v`` the known relative variances (ROI noise, flat-field and metering floor) and
``phi_k`` an unknown noise scale per channel.

Priors, all of them scale-free and none tuned on a camera:

* sensitivities: ``s_k ~ N(0, phi_k (t_k Lambda_k)^-1)`` with the precision
  ``Lambda = lambda (Omega + a I) + mu Q`` -- ``Omega`` the second-difference
  smoothness penalty, ``a`` (:data:`BAYES_AMPLITUDE`) a weak amplitude term that makes
  the prior proper, ``Q = I - P'P`` the squared distance to the camera database's
  principal subspace of that channel, ``t_k`` the mean diagonal of the data's normal
  matrix (units);
* ``(lambda, mu)`` per channel by maximising the marginal likelihood (the
  evidence, with ``phi_k`` profiled out: Wahba's generalised maximum likelihood)
  over a grid that includes ``mu = 0``, so a camera unlike the database turns the
  database off by itself and one like it uses it;
* light source: ``gamma_j ~ N(0, SIGMA_GAIN^2)`` constrained to ``sum gamma_j = 0``
  (the overall scale stays with the sensitivities), ``d_j ~ N(d_0, SIGMA_SHIFT_NM^2)``
  with a flat prior on ``d_0``. The widths are the light source's metering accuracy
  (about 1-2 % in power and 1 nm in wavelength for a compact array
  spectroradiometer), a property of the instrument, not of a camera.

The sensitivities and the corrections are found jointly (Gauss-Newton with variable
projection: for fixed corrections the sensitivities solve a linear problem), the final
sensitivities are non-negative (NNLS at the chosen hyper-parameters), and the Laplace
approximation at the solution gives the joint covariance of sensitivities and
corrections, the uncertainty that :mod:`tunespec.core.uncertainty` propagates into
reflectances and colorimetry.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Eq. 1 and 3. G. Wahba, "A comparison of GCV and GML for choosing
the smoothing parameter in the generalized spline smoothing problem", Annals of
Statistics 13 (1985) 1378-1402 (the profiled marginal likelihood). D. J. C. MacKay,
"Bayesian interpolation", Neural Computation 4 (1992) 415-447 (evidence for
regularisation constants). G. H. Golub, V. Pereyra, "The differentiation of
pseudo-inverses and nonlinear least squares problems whose variables separate", SIAM J.
Numer. Anal. 10 (1973) 413-432 (variable projection). P. Urban et al., "Recovering
camera sensitivities using target-based reflectances captured under multiple LED
illuminations", Workshop on Color Image Processing 2010 (the multi-LED setting).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.optimize import nnls

from tunespec.core.errors import SingularSystemError
from tunespec.core.led_correction import _corrected
from tunespec.core.progress import StopFn, check_stop

__all__ = [
    "BAYES_AMPLITUDE",
    "BAYES_LAMBDAS",
    "BAYES_MUS",
    "CORRECTION_MODES",
    "ROUGHNESS_CAP_FACTOR",
    "SIGMA_GAIN",
    "SIGMA_SHIFT_NM",
    "BayesFit",
    "database_roughness",
    "fit_bayes",
    "roughness",
]

#: Candidate smoothness weights ``lambda`` (relative to the data's mean diagonal).
BAYES_LAMBDAS = np.logspace(-9.0, 1.0, 21)
#: Candidate database weights ``mu``; 0 = no database prior at all.
BAYES_MUS = np.concatenate([[0.0], np.logspace(-6.0, 1.0, 8)])
#: Amplitude term of the smoothness prior, relative to ``Omega`` (mean diagonal 1):
#: ``lambda (Omega + BAYES_AMPLITUDE I)`` gives the linear trends that ``Omega`` does
#: not see a variance 10^6 times that of the curvature -- effectively flat, but proper,
#: so that the evidence can compare priors. Results are the same for 1e-6 ... 1e-4;
#: a *free* amplitude weight is not used: the evidence then prefers a white
#: (ridge-only) prior that fits the noise.
BAYES_AMPLITUDE = 1e-6
#: Prior standard deviation of each LED's reported power (relative): the power
#: accuracy of the light source's spectroradiometer per LED.
SIGMA_GAIN = 0.02
#: Prior standard deviation of each LED's wavelength offset about the common one (nm).
SIGMA_SHIFT_NM = 1.0
#: Gauss-Newton iterations of the joint fit (the problem is nearly linear).
_MAX_ITER = 12
_TOL_SHIFT_NM = 1e-3
_TOL_GAIN = 1e-5


@dataclass(frozen=True, eq=False)
class BayesFit:
    """Result of :func:`fit_bayes`.

    ``S`` (3, n) sensitivities; ``gain`` (n_i,) and ``shift_nm`` (n_i,) the per-LED
    corrections (``i_j(l) = gain_j * reported_j(l + shift_j)``); ``shift0_nm`` their
    common offset; ``covariance`` (3 n + 2 n_i, 3 n + 2 n_i) the joint posterior
    covariance of ``(s_R, s_G, s_B, log gain, shift_nm)``; ``params`` the
    hyper-parameters and diagnostics (JSON-friendly); ``replicates`` per spectra of
    ``replicate_spectra`` its ``(S, gain, shift_nm)`` (:func:`_replicate_fit`).
    """

    S: NDArray[np.float64]
    gain: NDArray[np.float64]
    shift_nm: NDArray[np.float64]
    shift0_nm: float
    covariance: NDArray[np.float64]
    params: dict[str, Any]
    replicates: tuple[tuple[NDArray[np.float64], ...], ...] = ()


@dataclass(frozen=True)
class _Data:
    """Patch-wise sufficient statistics of the weighted problem (weights 1 / v)."""

    R: NDArray[np.float64]  # (n_p, n)
    C: NDArray[np.float64]  # (n_p, n_i, 3)
    W: NDArray[np.float64]  # (n_p, n_i, 3), 1 / v
    M: NDArray[np.float64]  # (n_i, 3, n, n): sum_p w r r'
    V: NDArray[np.float64]  # (n_i, 3, n): sum_p w c r
    cc: NDArray[np.float64]  # (3,): sum w c^2
    step: float

    @property
    def m(self) -> int:
        return self.C.shape[0] * self.C.shape[1]


def _data(
    R: NDArray[np.float64],
    C: NDArray[np.float64],
    var: NDArray[np.float64],
    step: float,
) -> _Data:
    n_p, n_i, _ = C.shape
    n = R.shape[1]
    W = 1.0 / var
    RR = (R[:, :, None] * R[:, None, :]).reshape(n_p, n * n)
    M = (W.reshape(n_p, n_i * 3).T @ RR).reshape(n_i, 3, n, n)
    V = np.einsum("pik,pl->ikl", W * C, R)
    cc = np.einsum("pik,pik->k", W, C * C)
    return _Data(R, C, W, M, V, cc, step)


def _normal(data: _Data, L: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """``G_k = A_k' W A_k`` (3, n, n) and ``b_k = A_k' W c_k`` (3, n) for spectra L."""
    Ls = L * data.step
    G = np.einsum("il,im,iklm->klm", Ls, Ls, data.M, optimize=True)
    b = np.einsum("il,ikl->kl", Ls, data.V)
    return G, b


def _normal_at(data: _Data, wl: NDArray, L_rep: NDArray) -> Any:
    """``state -> (G, b)``: :func:`_normal` at the spectra ``L_rep`` corrected as
    ``state`` says."""

    def normal(st: _State) -> tuple[NDArray, NDArray]:
        Lc, _ = _corrected(wl, L_rep, np.exp(st.gamma), st.shift)
        return _normal(data, Lc)

    return normal


def _smoothness_penalty(n: int) -> NDArray[np.float64]:
    """``D2' D2`` (n, n) of the second difference, scaled to mean diagonal 1."""
    D2 = np.diff(np.eye(n), 2, axis=0)
    Om = D2.T @ D2
    Om *= n / np.trace(Om)
    return Om


def _subspace_penalty(P: NDArray | None, n: int) -> NDArray[np.float64]:
    """``I - P' P`` (n, n), the squared distance to the span of ``P``'s rows, scaled
    to mean diagonal 1; zeros without a basis (no database prior)."""
    if P is None:
        return np.zeros((n, n))
    Q = np.eye(n) - P.T @ P
    Q *= n / max(np.trace(Q), 1.0)
    return Q


def _penalties(n: int, bases: list[NDArray | None]) -> tuple[NDArray, list[NDArray]]:
    """Smoothness ``Omega`` and per-channel subspace ``Q_k``, each mean diagonal 1."""
    return _smoothness_penalty(n), [_subspace_penalty(P, n) for P in bases]


def _logdet(A: NDArray[np.float64]) -> float | None:
    try:
        c, _ = cho_factor(A, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    return 2.0 * float(np.sum(np.log(np.diag(c))))


def _evidence(
    G: NDArray, b: NDArray, cc: float, m: int, t: float, Lam: NDArray
) -> float:
    """-2 log marginal likelihood with the noise scale profiled out (up to a constant).

    ``c ~ N(0, phi (V + A (t Lam)^-1 A'))``; with ``H = G + t Lam``:
    ``m log(RSS/m) + log|H| - log|t Lam|``, ``RSS = c'V^-1 c - b' H^-1 b``.
    """
    H = G + t * Lam
    try:
        f = cho_factor(H, lower=True, check_finite=False)
    except np.linalg.LinAlgError:
        return np.inf
    rss = cc - float(b @ cho_solve(f, b, check_finite=False))
    ld_lam = _logdet(t * Lam)
    if ld_lam is None or not rss > 0:
        return np.inf
    ld_h = 2.0 * float(np.sum(np.log(np.diag(f[0]))))
    return m * np.log(rss / m) + ld_h - ld_lam


def _choose(
    G: NDArray,
    b: NDArray,
    cc: float,
    m: int,
    Om: NDArray,
    Q: NDArray,
    use_db: bool,
    should_stop: StopFn | None,
    max_roughness: float | None = None,
) -> tuple[float, float, float]:
    """Hyper-parameters ``(lambda, mu)`` of one channel maximising the evidence.

    A grid search (the evidence can have two local optima), refined in ``lambda``
    by a factor-of-two grid around the best point, then stiffened where the curve
    is rougher than ``max_roughness`` (:func:`roughness`; see
    :data:`ROUGHNESS_CAP_FACTOR`). Returns ``(lambda, mu, -2 log evidence)``.
    Where the Gaussian posterior mean rings below zero the evidence's prior stays:
    the final curve is the non-negative fit at it (:func:`_solve_s`).
    """
    n = G.shape[0]
    t = float(np.trace(G)) / n
    if not t > 0:
        raise SingularSystemError("the stimuli carry no light (all zero)")
    Om_a = Om + BAYES_AMPLITUDE * np.eye(n)
    best = (np.inf, 0.0, 0.0)
    for mu in BAYES_MUS if use_db else (0.0,):
        check_stop(should_stop)
        for lam in BAYES_LAMBDAS:
            e = _evidence(G, b, cc, m, t, lam * Om_a + mu * Q)
            if e < best[0]:
                best = (e, float(lam), float(mu))
    if not np.isfinite(best[0]):
        raise SingularSystemError("no regularisation makes the system solvable")
    _, lam0, mu = best
    for lam in lam0 * np.array([0.25, 0.5, 2.0, 4.0]):
        e = _evidence(G, b, cc, m, t, lam * Om_a + mu * Q)
        if e < best[0]:
            best = (e, float(lam), mu)
    e, lam, mu = best
    # Plausibility check: no camera ever measured is as rough as a curve that
    # oscillates from one sample to the next; such a curve absorbs what the data
    # cannot attribute (per-LED metering error a small chart cannot separate from
    # the sensitivity). Stiffen until it is no rougher than the cap, whatever the
    # misfit: the corrections take up the rest in the next round.
    if max_roughness is not None:
        while lam < BAYES_LAMBDAS[-1] and (
            roughness(_nnls_quadratic(G + t * (lam * Om_a + mu * Q), b), Om)
            > max_roughness
        ):
            lam *= 2.0
        e = _evidence(G, b, cc, m, t, lam * Om_a + mu * Q)
    return lam, mu, e


#: The cap on a fitted curve's :func:`roughness`, as a multiple of the roughest
#: curve of the channel in the camera database, on the calibration's own grid (52
#: cameras on 380-730 nm at 2 nm: R 1.6e-4, G 5.7e-5, B 1.9e-4): no curve rougher
#: than any camera ever measured. Calibrations that fit the data are 5 to 30 times
#: smoother than that (the prior smooths); a ColorChecker 24 at bench seed 1 gave a G
#: 116 times rougher (sensitivity RMS 0.129, 0.019 capped). On the generalisation
#: benchmark (whole sources left out of the database, the cap computed without them)
#: it touches 18 of 180 default fits and leaves the mean dE00 at 0.0673. Only with
#: per-LED corrections, which take up what the stiffer curve leaves: without them a
#: rough curve is all that absorbs metering error, and capping it cost reflectance
#: accuracy there (bayes-noselfcal: mean dE00 0.095 -> 0.103, though the median
#: sensitivity RMS per family fell from 0.13-0.30 to 0.04-0.08).
ROUGHNESS_CAP_FACTOR = 1.0


def roughness(s: NDArray[np.float64], Om: NDArray[np.float64]) -> float:
    """``s' Omega s / s's``: a curve's mean squared second difference relative to its
    energy (``Omega`` of :func:`_smoothness_penalty`); scale-free."""
    energy = float(s @ s)
    return float(s @ Om @ s) / energy if energy > 0 else 0.0


def database_roughness(database_curves: NDArray[np.float64]) -> float:
    """The largest :func:`roughness` of a channel's database curves (n_cameras, n)."""
    Om = _smoothness_penalty(database_curves.shape[1])
    return max(roughness(s, Om) for s in np.asarray(database_curves, dtype=float))


def _nnls_quadratic(H: NDArray, b: NDArray) -> NDArray:
    """``argmin_{s >= 0} s'Hs - 2 b's`` for positive definite ``H``.

    The augmented non-negative least-squares problem ``min ||[W A; Q^1/2] s -
    [W c; 0]||`` compressed to its normal matrix ``H = A' W' W A + Q``: with
    ``H = L L'`` it equals ``min ||L' s - L^-1 b||``, an n_wl x n_wl NNLS problem
    instead of an (m + n_wl) x n_wl one.
    """
    try:
        L = np.linalg.cholesky(H)
    except np.linalg.LinAlgError:
        raise SingularSystemError(
            "the regularised normal matrix is not positive definite"
        ) from None
    rhs = solve_triangular(L, b, lower=True)
    s, _ = nnls(L.T, rhs, maxiter=50 * H.shape[0])
    return s


@dataclass
class _State:
    gamma: NDArray[np.float64]  # (n_i,) log gains, sum 0
    shift: NDArray[np.float64]  # (n_i,)
    shift0: float


def _channel_precisions(
    G: NDArray, Om: NDArray, Qs: list[NDArray], hyper: list[tuple[float, float, float]]
) -> list[NDArray]:
    n = Om.shape[0]
    out = []
    for k in range(3):
        lam, mu = hyper[k]
        t = float(np.trace(G[k])) / n
        out.append(t * (lam * (Om + BAYES_AMPLITUDE * np.eye(n)) + mu * Qs[k]))
    return out


def _jacobian_blocks(
    data: _Data, Lc: NDArray, dL: NDArray, S: NDArray, phi: NDArray
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """Blocks of ``J'WJ`` and ``J'W e`` for the corrections, given sensitivities S.

    Returns ``Hsg, Hsd`` (3, n, n_i): coupling of ``s_k`` with ``gamma_j`` and
    ``d_j``; ``Hc`` (3, n_i): the diagonal correction blocks ``Hgg, Hgd, Hdd``;
    ``g`` (2, n_i): ``J'W e`` for ``gamma`` and ``d``; and the residuals ``e``.
    """
    step = data.step
    R, C = data.R, data.C
    # Predicted responses and their derivatives per (p, j, k).
    pred = np.einsum("pl,jl,kl->pjk", R, Lc, S) * step
    dpred = np.einsum("pl,jl,kl->pjk", R, dL, S) * step
    w = data.W / phi[None, None, :]
    e = C - pred
    Hgg = np.einsum("pjk,pjk->j", w, pred * pred)
    Hgd = np.einsum("pjk,pjk->j", w, pred * dpred)
    Hdd = np.einsum("pjk,pjk->j", w, dpred * dpred)
    g = np.stack(
        [np.einsum("pjk,pjk->j", w, pred * e), np.einsum("pjk,pjk->j", w, dpred * e)]
    )
    # d pred / d s_k(l) = Lc_j(l) r_p(l) step
    Hsg = np.einsum("pjk,pjk,pl,jl->klj", w, pred, R, Lc, optimize=True) * step
    Hsd = np.einsum("pjk,pjk,pl,jl->klj", w, dpred, R, Lc, optimize=True) * step
    return Hsg, Hsd, np.stack([Hgg, Hgd, Hdd]), g, e


def _objective(
    data: _Data,
    G: NDArray,
    b: NDArray,
    S: NDArray,
    Lams: list[NDArray],
    phi: NDArray,
    state: _State,
    sg: float,
    sd: float,
) -> float:
    total = 0.0
    for k in range(3):
        s = S[k]
        total += (data.cc[k] - 2 * b[k] @ s + s @ (G[k] + Lams[k]) @ s) / phi[k]
    total += float(np.sum(state.gamma**2)) / sg**2
    total += float(np.sum((state.shift - state.shift0) ** 2)) / sd**2
    return total


def _solve_s(G: NDArray, b: NDArray, Lams: list[NDArray], nonneg: bool) -> NDArray:
    S = np.empty(b.shape)
    for k in range(3):
        H = G[k] + Lams[k]
        S[k] = _nnls_quadratic(H, b[k]) if nonneg else np.linalg.solve(H, b[k])
    return S


def _phi(
    data: _Data, G: NDArray, b: NDArray, S: NDArray, Lams: list[NDArray]
) -> NDArray:
    out = np.empty(3)
    for k in range(3):
        s = S[k]
        rss = data.cc[k] - 2 * b[k] @ s + s @ (G[k] + Lams[k]) @ s
        out[k] = max(float(rss), 1e-300) / data.m
    return out


#: Correction models: "per-led" (gains, offsets and their common part), "common" (one
#: wavelength offset for every LED), "none".
CORRECTION_MODES = ("per-led", "common", "none")


def _reduction(mode: str, n_i: int) -> NDArray[np.float64]:
    """``B`` mapping the free correction parameters onto ``(eta, d, d0)``."""
    q = (n_i - 1) + n_i + 1
    if mode == "per-led":
        return np.eye(q)
    if mode == "common":  # eta = 0, every d_j = d0
        B = np.zeros((q, 1))
        B[n_i - 1 :, 0] = 1.0
        return B
    return np.zeros((q, 0))


def _hessian(
    data: _Data,
    wl: NDArray,
    L_rep: NDArray,
    state: _State,
    S: NDArray,
    G: NDArray,
    Lams: list[NDArray],
    phi: NDArray,
    sg: float,
    sd: float,
    B: NDArray,
) -> tuple[NDArray, NDArray, NDArray]:
    """Gauss-Newton Hessian and gradient over ``(s_R, s_G, s_B, x)``, ``(eta, d, d0) = B x``.

    ``gamma = Z eta`` with ``Z`` an orthonormal basis of the sum-zero vectors. Returns
    ``(H, grad, Z)``; the gradient's sensitivity part is zero when ``S`` is the
    unconstrained conditional minimiser.
    """
    n = wl.size
    n_i = L_rep.shape[0]
    Lc, dL = _corrected(wl, L_rep, np.exp(state.gamma), state.shift)
    Hsg, Hsd, Hc, g, _ = _jacobian_blocks(data, Lc, dL, S, phi)
    Z = np.linalg.svd(np.eye(n_i) - 1.0 / n_i)[0][:, : n_i - 1]
    q = (n_i - 1) + n_i + 1
    N = 3 * n + q
    H = np.zeros((N, N))
    o = 3 * n
    ie, idd = slice(o, o + n_i - 1), slice(o + n_i - 1, o + 2 * n_i - 1)
    for k in range(3):
        sl = slice(k * n, (k + 1) * n)
        H[sl, sl] = (G[k] + Lams[k]) / phi[k]
        H[sl, ie] = Hsg[k] @ Z
        H[sl, idd] = Hsd[k]
    H[ie, ie] = Z.T @ np.diag(Hc[0]) @ Z + np.eye(n_i - 1) / sg**2
    H[ie, idd] = Z.T @ np.diag(Hc[1])
    H[idd, idd] = np.diag(Hc[2]) + np.eye(n_i) / sd**2
    H[idd, N - 1] = -1.0 / sd**2
    H[N - 1, N - 1] = n_i / sd**2
    H = np.triu(H) + np.triu(H, 1).T
    grad = np.zeros(N)
    grad[ie] = Z.T @ (g[0] - state.gamma / sg**2)
    grad[idd] = g[1] - (state.shift - state.shift0) / sd**2
    grad[N - 1] = float(np.sum(state.shift - state.shift0)) / sd**2
    T = np.zeros((N, 3 * n + B.shape[1]))
    T[:o, :o] = np.eye(o)
    T[o:, o:] = B
    return T.T @ H @ T, T.T @ grad, Z


def _apply_step(state: _State, x: NDArray, B: NDArray, Z: NDArray) -> _State:
    n_i = state.shift.size
    full = B @ x
    return _State(
        state.gamma + Z @ full[: n_i - 1],
        state.shift + full[n_i - 1 : 2 * n_i - 1],
        state.shift0 + full[-1],
    )


def _check_positive(ok: list[Any]) -> None:
    for k in range(3):
        if not ok[k]:
            raise SingularSystemError(
                f"channel {'RGB'[k]}: no positive sensitivity fits the responses "
                "(are they all zero or negative?)"
            )


def _gauss_newton(
    data: _Data,
    normal: Any,
    wl: NDArray,
    L_rep: NDArray,
    state: _State,
    system: tuple[NDArray, NDArray, list],
    widths: tuple[float, float],
    B: NDArray,
    priors: tuple[NDArray, list, list],
    should_stop: StopFn | None,
) -> tuple[_State, NDArray, NDArray, list, int]:
    """Gauss-Newton on the corrections at fixed hyper-parameters, to convergence.

    ``system`` is ``(G, b, Lams)`` at ``state``; ``priors`` ``(Omega, Q_k, hyper)``.
    Returns the new state, its system and the number of iterations.
    """
    G, b, Lams = system
    sg, sd = widths
    Om, Qs, hyper = priors
    n = wl.size
    iterations = 0
    for _ in range(_MAX_ITER):
        check_stop(should_stop)
        iterations += 1
        S = _solve_s(G, b, Lams, nonneg=False)
        phi = _phi(data, G, b, S, Lams)
        H, grad, Z = _hessian(data, wl, L_rep, state, S, G, Lams, phi, sg, sd, B)
        x = _correction_step(H, grad, 3 * n)
        new, G, b, Lams = _line_search(
            data, normal, state, x, B, Z, G, b, Lams, phi, sg, sd, Om, Qs, hyper
        )
        change = max(
            float(np.max(np.abs(new.shift - state.shift))) / _TOL_SHIFT_NM,
            float(np.max(np.abs(new.gamma - state.gamma))) / _TOL_GAIN,
        )
        state = new
        if change < 1.0:
            break
    return state, G, b, Lams, iterations


def fit_bayes(
    wavelength_nm: NDArray[np.float64],
    L_rep: NDArray[np.float64],
    R: NDArray[np.float64],
    C: NDArray[np.float64],
    var: NDArray[np.float64],
    step_nm: float,
    bases: list[NDArray[np.float64] | None],
    *,
    mode: str = "per-led",
    sigma_gain: float = SIGMA_GAIN,
    sigma_shift_nm: float = SIGMA_SHIFT_NM,
    max_roughness: Sequence[float | None] = (None, None, None),
    replicate_spectra: Sequence[NDArray[np.float64]] = (),
    should_stop: StopFn | None = None,
) -> BayesFit:
    """Joint MAP of sensitivities and light-source corrections, priors by evidence.

    Parameters
    ----------
    wavelength_nm, step_nm : (n,), float
        The grid and its step.
    L_rep, R : (n_i, n), (n_p, n)
        Illuminant spectra as reported (exposure-scaled); usable patches' reflectances.
    C, var : (n_p, n_i, 3)
        Responses and their (relative) variances.
    bases
        Per channel the database's principal components (q, n), or ``None``.
    mode
        :data:`CORRECTION_MODES`: ``"per-led"`` fits every LED's gain and offset,
        ``"common"`` one offset for all (the instrument's wavelength scale),
        ``"none"`` takes the reported spectra as they are.
    sigma_gain, sigma_shift_nm
        Prior widths of the per-LED corrections (module docstring).
    max_roughness
        Per channel the largest :func:`roughness` accepted (``None``: no cap), e.g.
        :data:`ROUGHNESS_CAP_FACTOR` x :func:`database_roughness`; with
        ``mode="per-led"`` only.
    replicate_spectra
        Readings with their noise drawn anew (:mod:`tunespec.core.readings`), each
        fitted at this fit's hyper-parameters from its solution (``.replicates``).

    Returns
    -------
    BayesFit
        With the covariance of ``(s_R, s_G, s_B, log gain, offset)``.

    References
    ----------
    The paper, Eq. 3; D. J. C. MacKay, "Bayesian interpolation", Neural
    Computation 4(3), 415-447 (1992) (hyper-parameters by the evidence).
    """
    n_i, n = L_rep.shape
    data = _data(R, C, var, step_nm)
    if mode != "per-led":  # the cap needs the corrections (ROUGHNESS_CAP_FACTOR)
        max_roughness = (None, None, None)
    Om, Qs = _penalties(n, bases)
    B = _reduction(mode, n_i)
    sg, sd = float(sigma_gain), float(sigma_shift_nm)

    normal = _normal_at(data, wavelength_nm, L_rep)

    def choose(G: NDArray, b: NDArray) -> tuple[list, list[float]]:
        got = [
            _choose(G[k], b[k], float(data.cc[k]), data.m, Om, Qs[k],
                    bases[k] is not None, should_stop, max_roughness[k])
            for k in range(3)
        ]  # fmt: skip
        return [(lam, mu) for lam, mu, _ in got], [ev for _, _, ev in got]

    state = _State(np.zeros(n_i), np.zeros(n_i), 0.0)
    G, b = normal(state)
    _check_positive([data.cc[k] > 0 and np.any(b[k] > 0) for k in range(3)])
    iterations = 0
    if not B.shape[1]:
        hyper, evid = choose(G, b)
        Lams = _channel_precisions(G, Om, Qs, hyper)
    else:
        # The corrections are found first with a stiff curve (a flexible one could
        # absorb them), then the priors are chosen at the corrected spectra and the
        # corrections refined, twice.
        state = _coarse_offset(data, normal, Om, Qs, sg, sd)
        G, b = normal(state)
        hyper = [(_OFFSET_SEARCH_LAMBDA, 0.0)] * 3
        evid = [float("nan")] * 3
        Lams = _channel_precisions(G, Om, Qs, hyper)
        for rounds in range(3):
            state, G, b, Lams, its = _gauss_newton(
                data, normal, wavelength_nm, L_rep, state, (G, b, Lams),
                (sg, sd), B, (Om, Qs, hyper), should_stop,
            )  # fmt: skip
            iterations += its
            if rounds < 2:
                # Hierarchical step: the prior widths of the per-LED corrections
                # from the corrections themselves (an EM update, bounded), then the
                # hyper-parameters at the corrected spectra.
                if mode == "per-led" and rounds == 1:
                    sg, sd = _update_widths(
                        data, wavelength_nm, L_rep, state, G, b, Lams, sg, sd, B, n
                    )
                hyper, evid = choose(G, b)
                Lams = _channel_precisions(G, Om, Qs, hyper)
    S = _solve_s(G, b, Lams, nonneg=True)
    _check_positive([np.any(S[k] > 0) for k in range(3)])
    phi = _phi(data, G, b, S, Lams)
    H, _, Z = _hessian(data, wavelength_nm, L_rep, state, S, G, Lams, phi, sg, sd, B)
    cov = _covariance(H, S, B, Z, n, n_i)
    replicates = tuple(_replicate_fit(data, wavelength_nm, L, state, B, (Om, Qs, hyper),
                                      (sg, sd), should_stop) for L in replicate_spectra)  # fmt: skip
    params = {"lambda": [h[0] for h in hyper],
              "database_weight": [h[1] for h in hyper],
              "neg2_log_evidence": [float(e) for e in evid],
              "noise_scale": [float(p) for p in phi], "corrections": mode,
              "sigma_gain": sg, "sigma_shift_nm": sd, "iterations": iterations,
              "max_roughness": list(max_roughness),
              "roughness": [roughness(S[k], Om) for k in range(3)]}  # fmt: skip
    return BayesFit(
        S, np.exp(state.gamma), state.shift.copy(), state.shift0, cov, params,
        replicates,
    )  # fmt: skip


def _replicate_fit(
    data: _Data,
    wl: NDArray,
    L_rep: NDArray,
    state: _State,
    B: NDArray,
    priors: tuple[NDArray, list, list],
    widths: tuple[float, float],
    should_stop: StopFn | None,
) -> tuple[NDArray[np.float64], ...]:
    """``(S, gain, shift_nm)`` of the fit with the reported spectra ``L_rep``: the
    corrections refined by Gauss-Newton from ``state`` at the fit's hyper-parameters
    and prior widths (a conditional bootstrap replicate: the priors stay as chosen,
    one to three iterations instead of the whole search)."""
    Om, Qs, hyper = priors
    normal = _normal_at(data, wl, L_rep)
    st = _State(state.gamma.copy(), state.shift.copy(), state.shift0)
    G, b = normal(st)
    Lams = _channel_precisions(G, Om, Qs, hyper)
    if B.shape[1]:
        st, G, b, Lams, _ = _gauss_newton(
            data, normal, wl, L_rep, st, (G, b, Lams), widths, B, priors, should_stop
        )
    return _solve_s(G, b, Lams, nonneg=True), np.exp(st.gamma), st.shift.copy()


#: Bounds of the hierarchical widths: from "no metering error" to far beyond a
#: working instrument.
_WIDTH_GAIN = (0.001, 0.05)
_WIDTH_SHIFT_NM = (0.02, 2.0)


def _update_widths(
    data: _Data,
    wl: NDArray,
    L_rep: NDArray,
    state: _State,
    G: NDArray,
    b: NDArray,
    Lams: list,
    sg: float,
    sd: float,
    B: NDArray,
    n: int,
) -> tuple[float, float]:
    """EM update of the correction priors' widths: ``sigma^2 = mean(x^2 + var x)``."""
    n_i = L_rep.shape[0]
    S = _solve_s(G, b, Lams, nonneg=False)
    phi = _phi(data, G, b, S, Lams)
    H, _, Z = _hessian(data, wl, L_rep, state, S, G, Lams, phi, sg, sd, B)
    cov = np.linalg.inv(H)[3 * n :, 3 * n :]
    var_eta = np.diag(cov)[: n_i - 1]
    var_d = np.diag(cov)[n_i - 1 : 2 * n_i - 1]
    eta = Z.T @ state.gamma
    g2 = (float(np.sum(eta**2)) + float(np.sum(var_eta))) / (n_i - 1)
    d2 = float(np.mean((state.shift - state.shift0) ** 2 + var_d))
    return (
        float(np.clip(np.sqrt(g2), *_WIDTH_GAIN)),
        float(np.clip(np.sqrt(d2), *_WIDTH_SHIFT_NM)),
    )


#: Smoothness weight of the coarse offset search: strong, so that the sensitivities
#: cannot bend to absorb a wrong offset (a weak one makes the search flat).
_OFFSET_SEARCH_LAMBDA = 1e-3


def _coarse_offset(
    data: _Data, normal: Any, Om: NDArray, Qs: list, sg: float, sd: float
) -> _State:
    """Best common offset on a 0.5 nm grid over +-3 nm (Gauss-Newton starts there).

    Scored with a fixed, strong smoothness prior and no database: the offset moves
    the illuminants against the chart's known reflectances, which a smooth
    sensitivity cannot imitate, whereas evidence-chosen (possibly weak) smoothing
    can absorb part of a wrong offset and flatten the search.
    """
    n_i = data.C.shape[1]
    hyper = [(_OFFSET_SEARCH_LAMBDA, 0.0)] * 3
    st0 = _State(np.zeros(n_i), np.zeros(n_i), 0.0)
    G, b = normal(st0)
    Lams = _channel_precisions(G, Om, Qs, hyper)
    phi = _phi(data, G, b, _solve_s(G, b, Lams, nonneg=False), Lams)
    best: tuple[float, _State] | None = None
    for d0 in np.arange(-3.0, 3.0 + 1e-9, 0.5):
        st = _State(np.zeros(n_i), np.full(n_i, d0), float(d0))
        G1, b1 = normal(st)
        L1 = _channel_precisions(G1, Om, Qs, hyper)
        S1 = _solve_s(G1, b1, L1, nonneg=False)
        f = _objective(data, G1, b1, S1, L1, phi, st, sg, sd)
        if best is None or f < best[0]:
            best = (f, st)
    assert best is not None
    return best[1]


def _correction_step(H: NDArray, grad: NDArray, n_s: int) -> NDArray:
    """Variable-projection Gauss-Newton step of the corrections (Schur complement).

    ``grad`` is zero in the sensitivity block (they are the exact conditional
    minimisers), so the correction step solves ``(H_cc - H_cs H_ss^-1 H_sc) x = g_c``.
    """
    Hss, Hsc, Hcc = H[:n_s, :n_s], H[:n_s, n_s:], H[n_s:, n_s:]
    schur = Hcc - Hsc.T @ np.linalg.solve(Hss, Hsc)
    return np.linalg.solve(schur, grad[n_s:])


def _line_search(
    data: _Data,
    normal: Any,
    state: _State,
    x: NDArray,
    B: NDArray,
    Z: NDArray,
    G: NDArray,
    b: NDArray,
    Lams: list,
    phi: NDArray,
    sg: float,
    sd: float,
    Om: NDArray,
    Qs: list,
    hyper: list,
) -> tuple[_State, NDArray, NDArray, list]:
    """Apply the step, halving it until the penalised objective does not increase."""
    f0 = _objective(
        data, G, b, _solve_s(G, b, Lams, nonneg=False), Lams, phi, state, sg, sd
    )
    trial = _apply_step(state, x, B, Z)
    # Never more than 0.5 nm or 2 % per iteration: the model is linearised.
    scale = min(
        1.0,
        0.5 / max(float(np.max(np.abs(trial.shift - state.shift))), 1e-12),
        0.02 / max(float(np.max(np.abs(trial.gamma - state.gamma))), 1e-12),
    )
    for _ in range(8):
        new = _apply_step(state, scale * x, B, Z)
        G1, b1 = normal(new)
        L1 = _channel_precisions(G1, Om, Qs, hyper)
        f1 = _objective(
            data, G1, b1, _solve_s(G1, b1, L1, nonneg=False), L1, phi, new, sg, sd
        )
        if f1 <= f0 + 1e-9 * abs(f0):
            return new, G1, b1, L1
        scale *= 0.5
    return state, G, b, Lams


def _covariance(
    H: NDArray, S: NDArray, B: NDArray, Z: NDArray, n: int, n_i: int
) -> NDArray[np.float64]:
    """Laplace covariance of ``(s_R, s_G, s_B, log gain, offset)`` at the solution.

    ``H`` is the Hessian over the free parameters ``(s, x)``. Sensitivity samples
    that the non-negativity constraint holds at 0 are fixed (zero variance); the
    corrections are mapped back through ``B`` and ``Z``.
    """
    free = np.ones(H.shape[0], dtype=bool)
    free[: 3 * n] = S.reshape(-1) > 0
    red = np.zeros(H.shape)
    red[np.ix_(free, free)] = np.linalg.inv(H[np.ix_(free, free)])
    N = 3 * n + 2 * n_i
    # (s, x) -> (s, eta, d, d0) -> (s, gamma = Z eta, d)
    T = np.zeros((N, H.shape[0]))
    T[: 3 * n, : 3 * n] = np.eye(3 * n)
    M = np.zeros((2 * n_i, (n_i - 1) + n_i + 1))
    M[:n_i, : n_i - 1] = Z
    M[n_i:, n_i - 1 : 2 * n_i - 1] = np.eye(n_i)
    T[3 * n :, 3 * n :] = M @ B
    out = T @ red @ T.T
    return 0.5 * (out + out.T)
