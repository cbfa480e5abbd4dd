"""The image formation model, Eq. 1 of the paper: ``c = S D(i) r + e``.

Used by the estimators (which invert it) and by the simulated bench (which renders
with it), so a closed-loop test recovers what the simulator was built with.

The sum over wavelength is weighted by the grid step, ``c = sum_l S(l) i(l) r(l) dl``,
so a response does not depend on the sampling step: the bench may render on a fine
grid while the estimators work on a coarser one.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source: Setup, Characterization
and Reflectance Estimation (the paper in ``shared/reference``), Eq. 1, 3 and 5.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["lighting_matrix", "render_rgb"]


def render_rgb(
    reflectance: ArrayLike,
    illuminant: ArrayLike,
    sensitivity: ArrayLike,
    step_nm: float,
) -> NDArray[np.float64]:
    """Noise-free camera responses, Eq. 1.

    Parameters
    ----------
    reflectance : (n_p, n_wl)
        Reflectance factors.
    illuminant : (n_i, n_wl)
        Spectral power of each illuminant (as the light source's spectroradiometer
        reports it, times the exposure's scale).
    sensitivity : (3, n_wl)
        Camera sensitivities, rows R, G, B, in response per (power unit x nm).
    step_nm
        Wavelength step of the common grid.

    Returns
    -------
    (n_p, n_i, 3)
        Responses.

    References
    ----------
    Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
    ``shared/reference``), Eq. 1 (camera response as the sum over
    wavelengths of sensitivity x illuminant x reflectance).

    Examples
    --------
    >>> import numpy as np
    >>> render_rgb(np.ones((1, 3)), np.ones((1, 3)), np.eye(3), 10.0)
    array([[[10., 10., 10.]]])
    """
    R = np.atleast_2d(np.asarray(reflectance, dtype=np.float64))
    L = np.atleast_2d(np.asarray(illuminant, dtype=np.float64))
    S = np.atleast_2d(np.asarray(sensitivity, dtype=np.float64))
    return np.einsum("pl,il,cl->pic", R, L, S) * step_nm


def lighting_matrix(
    illuminant: ArrayLike, sensitivity: ArrayLike, step_nm: float
) -> NDArray[np.float64]:
    """The combined lighting matrix ``F`` of Eq. 5, shape (3 n_i, n_wl).

    Rows are ordered illuminant-major, ``(i1 R, i1 G, i1 B, i2 R, ...)``, matching
    ``render_rgb(r, i, S).reshape(n_p, -1)``, so that ``render == r @ F.T``.

    References
    ----------
    Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
    ``shared/reference``), Eq. 1 and 5 (the stacked matrix of
    sensitivity x illuminant products that maps a reflectance to its responses).

    Examples
    --------
    >>> import numpy as np
    >>> r, i, S = np.ones((2, 4)), np.ones((5, 4)), np.ones((3, 4))
    >>> F = lighting_matrix(i, S, 1.0)
    >>> np.allclose(r @ F.T, render_rgb(r, i, S, 1.0).reshape(2, -1))
    True
    """
    L = np.atleast_2d(np.asarray(illuminant, dtype=np.float64))
    S = np.atleast_2d(np.asarray(sensitivity, dtype=np.float64))
    return (L[:, None, :] * S[None, :, :]).reshape(-1, L.shape[1]) * step_nm
