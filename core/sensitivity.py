"""Camera spectral sensitivities from a target captured under many illuminants.

Eq. 3 of the paper stacks Eq. 1 for every patch ``p`` and illuminant ``i``::

    c_k(p, i) = sum_l s_k(l) i(l) r_p(l) dl  =  (A s_k)[p, i],    k = R, G, B

so each channel's sensitivity ``s_k`` (n_wl,) solves a linear system with the
stimulus matrix ``A`` (n_p n_i, n_wl), whose rows are ``i(l) r_p(l) dl``. With narrowband
LEDs ``A`` is badly conditioned (its singular values fall by five orders of magnitude),
so plain least squares amplifies noise; a priori knowledge is needed. Two methods:

``"pca"``
    The paper's method (Eq. 4): ``s_k`` lies in the span of the first principal
    components of a database of camera sensitivities, fitted by least squares.
``"smooth"`` (default)
    Non-negative least squares with a second-difference smoothness penalty and a
    penalty on the distance to the database's principal subspace, rows weighted by
    their noise; the smoothness weight is chosen per channel by generalised
    cross-validation. It follows curves outside a four-dimensional span, never goes
    negative, and on cameras left out of the shipped database its median error is
    about 40 % below that of ``"pca"`` (0.014 vs. 0.024 of the peak, see
    ``benchmarks/loo_cameras.py``).

Both return sensitivities on the absolute scale of the inputs, so that
:func:`~tunespec.core.forward_model.render_rgb` with the given illuminants predicts
the responses (:func:`~tunespec.core.calibration.predict_responses`).

The estimation also finds a wavelength-scale error of the spectroradiometer that
reported the illuminants, with the chart's known reflectances as the wavelength
reference (``fit_spd_shift``: by default on for ``"smooth"``, off for ``"pca"``, the
paper's method as published). Sensitivities cannot absorb such a shift, and
1 nm of it costs about 0.3 CIEDE2000 in the reflectances estimated later; the
estimate then carries the shift (:attr:`SensitivityEstimate.spd_shift_nm`) and the
sensitivities belong to the corrected spectra
(:meth:`SensitivityEstimate.correct_illuminants`).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source: Setup, Characterization
and Reflectance Estimation (``shared/reference/paper-trichromatic-reflectance-capture``),
Eq. 1, 3 and 4. J. Jiang, D. Liu, J. Gu, S. Süsstrunk, "What is the space of spectral
sensitivity functions for digital color cameras?", WACV 2013, doi:10.1109/WACV.2013.6475015
(the database approach). G. H. Golub, M. Heath, G. Wahba, "Generalized cross-validation
as a method for choosing a good ridge parameter", Technometrics 21 (1979) 215-223.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import eigh, solve_triangular
from scipy.optimize import minimize_scalar

from tunespec.core.calibration import (
    Calibration,
    select_named,
    shift_values,
    undo_metering,
)
from tunespec.core.camera_basis import database_basis
from tunespec.core.datasets import load_camera_database
from tunespec.core.errors import InputError, SingularSystemError
from tunespec.core.excess import (
    bend_verdict,
    fit_bend,
    fit_excess_variance,
    fit_linearity,
    linearise,
)
from tunespec.core.led_correction import LedCorrection
from tunespec.core.metering import suppress_meter_floor
from tunespec.core.progress import ProgressFn, StopFn, check_stop, report, sub_progress
from tunespec.core.readings import (
    REPLICATES,
    ReadingReplicates,
    replicate_spectra,
    replicates_of,
)
from tunespec.core.responses import CHANNELS, Responses
from tunespec.core.sensitivity_bayes import (
    ROUGHNESS_CAP_FACTOR,
    _nnls_quadratic,
    _smoothness_penalty,
    database_roughness,
    fit_bayes,
)
from tunespec.core.sensitivity_bayes import _subspace_penalty as _basis_penalty
from tunespec.core.simulate import check_same_grid
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "SENSITIVITY_METHODS",
    "SMOOTH_LAMBDAS",
    "SMOOTH_PRIOR_COMPONENTS",
    "SMOOTH_PRIOR_WEIGHT",
    "SMOOTH_RELATIVE_ERROR",
    "SPD_SHIFT_RANGE_NM",
    "SensitivityEstimate",
    "database_basis",
    "estimate_camera_sensitivity",
    "stimulus_matrix",
]

#: Candidate smoothness weights for ``"smooth"``, relative to the mean diagonal of the
#: weighted normal matrix (so they do not depend on the units of the inputs).
SMOOTH_LAMBDAS = np.logspace(-6.0, 1.0, 15)
#: Weight of the penalty on the distance to the database subspace, same units. The
#: leave-one-camera-out benchmark is flat between 3e-3 and 3e-2 (median sensitivity
#: RMS 0.0138-0.0144 in a sweep); 0.01 sits in the middle of that plateau. Without
#: this penalty (0) the median is 0.13: GCV alone does not regularise enough.
SMOOTH_PRIOR_WEIGHT = 0.01
#: Principal components spanning the database subspace of ``"smooth"`` (6 and 8 do
#: equally well on held-out cameras; 8 leaves more room for an unusual camera).
SMOOTH_PRIOR_COMPONENTS = 8
#: Relative error of a response that the ROI statistics cannot see: the flat-field
#: residual (about 0.3 %) and the SPD metering error (about 1 % per LED, partly
#: absorbed by the fit). Added in quadrature to the ROI noise to weight the rows.
SMOOTH_RELATIVE_ERROR = 0.005
#: Absolute noise floor of a response (full scale), so a row never gets infinite weight.
_ABS_NOISE_FLOOR = 1e-4
#: Largest spectroradiometer wavelength shift searched by ``fit_spd_shift`` (nm).
SPD_SHIFT_RANGE_NM = 3.0
#: Smoothness weight used while searching the shift (the database penalty makes the
#: choice of this weight uncritical, see :func:`_estimate_sensitivity_smooth`).
_SHIFT_SEARCH_LAMBDA = 1e-4
#: Ridge added to the normal matrix, relative to its mean diagonal: far below any
#: penalty, it only keeps the matrix numerically positive definite.
_RIDGE_RELATIVE = 1e-10
#: Stimuli needed at least by ``"smooth"`` (rank of the stimulus matrix).
_MIN_RANK_SMOOTH = 4


#: The estimator's name for its result: a :class:`~tunespec.core.calibration.Calibration`
#: (kept because the estimator's callers, the statistics and the self-check use it).
SensitivityEstimate = Calibration


@dataclass(frozen=True)
class _Problem:
    """The linear system of Eq. 3, ready to solve.

    ``A`` (m, n_wl): stimulus rows, ``C`` (m, 3): responses, ``var`` (m, 3): variance
    of each response, ``wavelength_nm`` (n_wl,); ``L`` (n_i, n_wl) and ``R``
    (n_p, n_wl) the illuminants and the (unsaturated) patches that make ``A``;
    ``readings`` the illuminants as a :class:`Spectra` (names and the cleaning's
    ``meta``: their reading noise).
    """

    A: NDArray[np.float64]
    C: NDArray[np.float64]
    var: NDArray[np.float64]
    wavelength_nm: NDArray[np.float64]
    patches: tuple[str, ...]
    excluded_patches: tuple[str, ...]
    has_roi_noise: bool
    L: NDArray[np.float64]
    R: NDArray[np.float64]
    step_nm: float
    readings: Spectra

    def shifted(self, shift_nm: float) -> _Problem:
        """The same system with the illuminants' wavelength shift undone."""
        L = shift_values(self.wavelength_nm, self.L, shift_nm)
        return replace(self, A=stimulus_matrix(L, self.R, self.step_nm), L=L)


def stimulus_matrix(
    illuminants: NDArray[np.float64],
    reflectances: NDArray[np.float64],
    step_nm: float,
) -> NDArray[np.float64]:
    """Stimulus matrix of Eq. 3: row ``(p, i)`` is ``r_p(l) i(l) dl``.

    Parameters
    ----------
    illuminants : (n_i, n_wl)
    reflectances : (n_p, n_wl)
    step_nm
        Wavelength step (the weight of Eq. 1's sum).

    Returns
    -------
    (n_p n_i, n_wl)
        Rows patch-major, ``(p1 i1, p1 i2, ..., p2 i1, ...)``, matching
        ``render_rgb(r, i, S).reshape(-1, 3)``, so that ``A @ S.T`` renders.

    Examples
    --------
    >>> import numpy as np
    >>> from tunespec.core.forward_model import render_rgb
    >>> rng = np.random.default_rng(0)
    >>> r, i, S = rng.random((4, 6)), rng.random((2, 6)), rng.random((3, 6))
    >>> A = stimulus_matrix(i, r, 5.0)
    >>> np.allclose(A @ S.T, render_rgb(r, i, S, 5.0).reshape(-1, 3))
    True
    """
    R = np.atleast_2d(np.asarray(reflectances, dtype=np.float64))
    L = np.atleast_2d(np.asarray(illuminants, dtype=np.float64))
    return (R[:, None, :] * L[None, :, :]).reshape(-1, R.shape[1]) * step_nm


def _check_finite(spectra: Spectra, what: str) -> None:
    ok = np.isfinite(spectra.values).all(axis=1)
    if not ok.all():
        bad = [n for n, good in zip(spectra.names, ok, strict=True) if not good]
        raise InputError(
            f"{what} {', '.join(bad[:8])} contain NaN or infinite values",
            path=spectra.meta.get("source"),
        )


def _prepare(
    responses: Responses, illuminants: Spectra, reflectances: Spectra
) -> _Problem:
    """Validate the inputs and build the system of Eq. 3 (rows patch-major)."""
    check_same_grid(reflectances, illuminants)
    illum = select_named(
        illuminants, responses.illuminants, "illuminant(s) of the responses"
    )
    refl = select_named(reflectances, responses.patches, "patch(es) of the responses")
    _check_finite(illum, "illuminant(s)")
    _check_finite(refl, "reflectance(s)")
    # the reported spectra without their noise floor, as correct_illuminants gives them
    illum = suppress_meter_floor(illum)
    if not np.all(np.isfinite(responses.rgb)):
        p, i, _ = np.argwhere(~np.isfinite(responses.rgb))[0]
        raise InputError(
            "responses contain NaN or infinite values, e.g. patch "
            f"{responses.patches[p]!r} under {responses.illuminants[i]!r}"
        )
    keep = np.ones(len(responses.patches), dtype=bool)
    if responses.saturated is not None:
        # A patch with any clipped pixel is left out entirely: near full scale the
        # sensor is no longer linear, and Eq. 1 assumes it is.
        keep = ~np.any(responses.saturated > 0, axis=1)
    excluded = tuple(p for p, k in zip(responses.patches, keep, strict=True) if not k)
    patches = tuple(p for p, k in zip(responses.patches, keep, strict=True) if k)
    if not patches:
        raise SingularSystemError(
            "every patch has saturated responses; lower the exposure and capture again"
        )
    A = stimulus_matrix(illum.values, refl.values[keep], illuminants.step_nm)
    C = responses.rgb[keep].reshape(-1, 3)
    var = np.full_like(C, _ABS_NOISE_FLOOR**2)
    has_roi = responses.rgb_std is not None and responses.n_pixels is not None
    if has_roi:
        std = responses.rgb_std[keep].reshape(-1, 3)  # type: ignore[index]
        npx = np.maximum(responses.n_pixels[keep].reshape(-1, 1), 1.0)  # type: ignore[index]
        if not (np.all(np.isfinite(std)) and np.all(np.isfinite(npx))):
            raise InputError("response standard deviations contain NaN")
        var = var + std**2 / npx
    var = var + (SMOOTH_RELATIVE_ERROR * C) ** 2
    return _Problem(
        A,
        C,
        var,
        illuminants.wavelength_nm,
        patches,
        excluded,
        has_roi,
        illum.values,
        refl.values[keep],
        illuminants.step_nm,
        illum,
    )


def _database(
    database: Mapping[str, Spectra] | None,
    exclude: str | Iterable[str] | None,
    wavelength_nm: NDArray[np.float64],
    step_nm: float,
) -> dict[str, Spectra]:
    """The database on the inputs' grid, without the excluded cameras."""
    if database is None:
        grid = Grid(float(wavelength_nm[0]), float(wavelength_nm[-1]), step_nm)
        database = load_camera_database(grid)
    excl = {exclude} if isinstance(exclude, str) else set(exclude or ())
    unknown = sorted(excl - set(database))
    if unknown:
        raise InputError(
            f"cannot exclude unknown camera(s) {', '.join(unknown)}; the database has "
            f"{len(database)} cameras"
        )
    out = {n: s for n, s in database.items() if n not in excl}
    for name, s in out.items():
        if len(s) != 3:
            raise InputError(
                f"database camera {name!r} has {len(s)} curves, expected R, G, B",
                path=s.meta.get("source"),
            )
        wl = s.wavelength_nm
        if wl.shape != wavelength_nm.shape or not np.allclose(
            wl, wavelength_nm, rtol=0.0, atol=1e-6
        ):
            raise InputError(
                f"database camera {name!r} is on {wl[0]:g}-{wl[-1]:g} nm "
                f"({wl.size} samples), the inputs on {wavelength_nm[0]:g}-"
                f"{wavelength_nm[-1]:g} nm ({wavelength_nm.size} samples)",
                path=s.meta.get("source"),
            )
    return out


def _estimate_sensitivity_pca(
    problem: _Problem,
    database: dict[str, Spectra],
    *,
    n_components: int,
    explained_variance: float | None,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """The paper's Eq. 4: least squares in the span of database components.

    Per channel ``k``, ``s_k = alpha_k P^k`` with ``P^k`` from :func:`database_basis`,
    and ``alpha_k`` minimises ``||A P^k.T alpha - c_k||`` (unweighted, as in the paper).
    Eq. 4 writes the normal equations out; they are solved here by an orthogonal
    factorisation (``lstsq``), which gives the same minimiser without squaring the
    condition number.

    Returns
    -------
    S : (3, n_wl)
    params : dict
    """
    S = np.zeros((3, problem.A.shape[1]))
    used: list[int] = []
    explained: list[float] = []
    for k in range(3):
        check_stop(should_stop)
        P, ev = database_basis(database, k, n_components, explained_variance)
        B = problem.A @ P.T
        if B.shape[0] < B.shape[1] or _numerical_rank(B) < B.shape[1]:
            raise SingularSystemError(
                f"channel {CHANNELS[k]}: {problem.C.shape[0]} stimuli do not determine "
                f"{P.shape[0]} component weights (Eq. 4 is singular); use more "
                "patches or illuminants, or fewer components"
            )
        alpha = np.linalg.lstsq(B, problem.C[:, k], rcond=None)[0]
        S[k] = alpha @ P
        _check_positive(S[k], k)
        used.append(int(P.shape[0]))
        explained.append(ev)
        report(progress, (k + 1) / 3)
    params = {
        "n_components": used,
        "explained_variance": explained,
        "database_size": len(database),
    }
    return S, params


def _fit_spd_shift(
    problem: _Problem,
    database: dict[str, Spectra],
    should_stop: StopFn | None,
) -> tuple[float, bool]:
    """Find the wavelength shift of the reported illuminants from the responses.

    A shift of the spectra cannot be absorbed by the sensitivities: moving the
    illuminants by ``d`` is the same as moving sensitivity *and* reflectance by
    ``-d``, and the reflectances are known. The mismatch shows as a residual that
    grows with the slopes of the patch spectra, so the shift is the minimiser of the
    penalised weighted residual of the ``"smooth"`` model (unconstrained, fixed
    weights) over ``d``: a 0.5 nm grid over +-:data:`SPD_SHIFT_RANGE_NM`, refined
    by a bounded scalar search.

    The normal matrices are assembled per illuminant, ``G_k = sum_i D(i) M_ik D(i)``
    with ``M_ik = sum_p w_pik^2 r_p r_p'``, so one evaluation costs O(n_i n_wl^2)
    instead of a pass over all stimuli.

    Returns
    -------
    shift_nm : float
    at_bound : bool
        Whether the minimum lies at the edge of the searched range.
    """
    wl = problem.wavelength_nm
    n = wl.size
    n_p, n_i = problem.R.shape[0], problem.L.shape[0]
    w2 = (1.0 / problem.var).reshape(n_p, n_i, 3)
    C = problem.C.reshape(n_p, n_i, 3)
    Rw = problem.R[:, None, None, :] * w2[..., None]
    M = np.einsum("pikl,pm->iklm", Rw, problem.R, optimize=True)
    v = np.einsum("pikl,pik->ikl", Rw, C, optimize=True)
    cc = np.einsum("pik,pik->k", w2, C**2)
    Om = _smoothness_penalty(n)
    penalties = []
    L0 = problem.L * problem.step_nm
    for k in range(3):
        G0 = np.einsum("il,im,ilm->lm", L0, L0, M[:, k], optimize=True)
        t = np.trace(G0) / n
        Q = _subspace_penalty(database, k, n)
        penalties.append(
            t
            * (
                _SHIFT_SEARCH_LAMBDA * Om
                + SMOOTH_PRIOR_WEIGHT * Q
                + _RIDGE_RELATIVE * np.eye(n)
            )
        )

    def objective(shift_nm: float) -> float:
        check_stop(should_stop)
        L = shift_values(wl, problem.L, shift_nm) * problem.step_nm
        total = 0.0
        for k in range(3):
            G = np.einsum("il,im,ilm->lm", L, L, M[:, k], optimize=True)
            b = np.einsum("il,il->l", L, v[:, k])
            try:
                factor = np.linalg.cholesky(G + penalties[k])
            except np.linalg.LinAlgError:
                return np.inf
            z = solve_triangular(factor, b, lower=True)
            total += cc[k] - float(z @ z)
        return total

    grid = np.arange(-SPD_SHIFT_RANGE_NM, SPD_SHIFT_RANGE_NM + 1e-9, 0.5)
    values = np.array([objective(float(d)) for d in grid])
    if not np.any(np.isfinite(values)):
        raise SingularSystemError("cannot fit the illuminants' wavelength shift")
    j = int(np.argmin(values))
    lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
    found = minimize_scalar(
        objective, bounds=(lo, hi), method="bounded", options={"xatol": 0.005}
    )
    shift = float(found.x) if found.fun <= values[j] else float(grid[j])
    at_bound = j in (0, grid.size - 1)
    return shift, at_bound


def _numerical_rank(A: NDArray[np.float64], rtol: float = 1e-7) -> int:
    """Rank of ``A`` (m, n): singular values above ``rtol`` times the largest.

    Computed from the eigenvalues of the n x n Gram matrix (cheap for tall ``A``);
    ``rtol`` is kept well above the square root of machine precision, the limit of
    that route.
    """
    ev = np.linalg.eigvalsh(A.T @ A)
    top = float(ev.max()) if ev.size else 0.0
    if not top > 0:
        return 0
    return int(np.count_nonzero(ev > (rtol**2) * top))


def _check_positive(s: NDArray[np.float64], channel: int) -> None:
    """Refuse a sensitivity curve that is nowhere positive (zero or negative data)."""
    if not np.any(s > 0):
        raise SingularSystemError(
            f"channel {CHANNELS[channel]}: no positive sensitivity fits the responses "
            "(are they all zero or negative?)"
        )


def _subspace_penalty(
    database: Mapping[str, Spectra], channel: int, n: int
) -> NDArray[np.float64]:
    """``I - P' P`` (n, n), the squared distance to the database subspace of ``channel``.

    ``P`` are the first :data:`SMOOTH_PRIOR_COMPONENTS` components
    (:func:`database_basis`); scaled to mean diagonal 1. An empty database gives
    zeros (no subspace penalty).
    """
    if not database:
        return _basis_penalty(None, n)
    P, _ = database_basis(
        database, channel, min(SMOOTH_PRIOR_COMPONENTS, len(database))
    )
    return _basis_penalty(P, n)


def _estimate_sensitivity_smooth(
    problem: _Problem,
    database: dict[str, Spectra],
    *,
    n_components: int,
    explained_variance: float | None,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> tuple[NDArray[np.float64], dict[str, Any]]:
    """Non-negative, smooth, database-guided least squares.

    Per channel ``k``, with row weights ``w = 1 / sigma`` (the ROI noise of the
    response, ``rgb_std / sqrt(n_pixels)``, plus :data:`SMOOTH_RELATIVE_ERROR` of the
    response in quadrature)::

        s_k = argmin_{s >= 0} ||w (A s - c_k)||^2
                              + t (lambda ||D2 s||^2 + mu ||(I - P' P) s||^2)

    ``D2`` is the second difference (a smoothness prior), ``P`` the first
    :data:`SMOOTH_PRIOR_COMPONENTS` database components (:func:`database_basis`), so
    the second penalty is the squared distance to the database subspace; it is
    scale-free because the subspace is uncentred. ``t`` is the mean diagonal of the
    weighted normal matrix, so ``lambda`` and ``mu`` do not depend on units;
    ``mu = SMOOTH_PRIOR_WEIGHT``. ``lambda`` is chosen among :data:`SMOOTH_LAMBDAS` by
    generalised cross-validation, ``GCV = m RSS / (m - tr H_lambda)^2``, of the
    unconstrained problem; the non-negative solution is then computed for it.

    ``n_components`` and ``explained_variance`` (the ``"pca"`` options) are not used:
    the subspace here is only a soft prior and wants more room than Eq. 4's basis.
    An empty database turns the subspace penalty off.

    Notes
    -----
    GCV minimises the predicted response error, not the sensitivity error. Without the
    database penalty it picks almost no smoothing (the directions that the stimuli
    hardly see do not affect the prediction) and the curves oscillate; with it, the
    choice of ``lambda`` matters little. The database penalty is what makes the
    estimate accurate on the narrowband-LED problem.

    Returns
    -------
    S : (3, n_wl)
    params : dict
    """
    del n_components, explained_variance
    m, n = problem.A.shape
    Om_smooth = _smoothness_penalty(n)
    use_prior = bool(database)
    S = np.zeros((3, n))
    lambdas: list[float] = []
    n_steps = 3 * len(SMOOTH_LAMBDAS)
    for k in range(3):
        w = 1.0 / np.sqrt(problem.var[:, k])
        Aw = problem.A * w[:, None]
        cw = problem.C[:, k] * w
        G = Aw.T @ Aw
        b = Aw.T @ cw
        cc = float(cw @ cw)
        t = np.trace(G) / n
        if not t > 0:
            raise SingularSystemError("the stimuli carry no light (all zero)")
        Q_prior = _subspace_penalty(database, k, n)
        # GCV for every lambda from one generalised eigendecomposition: with
        # M = G + t mu Q_prior and V' M V = I, V' (t Om) V = diag(d), the regularised
        # normal matrix is H = V^-T (I + lambda diag(d)) V^-1. A tiny ridge keeps M
        # positive definite when neither the data nor the prior fix a direction.
        M = G + t * (SMOOTH_PRIOR_WEIGHT * Q_prior + _RIDGE_RELATIVE * np.eye(n))
        try:
            d, V = eigh(t * Om_smooth, M)
        except np.linalg.LinAlgError:
            raise SingularSystemError(
                f"channel {CHANNELS[k]}: the regularised system is singular"
            ) from None
        beta = V.T @ b
        GV = V.T @ G @ V
        gcv = np.empty(len(SMOOTH_LAMBDAS))
        for j, lam in enumerate(SMOOTH_LAMBDAS):
            check_stop(should_stop)
            f = 1.0 / (1.0 + lam * d)
            gamma = f * beta
            rss = max(cc - 2.0 * float(gamma @ beta) + float(gamma @ GV @ gamma), 0.0)
            dof = float(np.sum(np.diag(GV) * f))
            gcv[j] = m * rss / max(m - dof, 1.0) ** 2
            report(progress, (k * len(SMOOTH_LAMBDAS) + j + 1) / n_steps)
        lam = float(SMOOTH_LAMBDAS[int(np.argmin(gcv))])
        H = M + lam * t * Om_smooth
        S[k] = _nnls_quadratic(H, b)
        _check_positive(S[k], k)
        lambdas.append(lam)
    params = {
        "lambda": lambdas,
        "prior_weight": SMOOTH_PRIOR_WEIGHT if use_prior else 0.0,
        "prior_components": min(SMOOTH_PRIOR_COMPONENTS, len(database))
        if use_prior
        else 0,
        "relative_error": SMOOTH_RELATIVE_ERROR,
        "roi_noise_weights": problem.has_roi_noise,
        "database_size": len(database),
    }
    return S, params


def _estimate_sensitivity_bayes(
    problem: _Problem,
    database: dict[str, Spectra],
    *,
    fit_shift: bool,
    self_calibrate: bool,
    illuminant_names: tuple[str, ...],
    replicates: int,
    should_stop: StopFn | None,
) -> tuple[
    NDArray[np.float64],
    dict[str, Any],
    LedCorrection,
    NDArray[np.float64],
    ReadingReplicates | None,
]:
    """Empirical Bayes with per-LED self-calibration (:mod:`.sensitivity_bayes`),
    fitted again with the readings' noise drawn anew (:mod:`.readings`).

    The database prior is the subspace of the first :data:`SMOOTH_PRIOR_COMPONENTS`
    components per channel; its weight, like the smoothness weight, is chosen per
    calibration by the evidence (0 included), so it is used only when this camera's
    data support it.
    """
    n_p = len(problem.patches)
    n_i = problem.L.shape[0]
    bases: list[NDArray[np.float64] | None] = [
        database_basis(database, k, min(SMOOTH_PRIOR_COMPONENTS, len(database)))[0]
        if database
        else None
        for k in range(3)
    ]
    fit = fit_bayes(
        problem.wavelength_nm,
        problem.L,
        problem.R,
        problem.C.reshape(n_p, n_i, 3),
        problem.var.reshape(n_p, n_i, 3),
        problem.step_nm,
        bases,
        mode="per-led" if self_calibrate else ("common" if fit_shift else "none"),
        max_roughness=[
            ROUGHNESS_CAP_FACTOR
            * database_roughness(np.array([s.values[k] for s in database.values()]))
            if database
            else None
            for k in range(3)
        ],
        replicate_spectra=replicate_spectra(problem.readings, replicates),
        should_stop=should_stop,
    )
    n = problem.wavelength_nm.size
    sd = np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))
    correction = LedCorrection(
        illuminant_names,
        tuple(float(g) for g in fit.gain),
        tuple(float(d) for d in fit.shift_nm),
        fit.shift0_nm,
        tuple(
            float(g * u) for g, u in zip(fit.gain, sd[3 * n : 3 * n + n_i], strict=True)
        )
        if self_calibrate
        else (),
        tuple(float(u) for u in sd[3 * n + n_i :]) if self_calibrate else (),
    )
    params = {
        **fit.params,
        "prior_components": min(SMOOTH_PRIOR_COMPONENTS, len(database))
        if database
        else 0,
        "relative_error": SMOOTH_RELATIVE_ERROR,
        "roi_noise_weights": problem.has_roi_noise,
        "database_size": len(database),
    }
    readings = replicates_of(problem.readings, fit.S, fit.replicates)
    return fit.S, params, correction, fit.covariance, readings


_MethodFn = Callable[..., Any]

#: Sensitivity estimation methods by name (colour-science's ``*_METHODS`` pattern).
SENSITIVITY_METHODS: dict[str, _MethodFn] = {
    "bayes": _estimate_sensitivity_bayes,
    "pca": _estimate_sensitivity_pca,
    "smooth": _estimate_sensitivity_smooth,
}


def estimate_camera_sensitivity(
    responses: Responses,
    illuminants: Spectra,
    reflectances: Spectra,
    *,
    method: str = "bayes",
    database: Mapping[str, Spectra] | None = None,
    exclude: str | Iterable[str] | None = None,
    n_components: int = 4,
    explained_variance: float | None = None,
    fit_spd_shift: bool | None = None,
    self_calibrate: bool | None = None,
    replicates: int = REPLICATES,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> SensitivityEstimate:
    """Estimate a camera's R, G, B spectral sensitivities from known stimuli.

    Solves Eq. 3 of the paper for the sensitivities, given the camera responses of a
    target (e.g. the ColorChecker SG) under each illuminant, the illuminants'
    spectral power (as the light source's spectroradiometer reports it, times the
    exposure scale) and the patches' reflectances.

    Parameters
    ----------
    responses
        Responses (n_p, n_i, 3) in full-scale units. Patches with any saturated
        response (``responses.saturated > 0``) are left out. ``rgb_std`` and
        ``n_pixels``, if present, weight the rows of ``"smooth"``.
    illuminants : Spectra, (>= n_i, n_wl)
        Illuminant spectra; must contain every name in ``responses.illuminants``.
    reflectances : Spectra, (>= n_p, n_wl)
        Patch reflectances on the same grid; must contain every patch name.
    method
        ``"bayes"`` (default: empirical Bayes with per-LED self-calibration,
        :mod:`.sensitivity_bayes`), ``"smooth"`` or ``"pca"`` (the paper's Eq. 4).
    database
        Camera name -> sensitivities (R, G, B), the a priori knowledge. Default:
        the shipped database (:func:`load_camera_database`).
    exclude
        Camera name(s) to leave out of the database (a leave-one-out check).
    n_components, explained_variance
        ``"pca"``: principal components per channel (the paper uses 4), or if given
        the fewest explaining this fraction of the database's variance (paper: 0.97).
    fit_spd_shift
        Also fit one wavelength-scale error of the spectroradiometer that reported
        ``illuminants`` (within +-:data:`SPD_SHIFT_RANGE_NM`; a 1 nm shift costs
        about 0.3 CIEDE2000, ``benchmarks/loo_cameras.py``). The estimate then
        belongs to ``estimate.correct_illuminants(spectra)``. ``None`` (default):
        on for ``"bayes"`` and ``"smooth"``, off for ``"pca"`` (as published).
    self_calibrate
        ``"bayes"``: fit every LED's gain and wavelength offset too (default: with
        ``fit_spd_shift``); the corrections are in ``.led_correction`` and applied
        by :meth:`SensitivityEstimate.correct_illuminants`.
    replicates
        ``"bayes"``: fits again with the readings' noise drawn anew (:mod:`.readings`;
        0: none, as the self-check's hold-out fit needs none).
    progress, should_stop
        Progress callback (fraction 0..1) and cancellation check.

    A sensor that bends its responses (``c = x^(1 + gamma)``) shows it in the
    chart's residuals: where :func:`~tunespec.core.excess.fit_linearity` finds it
    after a ``"bayes"`` fit, the calibration is fitted again on the linearised
    responses and keeps ``gamma`` (``.excess.linearity_gamma``; each fit reports half
    of the progress).

    Returns
    -------
    SensitivityEstimate
        ``.sensitivity`` (names R, G, B) on the inputs' grid and absolute scale.

    Raises
    ------
    InputError
        Names missing from the spectra, different grids, NaN values, an unknown
        method or excluded camera.
    SingularSystemError
        Too few or degenerate stimuli, or no usable (unsaturated) patch.

    References
    ----------
    The paper, Eq. 3 and 4 (doi:10.2352/ISSN.2169-2629.2017.25.30, Color and Imaging
    Conference 2017); Jiang et al., WACV 2013.

    Examples
    --------
    >>> from tunespec.core.datasets import load_camera, load_colorchecker_sg, load_led_set
    >>> from tunespec.core.simulate import scale_to_exposure, simulate_responses
    >>> name = "Canon EOS 5D Mark III"
    >>> truth, refl = load_camera(name), load_colorchecker_sg()
    >>> leds = scale_to_exposure(refl, load_led_set(), truth)
    >>> resp = simulate_responses(refl, leds, truth, noise=None, rng=0)
    >>> est = estimate_camera_sensitivity(resp, leds, refl, exclude=name)
    >>> est.sensitivity.names
    ('R', 'G', 'B')
    """

    fit_spd_shift, self_calibrate = _options(method, fit_spd_shift, self_calibrate)
    report(progress, 0.0)
    problem = _prepare(responses, illuminants, reflectances)
    db = _database(database, exclude, problem.wavelength_nm, illuminants.step_nm)
    _check_solvable(problem, method, db)

    def fit(problem: _Problem, progress: ProgressFn | None) -> SensitivityEstimate:
        return _estimate_once(
            problem, db, method, fit_spd_shift=fit_spd_shift,
            self_calibrate=self_calibrate, n_components=n_components,
            explained_variance=explained_variance, replicates=replicates,
            illuminant_names=tuple(responses.illuminants), exclude=exclude,
            progress=progress, should_stop=should_stop,
        )  # fmt: skip

    cal = fit(problem, sub_progress(progress, 0.0, 0.5))
    gamma, se = _chart_linearity(cal, problem)
    if cal.method == "bayes" and bend_verdict(gamma, se) == "undo":  # linearised
        linear = _prepare(linearise(responses, gamma), illuminants, reflectances)
        cal = _linearised(fit(linear, sub_progress(progress, 0.5, 1.0)), gamma)
    report(progress, 1.0)
    return _with_bend(cal, gamma, se)


def _with_bend(
    cal: SensitivityEstimate, gamma: float, se: float
) -> SensitivityEstimate:
    """``cal`` with the chart's bend as fitted, undone or not
    (``params["linearity_gamma_found"]`` and ``..._se``; nothing where no fit ran):
    a bend too large to undo is
    :func:`~tunespec.core.plausibility.check_chart_linearity`'s."""
    if not np.isfinite(se):
        return cal
    found = {"linearity_gamma_found": gamma, "linearity_gamma_se": se}
    return replace(cal, params={**cal.params, **found})


def _linearised(cal: SensitivityEstimate, gamma: float) -> SensitivityEstimate:
    """``cal``, fitted to responses linearised at ``gamma``, keeping it."""
    assert cal.excess is not None
    return _with_side_meta(
        replace(cal, excess=replace(cal.excess, linearity_gamma=gamma))
    )


def _chart_linearity(
    cal: SensitivityEstimate, problem: _Problem
) -> tuple[float, float]:
    """The chart's non-linearity ``gamma`` and its standard error at the fit's
    residuals (:func:`_chart_residual_terms`); ``(0, inf)`` where none was fitted.
    ``"bayes"``: :func:`fit_linearity` under its error model, where that found a
    non-linearity. The paper's estimators: :func:`fit_bend`, only ever refused
    (:func:`~tunespec.core.plausibility.check_chart_linearity`): they leave a misfit
    of percents and reproduce the paper as published."""
    if cal.method != "bayes":
        return fit_bend(*_chart_residual_terms(problem, cal))
    if cal.excess is None or cal.excess.nonlinearity == 0.0:
        return 0.0, float("inf")
    return fit_linearity(*_chart_residual_terms(problem, cal), cal.excess)


def _estimate_once(
    problem: _Problem,
    db: dict[str, Spectra],
    method: str,
    *,
    fit_spd_shift: bool,
    self_calibrate: bool,
    n_components: int,
    explained_variance: float | None,
    replicates: int,
    illuminant_names: tuple[str, ...],
    exclude: str | Iterable[str] | None,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> SensitivityEstimate:
    """One fit of :func:`estimate_camera_sensitivity` (its options resolved) to the
    prepared ``problem`` with the camera database ``db``."""
    report(progress, 0.0)
    if method == "bayes":
        S, params, correction, covariance, readings = _estimate_sensitivity_bayes(
            problem, db, fit_shift=fit_spd_shift, self_calibrate=self_calibrate,
            illuminant_names=illuminant_names, replicates=replicates,
            should_stop=should_stop,
        )  # fmt: skip
        shift_nm = float(correction.common_shift_nm)
        shift_at_bound = abs(shift_nm) >= SPD_SHIFT_RANGE_NM
    else:
        correction, covariance, readings = None, None, None
        S, params, shift_nm, shift_at_bound = _estimate_classic(
            problem, db, method, fit_spd_shift=fit_spd_shift,
            n_components=n_components, explained_variance=explained_variance,
            progress=progress, should_stop=should_stop,
        )  # fmt: skip
    excluded = sorted({exclude} if isinstance(exclude, str) else set(exclude or ()))
    params |= {"n_stimuli": int(problem.C.shape[0]), "n_patches": len(problem.patches),
               "excluded_cameras": excluded, "spd_shift_fitted": fit_spd_shift,
               "spd_shift_nm": shift_nm, "spd_shift_at_bound": shift_at_bound}  # fmt: skip
    report(progress, 1.0)
    return _with_excess(SensitivityEstimate(
        Spectra(problem.wavelength_nm, S, CHANNELS), method, params,
        problem.excluded_patches, spd_shift_nm=shift_nm, led_correction=correction,
        covariance=covariance, readings=readings,
    ), problem)  # fmt: skip


def _with_excess(cal: SensitivityEstimate, problem: _Problem) -> SensitivityEstimate:
    """``cal`` with its excess variance (:func:`fit_excess_variance` of
    :func:`_chart_residual_terms`) and the side file's keys in its sensitivities'
    meta."""
    measured, pred, noise = _chart_residual_terms(problem, cal)
    excess = fit_excess_variance(
        measured, pred, noise, weight_variance=problem.var.reshape(pred.shape)
    )
    return _with_side_meta(replace(cal, excess=excess))


def _with_side_meta(cal: SensitivityEstimate) -> SensitivityEstimate:
    """``cal`` with the side file's keys in its sensitivities' meta (the pipeline
    reads them there)."""
    s = cal.sensitivity
    sens = Spectra(s.wavelength_nm, s.values, s.names, cal.side_meta())
    return replace(cal, sensitivity=sens)


def _chart_residual_terms(
    problem: _Problem, cal: SensitivityEstimate
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """The chart's responses, what the fit predicts for them (Eq. 1 with the fitted
    corrections) and their known variance, (n_p, m) each: the ROI noise (the
    flat-field residual is fitted from the residuals) and what the light's reading
    noise does to Eq. 1 at the chart (the replicates' spread,
    :class:`~tunespec.core.readings.ReadingReplicates`): the estimate's budget
    carries that apart, as its ``readings`` term, and an excess fitted to it would
    count it twice."""
    S = cal.sensitivity.values
    L = undo_metering(problem.readings, cal.led_correction, cal.spd_shift_nm)
    pred = stimulus_matrix(L.values, problem.R, problem.step_nm) @ S.T
    n_p = len(problem.patches)
    noise = (problem.var - (SMOOTH_RELATIVE_ERROR * problem.C) ** 2).reshape(n_p, -1)
    if cal.readings is not None:
        dF = cal.readings.lighting_deviations(
            problem.readings, S, cal.corrections_for(problem.readings.names)
        )
        noise = noise + np.mean(np.einsum("kml,pl->kpm", dF, problem.R) ** 2, axis=0)
    return problem.C.reshape(n_p, -1), pred.reshape(n_p, -1), noise


def _check_solvable(problem: _Problem, method: str, db: dict[str, Spectra]) -> None:
    """Raise if the stimuli are degenerate or ``"pca"`` has no database."""
    if _numerical_rank(problem.A) < min(_MIN_RANK_SMOOTH, problem.A.shape[1]):
        raise SingularSystemError(
            f"the {problem.A.shape[0]} stimuli span fewer than {_MIN_RANK_SMOOTH} "
            "independent spectra; use more patches or illuminants"
        )
    if method == "pca" and not db:
        raise InputError("method 'pca' needs a camera database (it is empty)")


def _estimate_classic(
    problem: _Problem,
    db: dict[str, Spectra],
    method: str,
    *,
    fit_spd_shift: bool,
    n_components: int,
    explained_variance: float | None,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> tuple[NDArray[np.float64], dict[str, Any], float, bool]:
    """``"smooth"`` or ``"pca"`` after the optional common SPD-shift fit:
    ``(S, params, shift_nm, shift_at_bound)``."""
    shift_nm, shift_at_bound = 0.0, False
    if fit_spd_shift:
        shift_nm, shift_at_bound = _fit_spd_shift(problem, db, should_stop)
        report(progress, 0.2)
    S, params = SENSITIVITY_METHODS[method](
        problem.shifted(shift_nm),
        db,
        n_components=n_components,
        explained_variance=explained_variance,
        progress=None if progress is None else _scaled(progress, 0.2 * fit_spd_shift),
        should_stop=should_stop,
    )
    return S, params, shift_nm, shift_at_bound


def _options(
    method: str, fit_spd_shift: bool | None, self_calibrate: bool | None
) -> tuple[bool, bool]:
    """``(fit_spd_shift, self_calibrate)`` with their per-method defaults resolved
    (see :func:`estimate_camera_sensitivity`); an unknown method or per-LED
    self-calibration without ``"bayes"`` is an :class:`InputError`."""
    if method not in SENSITIVITY_METHODS:
        raise InputError(
            f"unknown sensitivity method {method!r}; choose one of "
            f"{', '.join(SENSITIVITY_METHODS)}"
        )
    if fit_spd_shift is None:
        fit_spd_shift = method in ("smooth", "bayes")
    if self_calibrate is None:
        self_calibrate = method == "bayes" and fit_spd_shift
    elif self_calibrate and method != "bayes":
        raise InputError(
            f"per-LED self-calibration needs method 'bayes', not {method!r}"
        )
    return bool(fit_spd_shift), bool(self_calibrate)


def _scaled(progress: ProgressFn, start: float) -> ProgressFn:
    """``progress`` mapped from [0, 1] onto [start, 1]."""
    return lambda f: report(progress, start + (1.0 - start) * f)
