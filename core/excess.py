"""What a calibration's residuals show beyond the noise it knows: systematic response errors.

Photon and read noise (the ROI statistics) and the flat-field residual are not all that
moves a measured response away from Eq. 1. Stray light and cross-talk between patches,
a sensor that is slightly non-linear, and the flat field's irradiance ratio where it is
not the same under every LED add errors that no ROI statistic shows, and the parts of
them that a patch shares under all LEDs do not average out over its 3 n_i responses:
they move its luminance, and so L*, as one.

The chart's residuals after the calibration ``e_p = c_p - c_hat_p`` (the stacked
responses of patch ``p``) are modelled as::

    e_p ~ N(0, diag(v_p + tau_r^2 c_hat_p^2 + tau_a^2 cbar^2) + tau_c^2 c_hat_p c_hat_p')

``v_p`` the known variances (ROI mean noise, flat-field residual), ``tau_r`` a relative
error of each response on its own, ``tau_a`` an additive one in units of the mean
response ``cbar`` under that LED and channel (stray light, cross-talk) and ``tau_c`` a
relative error that a patch shares under every LED and channel. All three are found by
maximum likelihood over a grid (:func:`fit_excess_variance`, exact Gaussian
likelihood, the rank-one term by the matrix determinant lemma and Sherman-Morrison). The calibration keeps them
(:class:`ExcessVariance`), and :mod:`tunespec.core.uncertainty` adds them to every
estimated reflectance's response covariance.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Eq. 1 and 6. JCGM 100:2008 (GUM), 3.2.4 (recognised systematic
effects are part of the uncertainty); S. R. Searle, G. Casella, C. E. McCulloch,
*Variance Components* (Wiley, 1992), ch. 6 (maximum likelihood of variance components).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError

__all__ = [
    "FLAT_FIELD_RESIDUAL",
    "ExcessVariance",
    "fit_excess_variance",
]

#: Relative standard deviation of a response that flat-fielding (Eq. 2) leaves: the
#: irradiance ratio between white reference and target is known to about 0.3 %.
FLAT_FIELD_RESIDUAL = 0.003
#: Relative standard deviations tried for each term: 0 and 1e-4 to 5 %.
TAU_GRID = np.concatenate([[0.0], np.logspace(-4.0, np.log10(0.05), 40)])
#: Largest relative error accepted from a side file.
_TAU_MAX = 1.0


@dataclass(frozen=True)
class ExcessVariance:
    """Systematic errors of the responses found in a calibration's residuals.

    ``response_relative`` (``tau_r``): a relative error of each response on its
    own; ``level_relative`` (``tau_a``): an additive error of each response in
    units of the mean response under its LED and channel (stray light and
    cross-talk add light in proportion to what the chart sends back, not to the
    patch's own signal); ``common_relative`` (``tau_c``): a relative error shared
    by all responses of one patch; ``n_patches`` and ``n_responses``: how many
    residuals measured them.
    """

    response_relative: float
    common_relative: float
    n_patches: int = 0
    n_responses: int = 0
    level_relative: float = 0.0

    def covariance(
        self, rgb: NDArray[np.float64], level: NDArray[np.float64] | None = None
    ) -> NDArray[np.float64]:
        """Their response covariance for responses ``rgb`` (n_p, m), (n_p, m, m);
        ``level`` (m,): the mean response under each LED and channel (default the
        mean of ``rgb``'s rows)."""
        rgb = np.asarray(rgb, dtype=np.float64)
        if level is None:
            level = rgb.mean(axis=0)
        out = self.common_relative**2 * rgb[:, :, None] * rgb[:, None, :]
        idx = np.arange(rgb.shape[1])
        out[:, idx, idx] += (self.response_relative * rgb) ** 2 + (
            self.level_relative * np.asarray(level)
        ) ** 2
        return out

    def as_dict(self) -> dict[str, Any]:
        return {
            "response_relative": self.response_relative,
            "level_relative": self.level_relative,
            "common_relative": self.common_relative,
            "n_patches": self.n_patches,
            "n_responses": self.n_responses,
        }

    @classmethod
    def from_dict(cls, doc: Any, path: str | None = None) -> ExcessVariance:
        """Back from :meth:`as_dict` (a side file's ``excess_variance``)."""
        if not isinstance(doc, dict):
            raise InputError("excess_variance: expected an object", path=path)
        vals = {}
        for key in ("response_relative", "level_relative", "common_relative"):
            v = doc.get(key, 0.0)
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise InputError(f"excess_variance.{key}: expected a number", path=path)
            if not 0.0 <= float(v) <= _TAU_MAX:
                raise InputError(
                    f"excess_variance.{key} = {v}: expected 0 to {_TAU_MAX}", path=path
                )
            vals[key] = float(v)
        counts = [doc.get(k, 0) for k in ("n_patches", "n_responses")]
        if any(isinstance(c, bool) or not isinstance(c, int) or c < 0 for c in counts):
            raise InputError(
                "excess_variance: n_patches and n_responses must be counts", path=path
            )
        return cls(
            vals["response_relative"],
            vals["common_relative"],
            counts[0],
            counts[1],
            vals["level_relative"],
        )


def fit_excess_variance(
    measured: NDArray[np.float64],
    predicted: NDArray[np.float64],
    noise_variance: NDArray[np.float64],
) -> ExcessVariance:
    """Maximum-likelihood ``(tau_r, tau_a, tau_c)`` of the chart's residuals.

    Parameters
    ----------
    measured, predicted : (n_p, m)
        Each patch's stacked responses and what the calibration predicts for them.
    noise_variance : (n_p, m)
        Their known variances (ROI mean noise and flat-field residual).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> c = rng.uniform(0.05, 0.8, (140, 66))
    >>> v = (1e-3 * c) ** 2
    >>> e = c * (0.004 * rng.standard_normal((140, 1)) + 0.002 * rng.standard_normal(c.shape))
    >>> e += 0.003 * c.mean(axis=0) * rng.standard_normal(c.shape)
    >>> fit = fit_excess_variance(c + e + np.sqrt(v) * rng.standard_normal(c.shape), c, v)
    >>> [round(x, 4) for x in (fit.common_relative, fit.response_relative, fit.level_relative)]
    [0.0046, 0.0021, 0.0028]
    """
    c = np.asarray(predicted, dtype=np.float64)
    r = np.asarray(measured, dtype=np.float64) - c
    v = np.asarray(noise_variance, dtype=np.float64)
    level2 = c.mean(axis=0) ** 2
    n_p, m = c.shape
    t2 = TAU_GRID[:, None] ** 2
    best, best_nll = (0.0, 0.0, 0.0), np.inf
    for ta in TAU_GRID:
        for tr in TAU_GRID:
            d = v + (tr * c) ** 2 + ta**2 * level2
            d = np.where(d > 0, d, np.inf)
            q0 = np.sum(r**2 / d, axis=1)
            ld0 = np.sum(np.log(np.where(np.isfinite(d), d, 1.0)), axis=1)
            su = np.sum(c**2 / d, axis=1)
            sr = np.sum(c * r / d, axis=1)
            den = 1.0 + t2 * su[None]
            nll = np.sum(
                q0[None] - t2 * sr[None] ** 2 / den + ld0[None] + np.log(den), 1
            )
            j = int(np.argmin(nll))
            if nll[j] < best_nll:
                best_nll, best = (
                    float(nll[j]),
                    (float(tr), float(ta), float(TAU_GRID[j])),
                )
    return ExcessVariance(best[0], best[2], n_p, n_p * m, best[1])
