"""Single-shot CIE XYZ (D50) from one RGB capture under an illuminant-matched LED mix.

The gonio-imager measures colorimetry at every geometry "in a single shot by simply
adjusting the tunable light source to the desired SPD" (the paper's introduction).
With the camera's calibrated sensitivities ``S`` (Eq. 3-4) and the mix's measured SPD
``i``, the camera's response to any reflectance ``r`` is predicted by Eq. 1,
``c = S diag(i) r``. A camera-to-XYZ transform is then derived, as the rawtoaces /
ACES input transforms are (colour-science's ``matrix_idt``), from a *reflectance
prior* -- a training set, not the target being measured -- by least squares over the
prior's predicted responses with the perfect white preserved exactly:

    C = argmin sum_k || phi(c_k) C - XYZ_D50(r_k) ||^2,   phi(c_white) C = XYZ_D50(white)

``phi`` is a degree-2 root-polynomial (Finlayson et al. 2015: R, G, B, sqrt(RG),
sqrt(GB), sqrt(RB)), which scales with the exposure like a matrix does, or plain
R, G, B (a 3x3). Predicted responses carry no noise, so the prior can be large and the
transform richer than a chart fit supports. The XYZ are CIE D50 / 1931 2° by ASTM E308, Y = 100 for the perfect
reflector, as everywhere in TuneSpec (:mod:`tunespec.core.colorimetry`); responses
are the flat-fielded, full-scale units of :mod:`tunespec.core.responses`, so ``i``
carries the exposure scale as the Wiener estimator's illuminants do.

The baseline it is compared with is the classic chart characterisation: a 3x3 fitted by
least squares on the ColorChecker SG's *measured* RGB against its known XYZ
(:func:`fit_chart_matrix`).

Beyond matching D50 for the eye, :func:`optimise_mix_for_camera` chooses the LED
levels for the camera: it minimises the camera's colorimetric error (the residual of
the best transform over the prior, a measure of how far camera x mix is from the Luther
condition) while the mix stays an acceptable D50 simulator: chromaticity pinned to
D50's and the CIE 51.2 metamerism index of the reflectance set (here mean CIEDE2000
under the mix vs under D50) at most ``max_metamerism`` (0.5 = CIE 51.2 category B).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Eq. 1, 3-4, introduction; Academy of Motion Picture Arts and
Sciences, P-2013-001 "Recommended Procedures for the Creation and Use of Digital
Camera System Input Device Transforms (IDTs)" (rawtoaces; colour-science
``matrix_idt``); R. Luther, "Aus dem Gebiet der Farbreizmetrik", Z. techn. Physik 8
(1927) (colorimetric cameras); CIE 51.2-1999 "A method for assessing the quality of
daylight simulators for colorimetry" (metamerism index categories).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.colorimetry import ICC_D50_XYZ, delta_e_2000, xyz_d50
from tunespec.core.errors import InputError
from tunespec.core.forward_model import render_rgb
from tunespec.core.illuminant_match import (
    _lab,
    cmfs_on,
    lab_under,
    matching_grid,
    uv_prime,
)
from tunespec.core.spectra import Spectra

__all__ = [
    "TRANSFORM_TERMS",
    "CameraMix",
    "XyzTransform",
    "apply_xyz_transform",
    "fit_chart_matrix",
    "optimise_mix_for_camera",
    "xyz_transform",
]

#: Weight of the white's residuals in the CIELAB fit (keeps it exact to ~1e-6).
_WHITE_WEIGHT = 1e3
#: CIE 51.2 category B upper limit of the metamerism index (CIELAB units).
CIE51_CATEGORY_B = 0.5


def _lab_d50(XYZ: NDArray[np.float64]) -> NDArray[np.float64]:
    """CIELAB against the ICC D50 white (as :func:`colorimetry.xyz_to_lab_d50`)."""
    return _lab(XYZ, ICC_D50_XYZ)


@dataclass(frozen=True, eq=False)
class XyzTransform:
    """A camera-to-XYZ (D50) transform derived for one mix.

    Parameters
    ----------
    coefficients : (n_terms, 3)
        ``XYZ = root_polynomial_terms(rgb, kind) @ coefficients`` (rgb in full-scale
        units, XYZ with the perfect white's Y = 100).
    kind : str
        ``"matrix"`` (3 terms) or ``"root-polynomial"`` (6 terms).
    prior_mean_de00, prior_max_de00 : float
        CIEDE2000 of the fit over the prior (noise-free predicted responses).
    n_prior : int
    """

    coefficients: NDArray[np.float64]
    kind: str
    prior_mean_de00: float
    prior_max_de00: float
    n_prior: int

    def __call__(self, rgb: ArrayLike) -> NDArray[np.float64]:
        """XYZ of responses ``(..., 3)``."""
        return root_polynomial_terms(rgb, self.kind) @ self.coefficients

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "kind": self.kind,
            "coefficients": self.coefficients.tolist(),
            "prior_mean_de00": self.prior_mean_de00,
            "prior_max_de00": self.prior_max_de00,
            "n_prior": self.n_prior,
        }


def _check_inputs(sensitivity: Spectra, mix: Spectra, prior: Spectra) -> Spectra:
    if len(sensitivity) != 3:
        raise InputError(f"expected R, G, B sensitivities, got {len(sensitivity)} rows")
    if len(mix) != 1:
        raise InputError(f"expected one mix spectrum, got {len(mix)}")
    if len(prior) < 9:
        raise InputError(
            f"the reflectance prior needs at least 9 spectra, got {len(prior)}"
        )
    wl = sensitivity.wavelength_nm
    grid = matching_grid(sensitivity, mix, prior, step_nm=sensitivity.step_nm)
    if grid.n != wl.size:
        raise InputError(
            f"the sensitivities' grid {wl[0]:g}-{wl[-1]:g} nm must lie inside the mix "
            "and the prior"
        )
    return mix.resample(grid, average=True)


def _predicted(
    sensitivity: Spectra, mix: Spectra, reflectance: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Eq. 1 for reflectances under the mix, (n, 3)."""
    return render_rgb(reflectance, mix.values, sensitivity.values, sensitivity.step_nm)[
        :, 0, :
    ]


#: Exponents (of R, G, B) of each regressor, per transform kind: the degree-1
#: (a 3x3), 2 and 3 root-polynomials of Finlayson et al. (2015). Every term is a
#: product of powers summing to 1, so it scales with the exposure.
TRANSFORM_TERMS = {
    "matrix": ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    "root-polynomial": (
        (1, 0, 0), (0, 1, 0), (0, 0, 1),
        (1 / 2, 1 / 2, 0), (0, 1 / 2, 1 / 2), (1 / 2, 0, 1 / 2),
    ),
    "root-polynomial-3": (
        (1, 0, 0), (0, 1, 0), (0, 0, 1),
        (1 / 2, 1 / 2, 0), (0, 1 / 2, 1 / 2), (1 / 2, 0, 1 / 2),
        (1 / 3, 2 / 3, 0), (1 / 3, 0, 2 / 3), (2 / 3, 1 / 3, 0),
        (0, 1 / 3, 2 / 3), (2 / 3, 0, 1 / 3), (0, 2 / 3, 1 / 3),
        (1 / 3, 1 / 3, 1 / 3),
    ),
}  # fmt: skip


def _exponents(kind: str) -> NDArray[np.float64]:
    if kind not in TRANSFORM_TERMS:
        raise InputError(
            f"unknown transform kind {kind!r}: {', '.join(TRANSFORM_TERMS)}"
        )
    return np.array(TRANSFORM_TERMS[kind], dtype=np.float64)


def root_polynomial_terms(
    rgb: ArrayLike, kind: str = "root-polynomial"
) -> NDArray[np.float64]:
    """The regressors of a transform, ``(..., n_terms)`` (:data:`TRANSFORM_TERMS`).

    ``"matrix"``: R, G, B (a 3x3). ``"root-polynomial"``: R, G, B, sqrt(RG), sqrt(GB),
    sqrt(RB), the degree-2 root-polynomial of Finlayson et al. (2015);
    ``"root-polynomial-3"`` adds the 7 cube-root terms of degree 3. Every term scales
    with the exposure, so the transform holds at any exposure and HDR level. The
    linear terms keep their sign; negative responses (noise around black) count as 0
    in the roots.
    """
    e = _exponents(kind)
    c = np.asarray(rgb, dtype=np.float64)
    p = np.maximum(c, 0.0)[..., None, :]
    terms = np.prod(np.where(e > 0, p**e, 1.0), axis=-1)
    linear = (e == 1).any(axis=1)
    terms[..., linear] = c @ e[linear].T
    return terms


def _terms_jacobian(rgb: NDArray[np.float64], kind: str) -> NDArray[np.float64]:
    """d terms / d rgb, ``(..., n_terms, 3)``: ``e_jk t_j / c_k``."""
    e = _exponents(kind)
    c = np.maximum(np.asarray(rgb, dtype=np.float64), 1e-12)
    t = root_polynomial_terms(c, kind)
    return e * t[..., :, None] / c[..., None, :]


def _white_constrained_lstsq(
    phi: NDArray[np.float64],
    xyz: NDArray[np.float64],
    phi_w: NDArray[np.float64],
    xyz_w: NDArray[np.float64],
    weights: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Least-squares ``C`` (n_terms, 3), ``phi @ C ~ xyz``, with ``phi_w @ C = xyz_w``.

    Solved with a Lagrange multiplier (the KKT system), so the perfect white maps to
    its XYZ exactly. ``weights`` (n,) weight the rows.
    """
    if weights is not None:
        phi, xyz = phi * weights[:, None], xyz * weights[:, None]
    n = phi.shape[1]
    kkt = np.block([[phi.T @ phi, phi_w[:, None]], [phi_w[None, :], np.zeros((1, 1))]])
    rhs = np.vstack([phi.T @ xyz, xyz_w[None, :]])
    return np.linalg.solve(kkt, rhs)[:n]


def xyz_transform(
    sensitivity: Spectra,
    mix: Spectra,
    prior: Spectra,
    *,
    kind: str = "root-polynomial",
    relative: bool = False,
) -> XyzTransform:
    """The camera-to-XYZ (D50) transform for captures under ``mix``.

    Parameters
    ----------
    sensitivity : Spectra, (3, n_wl)
        Calibrated sensitivities R, G, B (``tunespec calibrate``), on the working grid.
    mix : Spectra, one spectrum
        The mix's SPD as the light source's spectroradiometer reports it, times the
        exposure scale (the same convention as the Wiener estimator's illuminants).
    prior : Spectra
        Training reflectances (e.g. the ColorChecker SG); never the target being
        measured.
    kind
        ``"root-polynomial"`` (default), ``"root-polynomial-3"`` or ``"matrix"``
        (a 3x3), see :func:`root_polynomial_terms`.
    relative
        Weight the prior's rows by ``1 / (Y + 1)`` (relative errors, as CIELAB
        weighs dark colours): better for a prior of few materials with dark ones
        (a gonio session's own spectra), slightly worse on broad sets (measured:
        0.78 vs 0.73 mean dE00 on the 190 rawtoaces reflectances).

    Returns
    -------
    XyzTransform

    Raises
    ------
    InputError
        Wrong shapes, fewer than 9 prior spectra, grids that do not nest, a channel
        that sees no light.

    Notes
    -----
    The fit is least squares in XYZ over the prior's *predicted* (noise-free)
    responses with the perfect white preserved. Because the responses are predicted
    from the sensitivities rather than measured, the prior can be as large as wanted
    and the transform may have more terms than a chart fit could support.

    References
    ----------
    AMPAS P-2013-001 (IDT from sensitivities, illuminant and training reflectances);
    G. D. Finlayson, M. Mackiewicz, A. Hurlbert, "Color correction using
    root-polynomial regression", IEEE Trans. Image Processing 24(5), 1460-1470
    (2015), doi:10.1109/TIP.2015.2405336; the paper, Eq. 1.
    """
    mix_g = _check_inputs(sensitivity, mix, prior)
    wl = sensitivity.wavelength_nm
    R = prior.resample(_grid_of(wl)).values
    rgb = _predicted(sensitivity, mix_g, R)
    rgb_w = _predicted(sensitivity, mix_g, np.ones((1, wl.size)))[0]
    if not np.all(np.isfinite(rgb_w)) or rgb_w.min() <= 0:
        raise InputError("the camera sees no light in some channel under the mix")
    xyz = xyz_d50(R, wl)
    C = _white_constrained_lstsq(
        root_polynomial_terms(rgb, kind),
        xyz,
        root_polynomial_terms(rgb_w, kind),
        xyz_d50(np.ones(wl.size), wl),
        1.0 / (np.maximum(xyz[:, 1], 0.0) + 1.0) if relative else None,
    )
    de = delta_e_2000(
        _lab_d50(np.maximum(root_polynomial_terms(rgb, kind) @ C, 1e-9)), _lab_d50(xyz)
    )
    return XyzTransform(C, kind, float(de.mean()), float(de.max()), len(prior))


def _grid_of(wl: NDArray[np.float64]) -> Any:
    from tunespec.core.spectra import Grid

    return Grid(float(wl[0]), float(wl[-1]), float(wl[1] - wl[0]))


def apply_xyz_transform(
    transform: XyzTransform,
    rgb: ArrayLike,
    rgb_var: ArrayLike | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """XYZ of responses ``(..., 3)`` (per patch or per pixel), with their covariance.

    Parameters
    ----------
    transform
        From :func:`xyz_transform`.
    rgb : (..., 3)
        Flat-fielded responses in full-scale units.
    rgb_var : (..., 3), optional
        Their noise variances (e.g. the merged HDR variance, :mod:`tunespec.core.hdr`).

    Returns
    -------
    XYZ : (..., 3)
    cov : (..., 3, 3) or None
        ``J diag(var) J^T`` with ``J`` the transform's Jacobian at ``rgb``
        (first-order propagation, JCGM 100).
    """
    c = np.asarray(rgb, dtype=np.float64)
    if c.shape[-1] != 3:
        raise InputError(f"expected responses of shape (..., 3), got {c.shape}")
    XYZ = transform(c)
    if rgb_var is None:
        return XYZ, None
    v = np.asarray(rgb_var, dtype=np.float64)
    J = np.einsum(
        "...tk,tj->...jk", _terms_jacobian(c, transform.kind), transform.coefficients
    )
    return XYZ, np.einsum("...ik,...k,...jk->...ij", J, v, J)


def fit_chart_matrix(rgb: ArrayLike, xyz: ArrayLike) -> NDArray[np.float64]:
    """The baseline: an ordinary least-squares 3x3 from a chart's measured RGB to XYZ.

    Parameters
    ----------
    rgb : (n, 3)
        The chart's measured responses (e.g. the ColorChecker SG under a D50 simulator).
    xyz : (n, 3)
        Its known XYZ (D50).

    Returns
    -------
    (3, 3)
        ``XYZ = M @ rgb``.
    """
    A = np.asarray(rgb, dtype=np.float64)
    B = np.asarray(xyz, dtype=np.float64)
    if A.ndim != 2 or A.shape[1] != 3 or A.shape != B.shape or len(A) < 3:
        raise InputError(
            f"expected matching (n, 3) arrays, got {A.shape} and {B.shape}"
        )
    return np.linalg.lstsq(A, B, rcond=None)[0].T


@dataclass(frozen=True, eq=False)
class CameraMix:
    """Result of :func:`optimise_mix_for_camera`.

    ``levels`` (n_led,) in [0, 1]; ``camera_rms_deab``: the prior's RMS CIELAB error of
    the camera's best transform under the mix (noise-free); ``metamerism_de00``: mean CIEDE2000 of the
    reflectance set under the mix vs D50; ``delta_uv`` against D50;
    ``start_camera_rms_deab``: the camera's error under the start levels (the plain
    D50 match), for comparison.
    """

    levels: NDArray[np.float64]
    camera_rms_deab: float
    metamerism_de00: float
    delta_uv: float
    start_camera_rms_deab: float = math.nan


def _camera_residual(
    x: NDArray[np.float64],
    A_rgb: NDArray[np.float64],
    A_rgb_w: NDArray[np.float64],
    xyz: NDArray[np.float64],
    xyz_w: NDArray[np.float64],
    kind: str,
) -> float:
    """Mean squared CIELAB error of the white-preserving LS transform under ``x``."""
    rgb = np.einsum("j,kjc->kc", x, A_rgb)
    rgb_w = x @ A_rgb_w
    phi = root_polynomial_terms(rgb, kind)
    C = _white_constrained_lstsq(phi, xyz, root_polynomial_terms(rgb_w, kind), xyz_w)
    d = _lab_d50(np.maximum(phi @ C, 1e-9)) - _lab_d50(xyz)
    return float(np.mean(np.sum(d * d, axis=1)))


def optimise_mix_for_camera(
    leds: Spectra,
    sensitivity: Spectra,
    prior: Spectra,
    start_levels: ArrayLike,
    *,
    max_metamerism: float = CIE51_CATEGORY_B,
    kind: str = "root-polynomial",
) -> CameraMix:
    """LED levels making camera x mix as colorimetric as the LEDs allow, D50 kept.

    Minimises the camera's CIELAB error over ``prior`` (the best white-preserving
    transform of ``kind`` for each mix) subject to: chromaticity of the mix = D50's
    (u'v'), mean CIEDE2000 of ``prior`` under the mix vs under D50 <=
    ``max_metamerism`` (CIE 51.2), levels in [0, 1]. ``start_levels`` is the plain D50
    match (:func:`~tunespec.core.illuminant_match.match_illuminant`); the result is
    never worse than it for the camera.

    References
    ----------
    Luther (1927); CIE 51.2-1999; AMPAS P-2013-001.
    """
    from scipy.optimize import minimize

    from tunespec.core.illuminant_match import illuminant_spd

    wl = sensitivity.wavelength_nm
    grid = _grid_of(wl)
    L = leds.resample(grid, average=True).values
    R = prior.resample(grid).values
    T = illuminant_spd("D50").resample(grid).values[0]
    cmfs = cmfs_on(wl)
    A_rgb = np.einsum("kl,jl,cl->kjc", R, L, sensitivity.values)
    A_rgb_w = np.einsum("jl,cl->jc", L, sensitivity.values)
    Aw = L @ cmfs
    xyz, xyz_w = xyz_d50(R, wl), xyz_d50(np.ones(wl.size), wl)
    lab_t = lab_under(R, T, cmfs)
    uv_t = uv_prime(T @ cmfs)
    x0 = np.asarray(start_levels, dtype=np.float64)
    if x0.shape != (len(leds),) or np.any(x0 < 0) or not np.any(x0 > 0):
        raise InputError(f"start_levels: expected {len(leds)} levels >= 0, not all 0")
    x0 = x0 / (x0 @ Aw)[1]

    def metamerism(x: NDArray[np.float64]) -> float:
        return float(delta_e_2000(lab_under(R, x @ L, cmfs), lab_t).mean())

    def camera(x: NDArray[np.float64]) -> float:
        return _camera_residual(x, A_rgb, A_rgb_w, xyz, xyz_w, kind)

    s = float(x0.max())
    res = minimize(
        lambda z: camera(z * s),
        x0 / s,
        method="SLSQP",
        bounds=[(0.0, 10.0)] * len(x0),
        constraints=[
            {"type": "eq", "fun": lambda z: 1e3 * (uv_prime((z * s) @ Aw) - uv_t)},
            {"type": "eq", "fun": lambda z: ((z * s) @ Aw)[1] - 1.0},
            {"type": "ineq", "fun": lambda z: max_metamerism - metamerism(z * s)},
        ],
        options={"maxiter": 200, "ftol": 1e-9},
    )
    x = np.clip(res.x * s, 0.0, None)
    feasible = np.max(np.abs(uv_prime(x @ Aw) - uv_t)) < 1e-5
    feasible = feasible and metamerism(x) <= max_metamerism * 1.001
    if not feasible or camera(x) > camera(x0):
        x = x0
    duv = float(np.hypot(*(uv_prime(x @ Aw) - uv_t)))
    return CameraMix(x / x.max(), math.sqrt(camera(x)), metamerism(x), duv,
                     math.sqrt(camera(x0)))  # fmt: skip
