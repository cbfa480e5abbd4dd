"""The calibration's self-check: do its residuals, corrections and readings hold up?

Table 1 of the paper is a fit to the calibration chart itself: a small error there
says the model can fit the chart, not that its numbers or their error bars are right.
Three checks look further, each against a model the numbers rest on:

1. **Residuals against the error model** (:func:`residual_chi_square`). Per channel
   ``chi2 = sum (c - c_hat)^2 / var`` over the chart's stimuli, divided by its degrees
   of freedom, with ``var`` the response variance the uncertainty budget states: the
   noise of the ROI mean, ``rgb_std^2 / n_pixels``, the flat-field residual and the
   systematic terms the calibration fitted to its residuals
   (:mod:`tunespec.core.excess`; without a fit the nominal
   ``(FLAT_FIELD_RESIDUAL * c)^2``). If the model is right the reduced value is 1
   with standard deviation ``sqrt(2 / dof)``; well above 1, something the model
   lacks (a wrong reading of the light, sensitivities too constrained to fit this
   camera) shows in the residuals, and the error bars built on that model are too
   narrow by about its square root. Against the ROI noise and the nominal flat field
   alone, a sensor with 0.2 % stray light and cross-talk and ``c^1.003`` (the
   generalisation benchmark's ``--systematic``) gave 22-58, a warning that the error
   bars were too narrow where they carry those terms and cover 95 %.
   **The systematic terms themselves** (:func:`systematic_warnings`): one fitted
   above :data:`SYSTEMATIC_LIMIT` (0.5 %; :data:`NONLINEARITY_LIMIT` for ``gamma``)
   is flagged by name. The error bars carry it, but the numbers are less precise
   than the instrument can give (a 1 % flat field: 0.08 -> 0.14 dE00).
2. **The light source's corrections** (:func:`led_correction_warnings`) and its
   **readings** (:func:`~tunespec.core.metering.reading_noise_fractions`). The
   self-calibration's per-LED gain and wavelength offset correct the light's
   metering; a gain far from 1 or an offset of several nm is no metering error a
   working spectroradiometer makes (the prior widths are 2 % and 1 nm,
   :mod:`tunespec.core.sensitivity_bayes`), but a wrong or swapped spectrum. A noise
   floor in the readings (:func:`tunespec.core.metering.reading_noise_rms`) enters
   Eq. 1 of the calibration and of every estimate.
3. **Patches left out** (:func:`hold_out_check`). The chart is calibrated again without
   every ``k``-th patch and the left-out patches' responses are predicted: Table 1's
   statistics out of sample, with their own chi-square (the calibration's own
   response covariance, :func:`tunespec.core.uncertainty.calibration_response_covariance`,
   added to the variance: a prediction carries it, a fit does not).

:func:`self_check` runs them all and returns a :class:`SelfCheck` whose
:attr:`~SelfCheck.warnings` are one line each, for the console, the GUI and the report.

The limits, on the simulated bench (``tunespec demo``, the bench whose truth is known
to be good): reduced chi-square against the fitted error model 1.11-1.17 per channel
on the fitted patches and 0.96-1.09 on the left-out ones (against the nominal 0.3 %
flat field, which is more than the bench has, it was 0.47-0.75 and 0.40-0.71 on seeds
0-3); per-LED gains within 0.970-1.020 and offsets within 0.6 nm; a reading noise of
at most 0.12 % of an LED's peak. A chi-square of :data:`CHI2_LIMIT` = 2 (residuals
1.4 times the model's, a 95 % interval that covers about 83 %) is well above the
bench's worst. An effect the fitted terms describe (1 % response noise that
``rgb_std`` does not know, a non-linearity ``c^1.02``, a 1 % flat field) leaves the
chi-square near 1 and is named by its term instead (see the tests).

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
``shared/reference``), Eq. 1 and Table 1. P. R. Bevington, D. K. Robinson, *Data
Reduction and Error Analysis for the Physical Sciences*, 3rd ed., McGraw-Hill (2003),
section 11.1 (reduced chi-square and its spread ``sqrt(2 / dof)``). T. Hastie,
R. Tibshirani, J. Friedman, *The Elements of Statistical Learning*, 2nd ed. (2009),
section 7.10 (cross-validation).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.calibration import predict_responses
from tunespec.core.errors import InputError
from tunespec.core.excess import ExcessVariance, flat_field_residual
from tunespec.core.metering import reading_noise_fractions
from tunespec.core.progress import ProgressFn, StopFn, check_stop, report
from tunespec.core.responses import CHANNELS, Responses
from tunespec.core.sensitivity import SensitivityEstimate
from tunespec.core.spectra import Spectra
from tunespec.core.stats import PredictionStats, prediction_stats, split_patches
from tunespec.core.uncertainty import calibration_response_covariance

__all__ = [
    "CHI2_LIMIT",
    "CHI2_SIGMAS",
    "GAIN_LIMIT",
    "HOLD_OUT_EVERY",
    "METER_NOISE_LIMIT",
    "NONLINEARITY_LIMIT",
    "SHIFT_LIMIT_NM",
    "SYSTEMATIC_LIMIT",
    "ChiSquare",
    "HeldOut",
    "SelfCheck",
    "finding_lines",
    "held_out_of",
    "hold_out_check",
    "led_correction_warnings",
    "residual_chi_square",
    "response_variance",
    "self_check",
    "systematic_warnings",
]


def finding_lines(warnings: Sequence[str]) -> tuple[str, ...]:
    """The self-check's warnings as the calibration's lists of warnings say them
    (the side file's ``warnings``, the wizard's, the report's): ``"self-check: ..."``."""
    return tuple(f"self-check: {w}" for w in warnings)


#: A reduced chi-square above this flags a channel (and above ``1 + CHI2_SIGMAS``
#: times its spread, which matters only for very few stimuli). The simulated bench
#: gives 0.96-1.17 (module docstring).
CHI2_LIMIT = 2.0
#: Standard deviations of the reduced chi-square above 1 that a flag needs at least.
CHI2_SIGMAS = 5.0
#: A per-LED gain further than this from 1 is flagged (5 times the prior width
#: :data:`~tunespec.core.sensitivity_bayes.SIGMA_GAIN` of a metering error).
GAIN_LIMIT = 0.10
#: A per-LED wavelength offset beyond this (nm) is flagged (twice the prior width
#: :data:`~tunespec.core.sensitivity_bayes.SIGMA_SHIFT_NM`, and the hierarchical
#: width's bound).
SHIFT_LIMIT_NM = 2.0
#: A correction is flagged only if it is also this many of its standard
#: uncertainties away from no correction (a poorly determined one is no finding).
CORRECTION_SIGMAS = 5.0
#: Reading noise as reported (:func:`tunespec.core.metering.reading_noise_fractions`,
#: fraction of the LED's peak) above which the light's readings are flagged: the
#: generalisation benchmark's instrument (0.1 % a reading, two averaged: 0.07 % on
#: the emission) shows 0.03-0.11 % per LED at a 1, 5 or 10 nm step, 0.3 % a reading
#: 0.13-0.50 %, which averaging two readings brings to 0.09-0.34 %; the cleaning is
#: validated up to 0.3 % (``docs/validation.md``).
METER_NOISE_LIMIT = 0.002
#: A fitted systematic error (:class:`~tunespec.core.excess.ExcessVariance`: the
#: flat field's residual, stray light, cross-talk, a relative error of each response
#: or of a whole patch) above this relative size is flagged: the simulated bench's
#: flat field of 0.3 % fits 0.28 %, and the generalisation benchmark's stray light and
#: cross-talk of 0.2 % fit 0.18-0.21 %; a 1 % flat field, which the error bars then
#: carry, doubles the benchmark's dE00 (0.08 -> 0.14, ``docs/validation.md``).
SYSTEMATIC_LIMIT = 0.005
#: A fitted non-linearity ``gamma`` (a response ``c^(1 + gamma)``) above this is
#: flagged (the benchmark's ``c^1.003`` fits 0.0024-0.0028; ``c^1.01`` fits 0.009).
NONLINEARITY_LIMIT = 0.005
#: What each systematic term is, and where to look when it is large.
_SYSTEMATIC_TERMS = {
    "flat_field_relative": (
        "flat-field residual",
        "shoot the white frames where the target sits, under the same light",
    ),
    "level_relative": ("stray light", "shield the chart from the light's glare"),
    "crosstalk_relative": (
        "cross-talk between channels",
        "check for flare and for a raw decoding that mixes channels",
    ),
    "response_relative": (
        "relative error of each response beyond its ROI noise",
        "check the light's stability and the exposures",
    ),
    "common_relative": (
        "relative error shared by all of a patch's responses",
        "check that the chart did not move between frames",
    ),
    "nonlinearity": (
        "non-linearity (response^(1 + gamma))",
        "check that the raw decoding is linear and its black level right",
    ),
}
#: The held-out check leaves out every this-many-th patch (28 of the SG's 140).
HOLD_OUT_EVERY = 5
#: Absolute floor of a response's standard deviation (full scale), only so that a
#: zero response without ROI statistics does not divide by zero: far below any
#: camera's noise, it changes no value the noise model gives (the calibration's
#: weights use 1e-4, which would double the variance of the dimmest responses).
_ABS_NOISE_FLOOR = 1e-6


# -- results ---------------------------------------------------------------------------
@dataclass(frozen=True)
class ChiSquare:
    """Reduced chi-square of response residuals per channel.

    Parameters
    ----------
    reduced : (3,)
        ``sum (c - c_hat)^2 / var`` over the stimuli, divided by :attr:`dof`, for
        R, G and B.
    dof
        Degrees of freedom per channel: the stimuli, less the parameters a fit spent
        on them.
    n_stimuli
        Stimuli (patch x illuminant pairs) per channel.
    worst_illuminant : (3,)
        Per channel the illuminant whose stimuli have the largest mean of
        ``(c - c_hat)^2 / var`` (where to look first), and that mean.
    """

    reduced: NDArray[np.float64]
    dof: int
    n_stimuli: int
    worst_illuminant: tuple[str, ...] = ()
    worst_value: tuple[float, ...] = ()

    @property
    def spread(self) -> float:
        """Standard deviation of a reduced chi-square with :attr:`dof` degrees of
        freedom, ``sqrt(2 / dof)``."""
        return float(np.sqrt(2.0 / self.dof))

    @property
    def limit(self) -> float:
        """The flag's limit: ``max(CHI2_LIMIT, 1 + CHI2_SIGMAS * spread)``."""
        return max(CHI2_LIMIT, 1.0 + CHI2_SIGMAS * self.spread)

    @property
    def flagged(self) -> tuple[str, ...]:
        """The channels over :attr:`limit`."""
        return tuple(
            c for c, v in zip(CHANNELS, self.reduced, strict=True) if v > self.limit
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form."""
        return {
            "reduced": {
                c: float(v) for c, v in zip(CHANNELS, self.reduced, strict=True)
            },
            "dof": int(self.dof),
            "n_stimuli": int(self.n_stimuli),
            "spread": self.spread,
            "limit": self.limit,
            "flagged": list(self.flagged),
            "worst_illuminant": {
                c: {"name": n, "value": float(v)}
                for c, n, v in zip(
                    CHANNELS, self.worst_illuminant, self.worst_value, strict=False
                )
            },
        }

    def format_values(self) -> str:
        """``R 0.64, G 0.46, B 0.63 (expected 1 +- 0.03)``."""
        values = ", ".join(
            f"{c} {v:.2f}" for c, v in zip(CHANNELS, self.reduced, strict=True)
        )
        return f"{values} (expected 1 +- {self.spread:.2f}, limit {self.limit:.2f})"


@dataclass(frozen=True)
class HeldOut:
    """The prediction of patches left out of a calibration (:func:`hold_out_check`).

    Parameters
    ----------
    every
        Every ``every``-th patch was left out.
    patches
        The left-out patches.
    prediction
        Table 1's statistics on them (:func:`~tunespec.core.stats.prediction_stats`).
    chi_square
        Their residuals against the noise model and the calibration's own response
        covariance (no degrees of freedom spent: they were not fitted).
    training
        Table 1 of the same calibration on the patches it was fitted to.
    """

    every: int
    patches: tuple[str, ...]
    prediction: PredictionStats
    chi_square: ChiSquare
    training: PredictionStats

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form."""
        return {
            "every": int(self.every),
            "patches": list(self.patches),
            "prediction": self.prediction.as_dict(),
            "training": self.training.as_dict(),
            "chi_square": self.chi_square.as_dict(),
        }


@dataclass(frozen=True)
class SelfCheck:
    """What :func:`self_check` found.

    Parameters
    ----------
    residuals
        Reduced chi-square of the fitted patches' residuals (:func:`residual_chi_square`).
    held_out
        The leave-patches-out prediction (``None``: not run).
    meter_noise
        Per illuminant the reading noise found, fraction of its peak
        (:func:`~tunespec.core.metering.reading_noise_fractions`; empty: no readings
        given).
    implausible_leds
        The LEDs whose fitted correction :func:`led_correction_warnings` flags.
    large_systematic
        The systematic terms the calibration fitted above their limits
        (:func:`systematic_warnings`).
    linearity_gamma
        The sensor's non-linearity the calibration undid in every response (0: none,
        :func:`~tunespec.core.excess.linearise`): said, not a finding by itself.
    warnings
        One line per finding; none means every check passed.
    """

    residuals: ChiSquare
    held_out: HeldOut | None = None
    meter_noise: Mapping[str, float] = field(default_factory=dict)
    implausible_leds: tuple[str, ...] = ()
    large_systematic: tuple[str, ...] = ()
    linearity_gamma: float = 0.0
    warnings: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        """Whether no check flagged anything."""
        return not self.warnings

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly form (``summary.json``, the stats JSON, the report)."""
        return {
            "passed": self.passed,
            "warnings": list(self.warnings),
            "residual_chi_square": self.residuals.as_dict(),
            "held_out": None if self.held_out is None else self.held_out.as_dict(),
            "meter_noise_fraction": {k: float(v) for k, v in self.meter_noise.items()},
            "implausible_leds": list(self.implausible_leds),
            "large_systematic_terms": list(self.large_systematic),
            "linearity_gamma": self.linearity_gamma,
            "limits": {
                "systematic_relative": SYSTEMATIC_LIMIT,
                "nonlinearity": NONLINEARITY_LIMIT,
                "chi_square": CHI2_LIMIT,
                "gain": GAIN_LIMIT,
                "shift_nm": SHIFT_LIMIT_NM,
                "meter_noise_fraction": METER_NOISE_LIMIT,
            },
        }

    def format_text(self) -> str:
        """The checks as text lines (the CLI prints them under Table 1)."""
        lines = ["Self-check:"]
        lines.append(
            "  residuals / error model, reduced chi-square: "
            + self.residuals.format_values()
        )
        if self.held_out is not None:
            h = self.held_out
            lines.append(
                f"  left out 1 in {h.every} patches ({len(h.patches)}): RGB mean "
                f"{h.prediction.mean[3]:.4f} max {h.prediction.max[3]:.4f} "
                f"(fitted {h.training.mean[3]:.4f} / {h.training.max[3]:.4f}); "
                f"chi-square {h.chi_square.format_values()}"
            )
        if self.linearity_gamma:
            lines.append(
                "  the sensor's non-linearity, undone in every response: "
                f"response^(1 + gamma), gamma {self.linearity_gamma:+.4f}"
            )
        if self.meter_noise:
            name, worst = max(self.meter_noise.items(), key=lambda kv: kv[1])
            lines.append(
                f"  light's reading noise: at most {100 * worst:.2f} % of the peak "
                f"({name}; limit {100 * METER_NOISE_LIMIT:.1f} %)"
            )
        lines.append(
            "  all checks passed"
            if self.passed
            else f"  {len(self.warnings)} finding(s), see the warnings"
        )
        return "\n".join(lines)


# -- the checks --------------------------------------------------------------------------
def response_variance(
    responses: Responses, excess: ExcessVariance | None = None
) -> NDArray[np.float64]:
    """The variance of each response the error model predicts, (n_p, n_i, 3).

    ``rgb_std^2 / n_pixels`` (the noise of the ROI mean; nothing without ROI
    statistics) plus the flat-field residual ``(f * rgb)^2`` plus ``1e-6^2`` (only so
    that nothing divides by zero); with a calibration's fitted ``excess``, ``f`` is
    its fitted flat field and its systematic terms' variance is added (the error
    model :mod:`tunespec.core.uncertainty` propagates), without one ``f`` is the
    nominal :data:`~tunespec.core.excess.FLAT_FIELD_RESIDUAL`.

    Examples
    --------
    >>> import numpy as np
    >>> r = Responses(("A1",), ("L1",), np.full((1, 1, 3), 0.5),
    ...               rgb_std=np.full((1, 1, 3), 0.01), n_pixels=np.full((1, 1), 100.0))
    >>> round(float(np.sqrt(response_variance(r)[0, 0, 0])), 5)  # sqrt(1e-6 + 2.25e-6)
    0.0018
    """
    rgb = np.asarray(responses.rgb, dtype=np.float64)
    var = (flat_field_residual(excess) * rgb) ** 2 + _ABS_NOISE_FLOOR**2
    if excess is not None:
        cov = excess.covariance(rgb.reshape(rgb.shape[0], -1))
        var = var + np.diagonal(cov, axis1=1, axis2=2).reshape(rgb.shape)
    if responses.rgb_std is not None:
        n_pix = (
            np.maximum(responses.n_pixels, 1.0)
            if responses.n_pixels is not None
            else np.ones(rgb.shape[:2])
        )
        var = var + responses.rgb_std**2 / n_pix[..., None]
    return var


def _chi_square(
    z2: NDArray[np.float64], illuminants: Sequence[str], spent: float
) -> ChiSquare:
    """:class:`ChiSquare` of normalised squared residuals ``z2`` (n_p, n_i, 3)."""
    n = int(z2.shape[0] * z2.shape[1])
    dof = max(round(n - spent), 1)
    per_led = z2.mean(axis=0)  # (n_i, 3)
    worst = per_led.argmax(axis=0)
    return ChiSquare(
        reduced=z2.sum(axis=(0, 1)) / dof,
        dof=dof,
        n_stimuli=n,
        worst_illuminant=tuple(illuminants[j] for j in worst),
        worst_value=tuple(float(per_led[j, k]) for k, j in enumerate(worst)),
    )


def residual_chi_square(
    estimate: SensitivityEstimate,
    responses: Responses,
    illuminants: Spectra,
    reflectances: Spectra,
    *,
    patches: Sequence[str] | None = None,
    fitted: bool = True,
) -> ChiSquare:
    """Reduced chi-square per channel of the residuals of Eq. 1's prediction.

    Parameters
    ----------
    estimate
        The calibration; its corrections are applied to ``illuminants``
        (:meth:`~tunespec.core.sensitivity.SensitivityEstimate.correct_illuminants`).
    responses
        The chart's responses, with ``rgb_std`` and ``n_pixels`` for the noise model.
    illuminants, reflectances
        On the calibration's grid, named as the responses.
    patches
        The patches to compare (default: all but the estimate's excluded ones).
    fitted
        The patches were fitted: ``dof`` is the stimuli less the parameters of a
        channel, its sensitivity samples and a third of the per-LED corrections (an
        upper bound of the effective parameters of a regularised fit, so the value is
        if anything too high). ``False``: predicted, nothing spent, and the
        calibration's response covariance (if it carries one) adds to the variance.

    Returns
    -------
    ChiSquare
    """
    if patches is None:
        skip = set(estimate.excluded_patches)
        patches = [p for p in responses.patches if p not in skip]
    patches = list(patches)
    if not patches:
        raise InputError("no patches to compare with the noise model")
    measured = estimate.linearise(responses.subset(patches))
    corrected = estimate.correct_illuminants(illuminants)
    predicted = predict_responses(
        estimate.sensitivity,
        corrected,
        reflectances,
        patches=tuple(patches),
        illuminant_names=measured.illuminants,
    )
    var = response_variance(measured, estimate.excess)
    spent = 0.0
    if fitted:
        n_corr = (
            0
            if estimate.led_correction is None
            else 2 * len(estimate.led_correction.names)
        )
        spent = estimate.sensitivity.wavelength_nm.size + n_corr / 3.0
    elif estimate.covariance is not None:
        cov = calibration_response_covariance(
            estimate,
            illuminants.select(list(measured.illuminants)),
            reflectances.select(patches),
        )
        var = var + np.diagonal(cov, axis1=1, axis2=2).reshape(var.shape)
    z2 = (measured.rgb - predicted.rgb) ** 2 / var
    return _chi_square(z2, measured.illuminants, spent)


def led_correction_warnings(estimate: SensitivityEstimate) -> tuple[str, ...]:
    """One line per LED whose fitted gain or wavelength offset is implausible.

    A gain further than :data:`GAIN_LIMIT` from 1, or an offset beyond
    :data:`SHIFT_LIMIT_NM`, and in either case :data:`CORRECTION_SIGMAS` of its
    standard uncertainty away from no correction. Nothing without a per-LED
    self-calibration.
    """
    corr = estimate.led_correction
    if corr is None:
        return ()
    n = len(corr.names)
    gain_std = corr.gain_std or (0.0,) * n
    shift_std = corr.shift_std_nm or (0.0,) * n
    out = []
    for j, name in enumerate(corr.names):
        g, s = corr.gain[j], corr.shift_nm[j]
        if abs(g - 1.0) > GAIN_LIMIT and abs(g - 1.0) > CORRECTION_SIGMAS * gain_std[j]:
            out.append(
                f"{name}: the calibration scaled its reported spectrum by {g:.3f} "
                f"(+- {gain_std[j]:.3f}); more than {100 * GAIN_LIMIT:.0f} % is no "
                "metering error: check that LED's spectrum and its exposure"
            )
        if abs(s) > SHIFT_LIMIT_NM and abs(s) > CORRECTION_SIGMAS * shift_std[j]:
            out.append(
                f"{name}: the calibration moved its reported spectrum by {s:+.1f} nm "
                f"(+- {shift_std[j]:.1f}); more than {SHIFT_LIMIT_NM:.0f} nm: check "
                "the spectroradiometer's wavelength scale and that LED's spectrum"
            )
    return tuple(out)


def systematic_warnings(estimate: SensitivityEstimate) -> dict[str, str]:
    """Per systematic term the calibration fitted above its limit
    (:data:`SYSTEMATIC_LIMIT`, :data:`NONLINEARITY_LIMIT`), one line: its size, that
    the error bars carry it, and where to look. Empty without a fit."""
    excess = estimate.excess
    if excess is None:
        return {}
    out = {}
    for key, (what, hint) in _SYSTEMATIC_TERMS.items():
        value = float(getattr(excess, key))
        gamma = key == "nonlinearity"
        # a non-linearity the calibration undid is flagged at the size it had
        undone = gamma and abs(excess.linearity_gamma) > value
        value = abs(excess.linearity_gamma) if undone else value
        limit = NONLINEARITY_LIMIT if gamma else SYSTEMATIC_LIMIT
        if value <= limit:
            continue
        size, cap = (
            (f"{value:.4f}", f"{limit}")
            if gamma
            else (f"{100 * value:.2f} %", f"{100 * limit:.1f} %")
        )
        carried = (
            "every response was linearised with it"
            if undone
            else "the error bars carry it"
        )
        out[what] = (
            f"the calibration's residuals show a {what} of {size} (limit {cap}): "
            f"{carried}, but the numbers are less precise than the instrument can "
            f"give; {hint}"
        )
    return out


def hold_out_check(
    responses: Responses,
    illuminants: Spectra,
    reflectances: Spectra,
    fit: Callable[[Responses], SensitivityEstimate],
    *,
    every: int = HOLD_OUT_EVERY,
) -> HeldOut:
    """Calibrate without every ``every``-th patch and predict those patches.

    Parameters
    ----------
    responses, illuminants, reflectances
        The chart, as the calibration got it (illuminants on its grid).
    fit
        Calibrates on the responses it is given, as the checked calibration was
        (same method and options).
    every
        Every ``every``-th patch, from the ``every``-th on, is left out
        (:func:`~tunespec.core.stats.split_patches`, as ``calibrate
        --hold-out-every``).

    Returns
    -------
    HeldOut
    """
    fit_names, held = split_patches(responses.patches, every=every, offset=every - 1)
    estimate = fit(responses.subset(list(fit_names)))
    return held_out_of(estimate, responses, illuminants, reflectances, held, every)


def held_out_of(
    estimate: SensitivityEstimate,
    responses: Responses,
    illuminants: Spectra,
    reflectances: Spectra,
    held: Sequence[str],
    every: int,
) -> HeldOut:
    """:class:`HeldOut` of a calibration fitted without the patches ``held``."""
    skip = set(estimate.excluded_patches)
    held = tuple(p for p in held if p not in skip)
    train = [p for p in responses.patches if p not in held and p not in skip]
    if not held:
        raise InputError("no left-out patches to predict (all saturated?)")
    corrected = estimate.correct_illuminants(illuminants)

    def stats(patches: Sequence[str]) -> PredictionStats:
        measured = estimate.linearise(responses.subset(list(patches)))
        predicted = predict_responses(
            estimate.sensitivity,
            corrected,
            reflectances,
            patches=tuple(patches),
            illuminant_names=measured.illuminants,
        )
        return prediction_stats(measured.rgb, predicted.rgb)

    return HeldOut(
        every=every,
        patches=held,
        prediction=stats(held),
        chi_square=residual_chi_square(
            estimate, responses, illuminants, reflectances, patches=held, fitted=False
        ),
        training=stats(train),
    )


def _chi_square_warning(chi: ChiSquare, what: str) -> list[str]:
    """One line if ``chi`` flags a channel, naming each flagged channel."""
    if not chi.flagged:
        return []
    k = [CHANNELS.index(c) for c in chi.flagged]
    values = ", ".join(f"{CHANNELS[i]} {chi.reduced[i]:.1f}" for i in k)
    worst = ", ".join(f"{CHANNELS[i]} {chi.worst_illuminant[i]}" for i in k)
    return [
        f"{what} residuals exceed the noise model: reduced chi-square {values} "
        f"(limit {chi.limit:.1f}; worst under {worst}): an effect the fitted error "
        "model lacks (a wrong LED spectrum, sensitivities too constrained to fit "
        "this camera, an error beyond the systematic terms), so the error bars are "
        "too narrow"
    ]


def self_check(
    estimate: SensitivityEstimate,
    responses: Responses,
    illuminants: Spectra,
    reflectances: Spectra,
    *,
    reported_illuminants: Spectra | None = None,
    fit: Callable[[Responses], SensitivityEstimate] | None = None,
    held_out: HeldOut | None = None,
    every: int = HOLD_OUT_EVERY,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> SelfCheck:
    """Every check of the module on one calibration.

    Parameters
    ----------
    estimate
        The calibration, fitted to ``responses``.
    responses, illuminants, reflectances
        The chart as the calibration got it (illuminants and reflectances on its
        grid).
    reported_illuminants
        The light's spectra as reported, at their own step, for the reading noise
        (default: ``illuminants``).
    fit
        Calibrates as ``estimate`` was (for the held-out check); ``None`` and no
        ``held_out``: the check is not run, and says so.
    held_out
        A held-out check already made (``calibrate --hold-out-every``: the
        calibration itself left patches out, :func:`held_out_of`).
    every
        The held-out check's patch spacing.

    Returns
    -------
    SelfCheck
    """
    check_stop(should_stop)
    warnings: list[str] = []
    residuals = residual_chi_square(estimate, responses, illuminants, reflectances)
    warnings += _chi_square_warning(residuals, "calibration")
    large = systematic_warnings(estimate)
    warnings += large.values()
    led_lines = led_correction_warnings(estimate)
    warnings += led_lines
    # as the light reported them, before their floor was cleaned, at their own
    # step (resampled, a spectrum's noise is averaged away)
    noise = reading_noise_fractions(
        illuminants if reported_illuminants is None else reported_illuminants
    )
    loud = {k: v for k, v in noise.items() if v > METER_NOISE_LIMIT}
    if loud:
        name, worst = max(loud.items(), key=lambda kv: kv[1])
        warnings.append(
            f"the light's readings carry noise of up to {100 * worst:.2f} % of the "
            f"peak ({name}; {len(loud)} of {len(noise)} spectra over "
            f"{100 * METER_NOISE_LIMIT:.1f} %): Eq. 1 uses them, so sensitivities and "
            "reflectances suffer; average repeated readings or check the instrument"
        )
    report(progress, 0.1)
    if held_out is None and fit is not None:
        check_stop(should_stop)
        held_out = hold_out_check(
            responses, illuminants, reflectances, fit, every=every
        )
    if held_out is not None:
        warnings += _chi_square_warning(
            held_out.chi_square, f"left-out patches' (1 in {held_out.every})"
        )
    report(progress, 1.0)
    return SelfCheck(
        residuals=residuals,
        held_out=held_out,
        meter_noise=noise,
        implausible_leds=tuple(dict.fromkeys(w.split(":")[0] for w in led_lines)),
        large_systematic=tuple(large),
        linearity_gamma=(
            0.0 if estimate.excess is None else estimate.excess.linearity_gamma
        ),
        warnings=tuple(warnings),
    )
