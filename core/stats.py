"""How well estimated sensitivities predict camera responses (Table 1 of the paper).

The paper validates its estimated sensitivities without ground truth: it predicts the
responses to known stimuli (ColorChecker SG patches under each LED) with Eq. 1 and
compares them with the captured ones. :func:`prediction_stats` computes its Table 1;
:func:`calibration_report` gives the same statistics for the patches used in the fit
and for patches held aside from it (a fair, out-of-sample check).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source: Setup, Characterization
and Reflectance Estimation (``shared/reference/paper-trichromatic-reflectance-capture``),
Table 1 and Figure 5.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.calibration import predict_responses
from tunespec.core.errors import InputError
from tunespec.core.responses import Responses
from tunespec.core.sensitivity import SensitivityEstimate
from tunespec.core.spectra import Spectra

__all__ = [
    "STAT_ROWS",
    "CalibrationReport",
    "PredictionStats",
    "calibration_report",
    "prediction_stats",
    "sensitivity_rms",
    "split_patches",
]

#: Row labels of Table 1: the three channels and their root mean square.
STAT_ROWS = ("Red", "Green", "Blue", "RGB")


@dataclass(frozen=True)
class PredictionStats:
    """Response prediction errors as in Table 1 of the paper.

    Parameters
    ----------
    mean, max, p95 : (4,)
        Mean, maximum and 95th percentile of the error, rows :data:`STAT_ROWS`:
        the absolute error ``|c - c_hat|`` of the red, green and blue channel, and the
        per-stimulus root mean square over the three channels. Full-scale units.
    n_stimuli
        Number of stimuli (patch x illuminant pairs) compared.
    """

    mean: NDArray[np.float64]
    max: NDArray[np.float64]
    p95: NDArray[np.float64]
    n_stimuli: int

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly ``{"n_stimuli": n, "Red": {"mean", "max", "p95"}, ...}``."""
        out: dict[str, Any] = {"n_stimuli": int(self.n_stimuli)}
        for i, row in enumerate(STAT_ROWS):
            out[row] = {
                "mean": float(self.mean[i]),
                "max": float(self.max[i]),
                "p95": float(self.p95[i]),
            }
        return out

    def format_table(self, title: str | None = None) -> str:
        """The statistics as a text table laid out like the paper's Table 1.

        Examples
        --------
        >>> import numpy as np
        >>> s = prediction_stats(np.zeros((2, 3)), np.full((2, 3), 0.001))
        >>> print(s.format_table())
        Channel     Mean   Maximum  95th pct.
        Red       0.0010    0.0010     0.0010
        Green     0.0010    0.0010     0.0010
        Blue      0.0010    0.0010     0.0010
        RGB       0.0010    0.0010     0.0010
        (2 stimuli)
        """
        lines = [] if title is None else [title]
        lines.append(f"{'Channel':<8}{'Mean':>8}{'Maximum':>10}{'95th pct.':>11}")
        for i, row in enumerate(STAT_ROWS):
            lines.append(
                f"{row:<8}{self.mean[i]:8.4f}{self.max[i]:10.4f}{self.p95[i]:11.4f}"
            )
        lines.append(f"({self.n_stimuli} stimuli)")
        return "\n".join(lines)


def prediction_stats(measured: ArrayLike, predicted: ArrayLike) -> PredictionStats:
    """Table 1 statistics of predicted vs. measured camera responses.

    Per channel ``k`` the error of a stimulus is ``|c_k - c_hat_k|``; the RGB error of a
    stimulus is the root mean square over its three channels,
    ``sqrt(mean_k (c_k - c_hat_k)**2)``. Each row reports the mean, the maximum and the
    95th percentile (linear interpolation between order statistics, numpy's default)
    over all stimuli.

    Parameters
    ----------
    measured, predicted : (..., 3)
        Responses in full-scale units, e.g. (n_stimuli, 3) or (n_p, n_i, 3); all
        leading axes are pooled.

    Returns
    -------
    PredictionStats

    Raises
    ------
    InputError
        If the shapes differ, the last axis is not 3, there are no stimuli, or a value
        is not finite.

    References
    ----------
    The paper, Table 1 (3080 stimuli: 140 patches x 22 LEDs).

    Examples
    --------
    >>> import numpy as np
    >>> s = prediction_stats([[0.5, 0.5, 0.5]], [[0.5, 0.5, 0.53]])
    >>> np.round(s.mean, 4)
    array([0.    , 0.    , 0.03  , 0.0173])
    """
    c = np.asarray(measured, dtype=np.float64)
    c_hat = np.asarray(predicted, dtype=np.float64)
    if c.shape != c_hat.shape or c.ndim < 1 or c.shape[-1] != 3:
        raise InputError(
            f"measured {c.shape} and predicted {c_hat.shape} responses must have the "
            "same shape (..., 3)"
        )
    c, c_hat = c.reshape(-1, 3), c_hat.reshape(-1, 3)
    if c.shape[0] == 0:
        raise InputError("no stimuli to compare")
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(c_hat))):
        raise InputError("responses contain NaN or infinite values")
    err = np.abs(c - c_hat)
    table = np.column_stack([err, np.sqrt(np.mean(err**2, axis=1))])
    return PredictionStats(
        mean=table.mean(axis=0),
        max=table.max(axis=0),
        p95=np.percentile(table, 95.0, axis=0),
        n_stimuli=int(table.shape[0]),
    )


def sensitivity_rms(
    estimated: ArrayLike | Spectra, reference: ArrayLike | Spectra
) -> float:
    """RMS difference of two sets of camera sensitivities after peak normalisation.

    Each channel (row) of each set is divided by its own maximum, so the absolute
    scale and the channel gains (white balance) drop out and only the shapes are
    compared; the RMS is then taken over all wavelengths and the three channels::

        sqrt(mean_{k, l} (s_k(l) / max s_k - t_k(l) / max t_k)**2)

    Parameters
    ----------
    estimated, reference : (3, n_wl) arrays or Spectra
        Sensitivities on the same grid.

    Returns
    -------
    float
        In units of the channel peak (0.01 = 1 % of the peak).

    References
    ----------
    Jiang et al., "What is the space of spectral sensitivity functions for digital
    color cameras?", WACV 2013 (sensitivities compared after peak normalisation).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.array([[0.0, 1.0, 0.0]] * 3)
    >>> round(sensitivity_rms(2 * t + [0.0, 0.0, 0.2], t), 4)
    0.0577
    """
    a = np.asarray(getattr(estimated, "values", estimated), dtype=np.float64)
    b = np.asarray(getattr(reference, "values", reference), dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2:
        raise InputError(f"sensitivity shapes differ: {a.shape} vs. {b.shape}")
    pa, pb = a.max(axis=1, keepdims=True), b.max(axis=1, keepdims=True)
    if not (np.all(pa > 0) and np.all(pb > 0)):
        raise InputError("a sensitivity curve has no positive value to normalise by")
    return float(np.sqrt(np.mean((a / pa - b / pb) ** 2)))


def split_patches(
    patches: Sequence[str], *, every: int = 5, offset: int = 4
) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Deterministic split of patches into fitting and held-aside ones.

    Every ``every``-th patch, starting at index ``offset``, is held aside (with the
    defaults: the 5th, 10th, ... patch, i.e. 28 of the 140 SG patches).

    Returns
    -------
    (fit, held_out)
        Patch names, each in the input order.

    Examples
    --------
    >>> split_patches(["a", "b", "c", "d"], every=2, offset=1)
    (('a', 'c'), ('b', 'd'))
    """
    if every < 2 or not 0 <= offset < every:
        raise InputError(f"bad split every={every}, offset={offset}")
    held = tuple(p for i, p in enumerate(patches) if i % every == offset)
    fit = tuple(p for i, p in enumerate(patches) if i % every != offset)
    return fit, held


@dataclass(frozen=True)
class CalibrationReport:
    """Prediction statistics of a sensitivity estimate on two sets of patches.

    Parameters
    ----------
    training
        Table 1 statistics on the patches the estimate was fitted to (all patches
        given, minus ``held_out_patches`` and the estimate's excluded patches).
    held_out
        The same on ``held_out_patches`` (``None`` if there were none).
    training_patches, held_out_patches
        The patch names in each set.
    """

    training: PredictionStats
    held_out: PredictionStats | None
    training_patches: tuple[str, ...]
    held_out_patches: tuple[str, ...]

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form."""
        return {
            "training": self.training.as_dict(),
            "held_out": None if self.held_out is None else self.held_out.as_dict(),
            "training_patches": list(self.training_patches),
            "held_out_patches": list(self.held_out_patches),
        }

    def format_text(self) -> str:
        """Both tables as text."""
        parts = [self.training.format_table("Fitted patches (Table 1)")]
        if self.held_out is not None:
            parts.append(self.held_out.format_table("Held-aside patches"))
        return "\n\n".join(parts)


def calibration_report(
    estimate: SensitivityEstimate,
    responses: Responses,
    illuminants: Spectra,
    reflectances: Spectra,
    *,
    held_out_patches: Sequence[str] = (),
) -> CalibrationReport:
    """Prediction statistics of ``estimate`` on fitted and on held-aside patches.

    For an out-of-sample check, fit the estimate without the held-aside patches
    (``responses.subset(fit_patches)``, e.g. from :func:`split_patches`) and pass the
    full responses here. Patches the estimate excluded (saturated) are left out of
    both sets. If the estimate fitted a spectroradiometer shift, the illuminants are
    corrected with it first (:meth:`SensitivityEstimate.correct_illuminants`).

    Parameters
    ----------
    estimate
        The sensitivity estimate to check.
    responses
        Measured responses, (n_p, n_i, 3).
    illuminants, reflectances : Spectra
        The illuminant spectra (named as ``responses.illuminants``) and patch
        reflectances (named as ``responses.patches``).
    held_out_patches
        Names of the patches that were not used in the fit.

    Returns
    -------
    CalibrationReport

    Raises
    ------
    InputError
        Unknown held-aside patch names, or the errors of :func:`predict_responses`.
    """
    unknown = [p for p in held_out_patches if p not in responses.patches]
    if unknown:
        raise InputError(f"held-aside patch(es) not in the responses: {unknown[:8]}")
    skip = set(estimate.excluded_patches)
    held = tuple(
        p for p in responses.patches if p in held_out_patches and p not in skip
    )
    train = tuple(
        p for p in responses.patches if p not in held_out_patches and p not in skip
    )

    corrected = estimate.correct_illuminants(illuminants)

    def stats(patches: tuple[str, ...]) -> PredictionStats:
        measured = estimate.linearise(responses.subset(list(patches)))
        predicted = predict_responses(
            estimate.sensitivity,
            corrected,
            reflectances,
            patches=patches,
            illuminant_names=measured.illuminants,
        )
        return prediction_stats(measured.rgb, predicted.rgb)

    if not train:
        raise InputError("no fitted patches left to report on")
    return CalibrationReport(
        training=stats(train),
        held_out=stats(held) if held else None,
        training_patches=train,
        held_out_patches=held,
    )
