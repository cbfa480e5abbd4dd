"""Plausibility of inputs that parse: scale, units, coverage and cross-checks.

:mod:`tunespec.core.limits` refuses files that cannot be read; this module refuses
files that read well but cannot mean what they claim, before they become a confident
wrong number (issue 24). Each check looks at the whole of the data (a distribution,
never one maximum) or at two inputs against each other, and raises
:class:`Implausible` with one line: what is implausible, by how much, and what to do.
A command may let the user override a check (``--force``); the checks that name one
bad value in a file (a typo, mixed units) cannot be overridden: the file is wrong.

The checks and the quantities they rest on:

- **Units of a reflectance file** (:func:`reflectance_unit`): percent or factor 0..1,
  decided spectrum by spectrum (:func:`percent_spectra`: a single typo cannot
  change it); one value that breaks the unit found is refused with its line and
  column, percent spectra among factor ones too. (Factor spectra among percent ones
  read as blacks below 1 %, which charts have: the calibration's fit shows them.)
- **Wavelength coverage** (:func:`check_coverage`): Eq. 1 integrates over the
  visible range; a step needs its inputs to cover :data:`NEEDED_RANGE_NM`.
- **Calibration grid** (:func:`calibration_grid_warning`): coarser than
  :data:`~tunespec.core.spectra.CALIBRATION_MAX_STEP_NM` misplaces LED light (a
  warning: a coarse grid is a valid, faster choice).
- **Prior size** (:func:`check_prior_size`): the Wiener prior's covariance (Eq. 5)
  has rank ``n - 1``; reflectance spectra need about six dimensions.
- **Responses** (:func:`check_responses`): a mean response below a few noise
  standard deviations under zero, or a saturated share above
  :data:`MAX_SATURATED_SHARE`.
- **Expected signal** (:func:`check_signal_scale`): Eq. 1 with a perfect white
  bounds what any non-fluorescent patch can give; the brightest patch under each
  light must reach a plausible fraction of it (responses x100, illuminants x1e6,
  sensitivities on another scale are caught).
- **Relative sensitivities** (:func:`check_absolute_sensitivities`): a CSV whose
  peak is exactly 1 is normalised, not on the calibration's absolute scale.
- **Spectroradiometer shift** (:func:`check_spd_shift`): a few nm at most.
- **A noise level** (:func:`check_noise_std`): at most 5 % of full scale.
- **The sample's scale against the chart's** (:func:`check_white_scale`): the
  white background reflects the same in both sessions, so Eq. 1's prediction for it
  (:func:`white_reflectance`) must agree; the one check that tells a sample on
  another scale (exposure, ISO, aperture or illuminants' unit not as recorded) from
  a darker sample.
- **A chart's linearity** (:func:`check_chart_linearity`): a raw sensor bends its
  responses by far less than the largest bend a calibration undoes; a larger one is
  a tone curve (JPEG, a TIFF with gamma) or a black level not subtracted, whichever
  method fitted the chart.

References
----------
The paper (Eq. 1, 5-6); ArgyllCMS and i1Profiler refuse charts that do not match, as
this module refuses inputs that do not match each other.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError, shown_names
from tunespec.core.responses import Responses
from tunespec.core.spectra import Spectra

__all__ = [
    "BOARD_BEND_SIGNIFICANCE",
    "BOARD_CHANNEL_SHARE",
    "BRACKET_BEND_MAX",
    "FRACTION_PERCENTILE",
    "MAX_CHI2_PER_RESPONSE",
    "MAX_PLAUSIBLE_FRACTION",
    "MAX_SATURATED_SHARE",
    "MAX_SPD_SHIFT_NM",
    "MIN_PRIOR_SPECTRA",
    "MIN_SEEN_FRACTION",
    "MIN_WHITE_LEVEL",
    "NEEDED_RANGE_NM",
    "NEGATIVE_SIGMAS",
    "NO_BRACKETS_WARNING",
    "SIGNAL_RANGE",
    "WHITE_SCALE_TOLERANCE",
    "Checks",
    "Implausible",
    "board_bend",
    "board_bend_warning",
    "bracket_bend_warning",
    "calibration_fit_warning",
    "calibration_grid_warning",
    "check_absolute_sensitivities",
    "check_coverage",
    "check_estimate_inputs",
    "check_noise_std",
    "check_prior_size",
    "check_response_consistency",
    "check_responses",
    "check_signal_scale",
    "check_spd_shift",
    "check_white_scale",
    "inconsistent_patches",
    "percent_spectra",
    "reflectance_unit",
    "white_ratios",
    "white_reflectance",
    "white_response",
]

#: The wavelength range (nm) every step needs its spectral inputs to cover: Eq. 1
#: over the visible range, and CIE colorimetry (ASTM E308 accepts 400-700 nm).
NEEDED_RANGE_NM = (400.0, 700.0)
#: The percentile of a reflectance file's values its messages quote.
FRACTION_PERCENTILE = 90.0
#: A factor spectrum has its median below this; a percent one far above it.
PERCENT_BULK = 1.5
#: Largest reflectance factor of a non-fluorescent surface (a little above 1 for
#: measurement noise); above it a value is either fluorescence (a smooth band) or a
#: typo (a single spike).
MAX_PLAUSIBLE_FRACTION = 1.05
#: Largest fluorescent reflectance factor accepted (limits.MAX_REFLECTANCE says 3).
MAX_FLUORESCENT_FRACTION = 3.0
#: A value above :data:`MAX_PLAUSIBLE_FRACTION` that exceeds its spectral
#: neighbours' mean by this much (and by half of it) is a typo, not fluorescence.
SPIKE_FRACTION = 0.3
#: Largest response (full scale = 1, saturation): flat-fielding moves a response a
#: little above 1, nothing moves it above this.
MAX_RESPONSE = 1.5
#: Largest spectroradiometer wavelength shift (nm) a user may ask to undo.
MAX_SPD_SHIFT_NM = 5.0
#: Fewest prior spectra: reflectances have about six significant dimensions and the
#: covariance of ``n`` spectra has rank ``n - 1``.
MIN_PRIOR_SPECTRA = 6
#: A mean response below ``-NEGATIVE_SIGMAS`` per-pixel standard deviations (and
#: :data:`NEGATIVE_FLOOR`) cannot come from a dark-subtracted photo.
NEGATIVE_SIGMAS = 5.0
NEGATIVE_FLOOR = 0.002
#: Largest share of saturated patch/light pairs a step accepts.
MAX_SATURATED_SHARE = 0.2
#: The brightest patch's response under a light, as a fraction of what a perfect
#: white gives by Eq. 1 (median over the lights): below ``SIGNAL_RANGE[0]`` nothing
#: in the sample reflects more than 2 %, above ``SIGNAL_RANGE[1]`` the sample
#: reflects more than a white (a scale mistake in one of the three inputs). One
#: light off the others by more than :data:`SIGNAL_SPREAD` is named (the demo's
#: lights agree within 15 %). A scale mistake that makes the sample look darker,
#: but not below 2 %, cannot be told from a darker sample.
SIGNAL_RANGE = (0.02, 1.5)
SIGNAL_SPREAD = 2.0
#: Largest chi-square per response of a target's responses against Eq. 1
#: (``core.uncertainty.ReflectanceUncertainty.chi2_per_response``: ``y' C^-1 y`` over
#: the responses, ``y`` the responses less the prior mean's, ``C`` their whole
#: error model with the prior's reach fitted). Under the model it is about 1: on
#: ``benchmarks/generalisation.py``'s sessions (10-27 cameras of ten families, 318
#: targets each; CAL1 model or held-out LEDs, readings at 1, 5 or 10 nm with 0.1 or
#: 0.3 % noise, with and without the sensor effects) the median per camera was
#: 0.89-1.22 and the largest 6.3 (``benchmarks/eq1_consistency.py``). The demo's
#: responses with two neighbouring LEDs' spectra swapped gave 150-2400, with a dark
#: level of 0.05 % of full scale left in them 10-26 (1 %: 4500-8500). See
#: docs/validation.md.
MAX_CHI2_PER_RESPONSE = 10.0
#: Largest relative difference between the white background's reflectance by Eq. 1
#: in a sample session and in its chart's session (:func:`check_white_scale`): the
#: median over the lights, and each light's from that median. A third of a stop
#: (another exposure, ISO or aperture) is 26 %. On ``benchmarks/white_scale.py``
#: (36 sessions a pair, ten families, both light sources, 0.3 % reading noise at
#: 10 nm, the sensor's effects) the median was within 0.6 % of 1 and each light
#: within 5.3 % of it; with the light's metering errors drawn anew for the sample
#: (an instrument re-calibrated between the sessions) 1.4 % and 26 %.
WHITE_SCALE_TOLERANCE = 0.1
#: Least share of a light the camera sees (Eq. 1 for a perfect white over the
#: light's integral times the camera's peak sensitivity) for the light to count in
#: :func:`check_white_scale`: a reading noise of up to 0.3 % of the LED's peak is up
#: to :data:`WHITE_SCALE_TOLERANCE` of what the camera sees of a light it sees 3 % of.
#: (On ``benchmarks/white_scale.py`` the lights this leaves out are IR-cut cameras'
#: deep red ones; seen 0.00-0.2 %, their ratios between two sessions were 0.3-1.4.)
MIN_SEEN_FRACTION = 0.03
#: Least share of a light's brightest channel a channel of the white board needs to
#: count in :func:`board_bend_warning`: a channel that barely sees an LED sees its
#: tails, which a reading at 10 nm does not resolve.
BOARD_CHANNEL_SHARE = 0.1
#: How many standard errors from zero the board's bend must lie, besides being
#: :data:`~tunespec.core.excess.LINEARITY_GAMMA_MAX` or more, to be said: with the
#: camera's own curves its channels misfit Eq. 1 by 1-3 % through 10 nm readings,
#: as by a bend of up to 0.05 (``benchmarks/board_bend.py``).
BOARD_BEND_SIGNIFICANCE = 4.0
#: Largest bend (``c^(1 + gamma)``) that a gonio geometry's exposure brackets may
#: show once the calibration's non-linearity is undone
#: (:func:`bracket_bend_warning`): brackets a factor 8 apart then read 4 % off
#: their exposures and the shortest (1/64) merges 8 % off, more than a shutter's
#: or a light level's step should be. A tone curve ``c^(1/1.05)`` (a bend of
#: -0.048, at a chart's limit :data:`~tunespec.core.excess.LINEARITY_GAMMA_MAX`)
#: costs the simulated gonio session 4 dE00; its own brackets show -0.0005
#: (``benchmarks/bracket_bend.py``).
BRACKET_BEND_MAX = 0.02
#: Least level of the white board (its brightest channel, full scale) under a light
#: for the light to count in :func:`check_white_scale`: a dark level off by 0.01 %
#: of full scale is 1 % of it, and a failing LED (at 1e-5 of its power,
#: ``tests/app/test_warnings_progress.py``) lights it at the dark level alone.
MIN_WHITE_LEVEL = 0.01


class Implausible(InputError):
    """An input that parses but cannot be what it claims (exit 2).

    ``check`` names the check (``"signal"``, ``"coverage"``, ...), for the
    provenance of an override; the message ends with what to do.
    """

    def __init__(
        self,
        check: str,
        message: str,
        *,
        path: str | PathLike[str] | None = None,
        line: int | None = None,
    ) -> None:
        self.check = check
        super().__init__(message, path=path, line=line)


@dataclass
class Checks:
    """Run plausibility checks, honouring an override.

    ``force``: an :class:`Implausible` becomes a warning (``warn``) and is recorded
    in :attr:`overridden` (what the outputs' provenance lists); without it the
    first one is raised. The hint of a refusal names ``force_hint`` (the CLI flag or
    the config key).
    """

    force: bool = False
    warn: Callable[[str], None] | None = None
    force_hint: str = "--force"
    overridden: list[str] = field(default_factory=list)

    def __call__(
        self, check: Callable[..., object], *args: object, **kw: object
    ) -> None:
        try:
            check(*args, **kw)
        except Implausible as exc:
            if not self.force:
                raise Implausible(
                    exc.check,
                    f"{exc.message}; {self.force_hint} to accept",
                    path=exc.path,
                    line=exc.line,
                ) from None
            self.overridden.append(str(exc))
            if self.warn is not None:
                self.warn(f"accepted with {self.force_hint}: {exc}")


# -- the responses against Eq. 1, after the estimate ---------------------------------
def check_response_consistency(
    chi2_per_response: NDArray[np.float64],
    by_light: NDArray[np.float64],
    illuminants: Sequence[str],
) -> None:
    """Most targets' responses fit no reflectance through Eq. 1: a set-up mistake.

    ``chi2_per_response`` (n_p,): each target's chi-square per response against
    Eq. 1 (:data:`MAX_CHI2_PER_RESPONSE`); ``by_light`` (n_i,): the estimate's mean
    squared standardised residual under each light, to name where the misfit is. A
    few targets alone are :func:`inconsistent_patches`' (a fluorescent or glossy
    one).
    """
    c = np.asarray(chi2_per_response, dtype=np.float64)
    c = c[np.isfinite(c)]
    if c.size == 0:
        return
    median = float(np.median(c))
    if median <= MAX_CHI2_PER_RESPONSE:
        return
    order = np.argsort(np.asarray(by_light))[::-1]
    worst = ", ".join(str(illuminants[i]) for i in order[:2])
    raise Implausible(
        "consistency",
        f"the responses fit no reflectance through Eq. 1: median chi-square "
        f"{median:.3g} per response over {c.size} patch(es) (about 1 expected, "
        f"{MAX_CHI2_PER_RESPONSE:g} at most), worst under {worst}: responses not "
        "dark-subtracted, illuminants named after other lights than those that lit "
        "the responses (two swapped?), another session's spectra, or a fluorescent "
        "target (brighteners under the violet LEDs)",
    )


def inconsistent_patches(
    chi2_per_response: NDArray[np.float64], patches: Sequence[str]
) -> str:
    """A warning line naming the targets whose responses fit no reflectance
    through Eq. 1 (above :data:`MAX_CHI2_PER_RESPONSE`), else ``""``: their
    estimates and intervals do not hold."""
    c = np.asarray(chi2_per_response, dtype=np.float64)
    bad = np.flatnonzero(c > MAX_CHI2_PER_RESPONSE)
    if bad.size == 0:
        return ""
    names = shown_names([str(patches[i]) for i in bad], 10)
    return (
        f"{bad.size} patch(es) fit no reflectance through Eq. 1 (chi-square "
        f"{c[bad].min():.3g}-{c[bad].max():.3g} per response, about 1 expected): "
        f"{names} (fluorescent, glossy or off their place?): their estimates "
        "and intervals do not hold"
    )


# -- units of a reflectance file ---------------------------------------------------
def percent_spectra(
    values: NDArray[np.float64],
) -> tuple[bool, NDArray[np.bool_], NDArray[np.bool_]]:
    """Whether reflectance data are in percent, judged spectrum by spectrum.

    A spectrum whose median exceeds :data:`PERCENT_BULK` is percent (no factor
    spectrum has most of its values above 1.5); one whose largest value is at most
    :data:`MAX_PLAUSIBLE_FRACTION` fits factors (or a percent black below 1 %). The
    data are percent when the first outnumber the second: a single typed value
    moves neither count, and a chart's few blacks do not outvote its patches.

    Returns ``(percent, percent_like, factor_like)`` (the last two per spectrum).
    """
    v = np.atleast_2d(np.asarray(values, dtype=np.float64))
    percent_like = np.median(v, axis=1) > PERCENT_BULK
    factor_like = v.max(axis=1, initial=0.0) <= MAX_PLAUSIBLE_FRACTION
    percent = bool(percent_like.any()) and int(percent_like.sum()) >= int(
        factor_like.sum()
    )
    return percent, percent_like, factor_like


def reflectance_unit(
    values: NDArray[np.float64],
    names: Sequence[str],
    wavelength_nm: NDArray[np.float64],
    *,
    declared_percent: bool | None = None,
    source: str | None = None,
    locate: Callable[[int, int], tuple[int | None, int | None]] | None = None,
) -> float:
    """What a reflectance file's values are divided by: 100 (percent) or 1.

    The unit is decided spectrum by spectrum (:func:`percent_spectra`), or taken
    from the file (``declared_percent``: CGATS ``SPEC_nnn`` fields are percent) and
    checked against the values.

    Raises
    ------
    InputError
        A value that breaks the unit (a spike above :data:`MAX_PLAUSIBLE_FRACTION`,
        or above :data:`MAX_FLUORESCENT_FRACTION`), named by line and column when
        ``locate(spectrum, wavelength_index)`` can say; spectra in percent among
        more in factors (mixed units); a declared unit the values contradict.
    """
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return 1.0
    percent, percent_like, factor_like = percent_spectra(v)
    bulk = float(np.percentile(v, FRACTION_PERCENTILE))
    if declared_percent:
        if bool(factor_like.all()):
            raise InputError(
                "spectral fields in percent by the format, but every value is at "
                f"most {float(v.max()):.3g} (below {100 * MAX_PLAUSIBLE_FRACTION / 100:g} "
                "%, darker than any black): factors 0..1 written as percent? write "
                "them x100",
                path=source,
            )
        percent = True
    elif percent_like.any() and not percent:
        bad = [names[k] for k in np.flatnonzero(percent_like)]
        raise InputError(
            f"mixed units: {len(bad)} spectrum(s) ({shown_names(bad, 5)}) look like "
            "percent (median above "
            f"{PERCENT_BULK:g}) among {int(factor_like.sum())} in factors 0..1 (at "
            f"most {MAX_PLAUSIBLE_FRACTION:g}); write every spectrum in one unit",
            path=source,
        )
    scale = 100.0 if percent else 1.0
    f = v / scale
    if float(np.median(f)) <= MAX_PLAUSIBLE_FRACTION:  # else all out of range
        _check_spikes(f, names, wavelength_nm, percent, bulk, source, locate)
    return scale


def _check_spikes(
    f: NDArray[np.float64],
    names: Sequence[str],
    wavelength_nm: NDArray[np.float64],
    percent: bool,
    bulk: float,
    source: str | None,
    locate: Callable[[int, int], tuple[int | None, int | None]] | None,
) -> None:
    """A value above a plausible reflectance that is a lone spike (or beyond
    fluorescence): a typo."""
    high = f > MAX_PLAUSIBLE_FRACTION
    if not np.any(high):
        return
    # the mean of the spectral neighbours (the one neighbour at either end)
    nb = np.empty_like(f)
    if f.shape[1] > 2:
        nb[:, 1:-1] = 0.5 * (f[:, :-2] + f[:, 2:])
    nb[:, 0] = f[:, min(1, f.shape[1] - 1)]
    nb[:, -1] = f[:, max(f.shape[1] - 2, 0)]
    # a spike: well above both neighbours (fluorescence is a band, not one sample)
    spike = high & (f - nb > np.maximum(SPIKE_FRACTION, 0.5 * nb))
    bad = spike | (f > MAX_FLUORESCENT_FRACTION)
    if not np.any(bad):
        return  # a smooth band above 1: fluorescence
    k, j = (int(x) for x in np.argwhere(bad)[0])
    shown = f[k, j] * (100.0 if percent else 1.0)
    unit = (
        f"percent (0..{100 * MAX_PLAUSIBLE_FRACTION:g})"
        if percent
        else f"fractions (0..{MAX_PLAUSIBLE_FRACTION:g})"
    )
    line, column = (None, None)
    if locate is not None:
        line, column = locate(k, j)
    where = f"column {column}: " if column else ""
    more = int(np.sum(bad)) - 1
    raise InputError(
        f"{shown:.4g} in a file of {unit}: a typo? ({where}{names[k]} at "
        f"{wavelength_nm[j]:g} nm; 90 % of the values are at most {bulk:.3g}"
        f"{f'; {more} more such value(s)' if more else ''})",
        path=source,
        line=line,
    )


# -- coverage, grids, sizes --------------------------------------------------------
def check_coverage(
    inputs: Sequence[tuple[str, NDArray[np.float64]]],
    step: str,
    needed_nm: tuple[float, float] = NEEDED_RANGE_NM,
    *,
    grid_nm: NDArray[np.float64] | None = None,
) -> None:
    """Every input (a label and its wavelengths) covers ``needed_nm``, and so does
    the working grid when given (``--grid`` narrower than the data)."""
    lo, hi = needed_nm
    for label, wl in inputs:
        if wl.size and (wl[0] > lo + 1e-6 or wl[-1] < hi - 1e-6):
            raise Implausible(
                "coverage",
                f"{label} covers {wl[0]:g}-{wl[-1]:g} nm; {step} needs at least "
                f"{lo:g}-{hi:g} nm (Eq. 1 over the visible range): give data over the "
                "whole range",
            )
    if (
        grid_nm is not None
        and grid_nm.size
        and (grid_nm[0] > lo + 1e-6 or grid_nm[-1] < hi - 1e-6)
    ):
        raise Implausible(
            "coverage",
            f"--grid {grid_nm[0]:g}-{grid_nm[-1]:g} nm; {step} needs at least "
            f"{lo:g}-{hi:g} nm: widen --grid",
        )


def calibration_grid_warning(step_nm: float, max_step_nm: float) -> str:
    """A warning line for a calibration grid coarser than ``max_step_nm`` (given
    with ``--grid``), else ``""``. A warning, not a refusal: a coarse grid is a
    valid (faster) choice with a known cost."""
    if step_nm <= max_step_nm + 1e-9:
        return ""
    return (
        f"--grid step {step_nm:g} nm is {step_nm / max_step_nm:.3g}x coarser than "
        f"calibration needs (at most {max_step_nm:g} nm: coarser steps misplace "
        "light inside each LED's band and Table 1 gets several times worse); give a "
        f"{max_step_nm:g} nm step or leave --grid out"
    )


def check_prior_size(n_spectra: int, path: object = None) -> None:
    """Enough prior spectra for a covariance of reflectance's dimensions."""
    if n_spectra < MIN_PRIOR_SPECTRA:
        raise Implausible(
            "prior",
            f"--prior has {n_spectra} spectra; its covariance (Eq. 5) needs at least "
            f"{MIN_PRIOR_SPECTRA} (reflectances have about six dimensions, and "
            f"{n_spectra} spectra span {max(n_spectra - 1, 0)}): give a larger prior "
            "or leave --prior out (the ColorChecker SG)",
            path=None if path is None else str(path),
        )


#: Largest ``--noise-std`` (full scale) a measurement's noise can be: above it the
#: Wiener estimate (Eq. 5) is the prior's mean whatever was measured.
MAX_NOISE_STD = 0.05


def check_noise_std(
    noise_std: float | None, rgb_std: NDArray[np.float64] | None
) -> None:
    """``--noise-std`` within what a camera's responses carry: at most
    :data:`MAX_NOISE_STD` of full scale."""
    if noise_std is None or noise_std <= MAX_NOISE_STD:
        return
    own = ""
    if rgb_std is not None and rgb_std.size:
        own = (
            f"; the responses' own standard deviations: median {np.median(rgb_std):.2g}"
        )
    raise Implausible(
        "noise",
        f"--noise-std {noise_std:g} is {noise_std:.0%} of full scale (at most "
        f"{MAX_NOISE_STD:g} accepted{own}): the estimate would be the prior's mean "
        "whatever was measured; give the level in units of full scale, or leave it out",
    )


def check_spd_shift(shift_nm: float | None) -> None:
    """``--spd-shift-nm`` within what a spectroradiometer gets wrong."""
    if shift_nm is not None and abs(shift_nm) > MAX_SPD_SHIFT_NM:
        raise Implausible(
            "spd_shift",
            f"--spd-shift-nm {shift_nm:g}: a spectroradiometer's wavelength error is "
            f"a few nm (at most {MAX_SPD_SHIFT_NM:g} accepted); give the shift in nm "
            "or leave it out (calibrate fits it)",
        )


def check_calibration_grid(
    sensitivity_nm: NDArray[np.float64], meta: Mapping[str, Any]
) -> None:
    """Sensitivities on the wavelengths their calibration's covariance and LED
    corrections were fitted on (``meta``: the side file's dict as
    ``core.io.export.read_sensitivity_meta`` gives it; nothing to check without a
    covariance).

    Resampled curves lose what the estimate needs, and the covariance resampled
    after them misstates its error: the demo's rawtoaces JSON (5 nm, of a 2 nm
    calibration) gave 0.090 instead of 0.048 mean CIEDE2000 and 95 % intervals
    covering 0.83 of the reflectance samples instead of 0.97. A side file with the
    curves (``core.io.export.curves_document``) gives them back before this check.
    """
    if "covariance_wavelength_nm" not in meta:
        return
    a = np.asarray(sensitivity_nm, dtype=np.float64)
    b = np.asarray(meta["covariance_wavelength_nm"], dtype=np.float64)
    if a.shape == b.shape and np.allclose(a, b):
        return
    raise Implausible(
        "calibration_grid",
        f"sensitivities at {_span(a)}, their calibration's covariance and LED "
        f"corrections at {_span(b)}: resampled curves give worse reflectances and "
        "intervals that miss (demo: 0.048 -> 0.090 dE00, coverage 0.97 -> 0.83); give "
        "the sensitivities CSV that 'tunespec calibrate' wrote, or export again (the "
        "side file then carries the curves)",
        path=meta.get("meta_path"),
    )


def _span(wavelength_nm: NDArray[np.float64]) -> str:
    wl = wavelength_nm
    step = f":{wl[1] - wl[0]:g}" if wl.size > 1 else ""
    return f"{wl[0]:g}:{wl[-1]:g}{step} nm"


def check_responses(
    rgb: NDArray[np.float64],
    patches: Sequence[str],
    illuminants: Sequence[str],
    *,
    rgb_std: NDArray[np.float64] | None = None,
    saturated: NDArray[np.float64] | None = None,
    path: object = None,
) -> None:
    """Responses a dark-subtracted photo can give: no mean far below zero, none
    above :data:`MAX_RESPONSE` (full scale is 1), and not mostly saturated."""
    where = None if path is None else str(path)
    sigma = np.zeros_like(rgb) if rgb_std is None else np.nan_to_num(rgb_std)
    floor = -(NEGATIVE_SIGMAS * sigma + NEGATIVE_FLOOR)
    low = rgb < floor
    if np.any(low):
        p, i, c = (int(x) for x in np.argwhere(low)[0])
        raise Implausible(
            "negative",
            f"patch {patches[p]} under {illuminants[i]}: response "
            f"{rgb[p, i, c]:.4g} ({'RGB'[c]}) is {NEGATIVE_SIGMAS:g} noise standard "
            f"deviations below zero, which a dark-subtracted photo cannot give "
            f"({int(np.sum(low))} such value(s)); check the responses file",
            path=where,
        )
    high = rgb > MAX_RESPONSE
    if np.any(high):
        p, i, c = (int(x) for x in np.argwhere(high)[0])
        raise Implausible(
            "full_scale",
            f"patch {patches[p]} under {illuminants[i]}: response "
            f"{rgb[p, i, c]:.4g} ({'RGB'[c]}) is above full scale (1 = saturation; "
            f"{int(np.sum(high))} such value(s)): responses are in units of full "
            "scale; check the responses file (a typo? percent or counts?)",
            path=where,
        )
    if saturated is not None and saturated.size:
        share = float(np.mean(saturated > 0))
        if share > MAX_SATURATED_SHARE:
            raise Implausible(
                "saturated",
                f"{share:.0%} of the patch/light pairs are saturated (at most "
                f"{MAX_SATURATED_SHARE:.0%} accepted): the responses carry no "
                "measurement there; capture again with shorter exposures",
                path=where,
            )


def check_signal_scale(
    rgb: NDArray[np.float64],
    white: NDArray[np.float64],
    illuminants: Sequence[str],
    *,
    labels: str = "--responses, --illuminants and --sensitivities",
) -> float:
    """The responses against Eq. 1's prediction for a perfect white.

    ``rgb`` (n_p, n_i, 3); ``white`` (n_i, 3) = Eq. 1 with reflectance 1. Under each
    light the channel with the most signal is compared: the brightest patch's
    response over the white's. Returns the median ratio over the lights.
    """
    dominant = np.argmax(white, axis=1)
    idx = np.arange(white.shape[0])
    w = white[idx, dominant]
    usable = w > 1e-3 * float(np.max(w, initial=0.0))
    if not np.any(usable):
        raise Implausible(
            "signal",
            f"Eq. 1 predicts no signal from {labels} (sensitivities and illuminants "
            "do not overlap)",
        )
    brightest = np.max(rgb[:, idx, dominant], axis=0)
    ratio = brightest[usable] / w[usable]
    names = [n for n, u in zip(illuminants, usable, strict=True) if u]
    median = float(np.median(ratio))
    lo, hi = SIGNAL_RANGE
    if not lo <= median <= hi:
        factor = median if median > hi else 1.0 / max(median, 1e-300)
        side = "more" if median > hi else "less"
        raise Implausible(
            "signal",
            f"the responses are {median:.3g}x what a perfect white gives by Eq. 1 "
            f"(brightest patch, median over {len(ratio)} lights; plausible "
            f"{lo:g}-{hi:g}): about {factor:.3g}x {side} signal than {labels} "
            "predict; one of them is on another scale (x100? relative "
            "sensitivities? another exposure?)",
        )
    off = (ratio > median * SIGNAL_SPREAD) | (ratio < median / SIGNAL_SPREAD)
    if np.any(off):
        k = int(np.argmax(np.abs(np.log(ratio / median))))
        n_off = int(np.sum(off))
        cause = (
            "its spectrum in --illuminants is on another scale, or its responses are "
            "not its own"
            if n_off < 3
            else "the lights of --illuminants, the responses' lights or the "
            "sensitivities' channels do not match each other (another order?)"
        )
        raise Implausible(
            "signal",
            f"light {names[k]}: its responses are {ratio[k] / median:.3g}x those the "
            f"other lights' give against Eq. 1 ({n_off} light(s) off by more than "
            f"{SIGNAL_SPREAD:g}x): {cause}",
        )
    return median


def check_absolute_sensitivities(values: NDArray[np.float64], path: object) -> None:
    """Sensitivities whose peak is exactly 1 are normalised (relative units)."""
    peak = float(np.max(values, initial=0.0))
    if abs(peak - 1.0) < 1e-9:
        raise Implausible(
            "relative",
            "sensitivities normalised to peak 1 (relative units): Eq. 1 needs the "
            "calibration's absolute scale; give the sensitivities CSV that "
            "'tunespec calibrate' wrote",
            path=str(path),
        )


def white_response(illuminants: Spectra, sensitivity: Spectra) -> NDArray[np.float64]:
    """Eq. 1 for a perfect white (reflectance 1) under each light, (n_i, 3).

    ``illuminants`` and ``sensitivity`` on one grid (as
    :func:`tunespec.core.wiener.on_integration_grid` gives them)."""
    from tunespec.core.forward_model import render_rgb

    ones = np.ones((1, illuminants.wavelength_nm.size))
    return render_rgb(
        ones, illuminants.values, sensitivity.values, illuminants.step_nm
    )[0]


def white_reflectance(
    white_rgb: NDArray[np.float64], illuminants: Spectra, sensitivity: Spectra
) -> NDArray[np.float64]:
    """The white background's reflectance under each light by Eq. 1, (n_i,): its
    level (``Responses.white_rgb``, Eq. 2's mean ``A_B``) over a perfect white's
    (:func:`white_response`), summed over the channels. NaN under a light the camera
    sees less than :data:`MIN_SEEN_FRACTION` of (a deep red LED through an IR-cut
    filter: the light's reading noise decides the ratio there), or that lit the
    board below :data:`MIN_WHITE_LEVEL` (an LED too weak for its exposure: the dark
    level's error and the reading's noise decide it).

    ``illuminants`` (named as the white's lights) and ``sensitivity`` on one grid."""
    white = np.asarray(white_rgb, dtype=np.float64)
    level = np.sum(white, axis=1)
    perfect = np.sum(white_response(illuminants, sensitivity), axis=1)
    # what the camera sees of each light against all of it at its most sensitive
    light = np.sum(illuminants.values, axis=1) * illuminants.step_nm
    peak = float(np.max(np.sum(sensitivity.values, axis=0), initial=0.0))
    seen = perfect / np.maximum(light * peak, 1e-300)
    lit = np.max(white, axis=1) >= MIN_WHITE_LEVEL
    usable = (seen >= MIN_SEEN_FRACTION) & (perfect > 0) & lit & (level > 0)
    return np.where(usable, level / np.where(usable, perfect, 1.0), np.nan)


def board_bend(
    white_rgb: NDArray[np.float64], perfect: NDArray[np.float64]
) -> tuple[float, float]:
    """The bend of the white board's channels and its standard error
    (:func:`~tunespec.core.excess.fit_board_bend` over the channels at
    :data:`MIN_WHITE_LEVEL` and :data:`BOARD_CHANNEL_SHARE` of their light's
    brightest or more)."""
    from tunespec.core.excess import fit_board_bend

    white = np.asarray(white_rgb, dtype=np.float64)
    brightest = np.max(white, axis=1, keepdims=True)
    usable = (white >= MIN_WHITE_LEVEL) & (white >= BOARD_CHANNEL_SHARE * brightest)
    return fit_board_bend(white, np.asarray(perfect, dtype=np.float64), usable)


def board_bend_warning(
    white_rgb: NDArray[np.float64], perfect: NDArray[np.float64]
) -> str | None:
    """What the white board's channels say of the sample's linearity, or None.

    ``white_rgb`` (n_i, 3): the board's level under each light (linear, as the
    estimate's responses); ``perfect``: :func:`white_response` there. A bend
    (:func:`board_bend`) a chart would be refused for
    (:func:`~tunespec.core.excess.bend_verdict`), at
    :data:`BOARD_BEND_SIGNIFICANCE` standard errors, is a tone curve on the sample's
    frames or sensitivities that do not fit this camera. Said where no covariance
    lets Eq. 1 check the targets themselves (:func:`check_response_consistency`:
    external curves, ``pca``, ``smooth``) and for every per-pixel image.
    """
    from tunespec.core.excess import LINEARITY_GAMMA_MAX, bend_verdict

    gamma, se = board_bend(white_rgb, perfect)
    if bend_verdict(gamma, se, BOARD_BEND_SIGNIFICANCE) != "refuse":
        return None
    return (
        f"the white background's channels bend as response^(1 + gamma) with gamma "
        f"{gamma:+.3f} +- {se:.2g} against Eq. 1 (a raw sensor's: within "
        f"+-{LINEARITY_GAMMA_MAX:g}): frames on a tone curve (a JPEG, a TIFF with "
        "gamma), a black level not subtracted, or sensitivities that do not fit this "
        "camera; its reflectances do not hold"
    )


def bracket_bend_warning(gamma: float, se: float) -> str | None:
    """What exposure brackets of one scene say of the frames' linearity, or None.

    ``gamma`` +- ``se``: the bend :func:`~tunespec.core.hdr.fit_bracket_bend` finds
    in brackets from which the calibration's own non-linearity was undone. One
    :func:`~tunespec.core.excess.bend_verdict` refuses with the limit
    :data:`BRACKET_BEND_MAX` means the brackets do not scale with their exposures,
    which the HDR merge and Eq. 1 assume: a tone curve, a black level not
    subtracted, exposures not as recorded.
    """
    from tunespec.core.excess import bend_verdict

    if bend_verdict(gamma, se, limit=BRACKET_BEND_MAX) != "refuse":
        return None
    return (
        f"its exposure brackets bend as response^(1 + gamma) with gamma "
        f"{gamma:+.3f} +- {se:.2g} (linearised raw frames: within "
        f"+-{BRACKET_BEND_MAX:g}): frames on a tone curve (a JPEG, a TIFF with "
        "gamma), a black level not subtracted, or bracket exposures not as "
        "recorded; its merged responses and the spectra from them do not hold"
    )


#: A gonio session whose plan has no HDR geometry: nothing checks its frames.
NO_BRACKETS_WARNING = (
    "no geometry of the plan has HDR brackets, so the frames' linearity is not "
    "checked (a tone curve or a black level not subtracted would pass unseen): "
    "give one geometry hdr: true"
)


def white_ratios(
    sample: Mapping[str, float], chart: Mapping[str, float]
) -> dict[str, float]:
    """The sample's white background over the chart's, per light both have
    (finite, positive ones): what :func:`check_white_scale` judges."""
    ratios = {n: sample[n] / chart[n] for n in sample if n in chart}
    return {n: r for n, r in ratios.items() if np.isfinite(r) and r > 0}


def check_white_scale(sample: Mapping[str, float], chart: Mapping[str, float]) -> float:
    """The white background's reflectance by Eq. 1 in a sample session against
    its chart session's (light -> :func:`white_reflectance`), over the lights both
    have. The responses of both are flat-fielded to their white (Eq. 2), so a
    sample whose responses or illuminants are on another scale than the chart's
    shows here, where a darker sample does not. Returns the median ratio (NaN
    when no light is shared)."""
    ratios = white_ratios(sample, chart)
    names = list(ratios)
    ratio = np.array(list(ratios.values()), dtype=np.float64)
    if ratio.size == 0:
        return float("nan")
    median = float(np.median(ratio))
    tol = WHITE_SCALE_TOLERANCE
    if abs(median - 1.0) > tol:
        raise Implausible(
            "white",
            f"the sample's white background reflects {median:.3g}x what it "
            f"reflected at calibration by Eq. 1 (median over {ratio.size} lights; "
            f"1 +- {tol:g} expected): the responses or the illuminants are on "
            "another scale than the chart session's (exposure, ISO or aperture "
            "not as recorded, illuminants in another unit, the light or the camera "
            "moved, another white background); its reflectances would come out "
            f"{median:.3g}x",
        )
    off = np.abs(ratio / median - 1.0) > tol
    if np.any(off):
        k = int(np.argmax(np.abs(np.log(ratio / median))))
        raise Implausible(
            "white",
            f"light {names[k]}: the sample's white background by Eq. 1, against "
            f"calibration, is {ratio[k] / median:.3g}x the other lights' "
            f"({int(off.sum())} light(s) off by more than "
            f"{tol:.0%}): its exposure or its spectrum in the illuminants is not "
            "the one that lit it, or the spectroradiometer's error for it changed "
            "since the calibration (calibrate again)",
        )
    return median


def check_estimate_inputs(
    checks: Checks,
    responses: Responses,
    illuminants: Spectra,
    sensitivity: Spectra,
    *,
    responses_path: object = None,
) -> None:
    """The checks of a reflectance estimate (Eq. 5-6) on its inputs: responses
    (:func:`check_responses`) and their scale against Eq. 1
    (:func:`check_signal_scale`). ``illuminants`` (named as the responses'
    lights) and ``sensitivity`` on one grid."""
    lights = illuminants.select(list(responses.illuminants))
    # the scale first: its message says by how much
    checks(
        check_signal_scale,
        responses.rgb,
        white_response(lights, sensitivity),
        responses.illuminants,
    )
    checks(
        check_responses,
        responses.rgb,
        responses.patches,
        responses.illuminants,
        rgb_std=responses.rgb_std,
        saturated=responses.saturated,
        path=responses_path,
    )


def check_chart_linearity(params: Mapping[str, Any]) -> None:
    """The chart's responses bend no more than a raw sensor's.

    ``params``: the calibration's (``Calibration.params``), with the bend
    ``c = x^(1 + gamma)`` its residuals showed (``linearity_gamma_found`` and
    ``linearity_gamma_se``; no check without them). A bend of
    :data:`~tunespec.core.excess.LINEARITY_GAMMA_MAX` or more, at least
    :data:`~tunespec.core.excess.LINEARITY_SIGNIFICANCE` standard errors from zero, is
    not undone: on the simulated chart an sRGB-like gamma 1/2.2 shows -0.68, 1/1.2
    -0.15 and x^1.1 0.09, a dark level of 0.5 % / 1 % of full scale left in -0.18 /
    -0.28 (``tests/test_mistakes_corpus.py``), where the benchmark's non-linear
    sensor (``signal^1.003``) shows 0.0023-0.0032 on all its 89 cameras
    (``docs/validation.md``) and a black level subtracted 0.3 %
    of full scale too much 0.049 (undone, with the self-check's warning).
    ``"pca"`` and ``"smooth"`` (:func:`~tunespec.core.excess.fit_bend`) on the same
    89 cameras and both lights: none refused (``smooth`` -0.014 to +0.005); their
    chart on ``c^(1/1.2)`` or ``c^1.1``: ``smooth`` refused on all 178, ``pca`` on
    153 and 126, where its misfit on a camera it does not know leaves the bend seen.
    """
    from tunespec.core.excess import LINEARITY_GAMMA_MAX, bend_verdict

    gamma = params.get("linearity_gamma_found")
    se = params.get("linearity_gamma_se")
    if gamma is None or se is None or bend_verdict(gamma, se) != "refuse":
        return
    raise Implausible(
        "linearity",
        f"the chart's responses bend as response^(1 + gamma) with gamma {gamma:+.3f} "
        f"+- {se:.2g} against Eq. 1 (a raw sensor's: within +-{LINEARITY_GAMMA_MAX:g}): "
        "a tone curve (a JPEG, a TIFF with gamma or another camera profile), a "
        "black level not subtracted, or reflectances that are not this chart's "
        "patches; extract the patches from raw or linear files and check "
        "--reflectances",
    )


def calibration_notes(meta: Mapping[str, Any], path: object) -> list[str]:
    """Warning lines, for an estimate, of what the calibration ``path`` (None: one
    in memory) found about itself (its side file's ``forced`` and ``warnings``,
    :data:`~tunespec.core.io.export.NOTE_KEYS`): its estimates inherit them."""
    lines = []
    name = "the calibration" if path is None else f"the calibration {path}"
    for key, what in (("forced", "was accepted with --force"), ("warnings", "warned")):
        notes = meta.get(key) or []
        if notes:
            more = f" (and {len(notes) - 1} more)" if len(notes) > 1 else ""
            lines.append(f"{name} {what}: {notes[0]}{more}")
    return lines


#: Table 1's mean RGB RMS over the mean response above which a calibration's fit is
#: suspect (the demo: 0.2 %).
MAX_FIT_RMS_SHARE = 0.05


def calibration_fit_warning(rgb_rms_mean: float, rgb: NDArray[np.float64]) -> str:
    """A warning line when the calibration's fit (Table 1) is poor for its signal,
    else ``""``: a chart file that does not match the chart photographed (another
    chart, patches in another order, a unit mistake) fits no sensitivities."""
    level = float(np.mean(np.abs(rgb)))
    if level <= 0 or rgb_rms_mean <= MAX_FIT_RMS_SHARE * level:
        return ""
    return (
        f"Table 1's mean RGB RMS {rgb_rms_mean:.3g} is {rgb_rms_mean / level:.0%} of "
        f"the mean response (a good fit: under {MAX_FIT_RMS_SHARE:.0%}): does "
        "--reflectances match the chart photographed (patch names, order, units)?"
    )
