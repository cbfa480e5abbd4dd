"""The estimate's lighting as its calibration found it, and the sample's scale
against the chart's.

:func:`estimation_lighting` is the first half of the estimate chain, which the
patches (``steps.estimate_reflectance``) and the per-pixel images
(``image_session``) share: the measured illuminants corrected as the calibration
found, then they and the sensitivities on the integration grid.

:func:`board_reflectance` is the white background's reflectance by Eq. 1 under each
light: ``calibrate`` keeps the chart session's (the side file's
``white_background``), and :func:`check_sample_scale` compares a sample session's
with it (``core.plausibility.check_white_scale``): both sessions are flat-fielded to
that board (Eq. 2), so a sample on another scale than its chart (an exposure in
another unit, another aperture, a moved light) shows there, where a darker sample
does not.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from tunespec.core.spectra import Grid, Spectra

if TYPE_CHECKING:
    from tunespec.core.plausibility import Checks
    from tunespec.core.responses import Responses

__all__ = [
    "board_reflectance",
    "check_sample_scale",
    "estimation_lighting",
    "sample_board",
    "sample_scale_record",
    "sample_scale_text",
    "white_background",
]


def sample_scale_text(ratios: Mapping[str, float] | None) -> str:
    """:func:`check_sample_scale`'s ratios as the provenance says them, ``""``
    without."""
    from tunespec.core.plausibility import WHITE_SCALE_TOLERANCE

    if not ratios:
        return ""
    r = np.array(list(ratios.values()))
    return (
        f"{np.median(r):.3f}x ({r.min():.3f}-{r.max():.3f} over {r.size} lights; "
        f"1 +- {WHITE_SCALE_TOLERANCE:g} accepted)"
    )


def check_sample_scale(
    checks: Checks, sample: Mapping[str, float] | None, meta: Mapping[str, Any]
) -> dict[str, float] | None:
    """The sample's white background by Eq. 1 (:func:`board_reflectance`; None:
    its level not recorded) against the chart session's
    (``core.plausibility.check_white_scale``), where the calibration kept it; a
    warning when the sample has no white level to compare. Returns the ratio per
    light compared (None: none). ``estimate`` and the per-pixel images call it."""
    from tunespec.core.calibration import white_from_meta
    from tunespec.core.plausibility import check_white_scale, white_ratios

    chart = white_from_meta(meta)
    if chart is None:
        return None
    if sample is None:
        if checks.warn is not None:
            checks.warn(
                "the responses carry no white-background level (white_R, white_G, "
                "white_B): their scale against the chart session's is not checked"
            )
        return None
    checks(check_white_scale, sample, chart)
    return white_ratios(sample, chart)


def estimation_lighting(
    illuminants: Spectra,
    sensitivity: Spectra,
    meta: Mapping[str, Any],
    grid: Grid,
    *,
    spd_shift_nm: float | None = None,
) -> tuple[Spectra, Spectra, Grid]:
    """The first half of the estimate chain, which the per-pixel images share
    (``image_session``): the illuminants corrected as the calibration found
    (``meta``), then they and the sensitivities on the integration grid (Eq. 1 on
    the sensitivities' finer grid, the reflectances on ``grid``:
    ``core.wiener.on_integration_grid``).

    With a calibration's corrections the spectra are first taken as the
    calibration took its own (``core.metering.as_calibrated``, on the
    sensitivities' grid: ``calibrate``'s CSV is on the calibration's): the
    corrections were fitted on that form.
    Applied to the spectra as read, they placed an IR-cut camera's blue edge
    wrongly (``benchmarks/cli_protocol.py``: IR-cut-01's 10 nm readings 0.104-0.300
    mean dE00 against 0.090-0.118 over 4 draws; at 1 nm, 10 cameras 0.103 against
    0.090, see docs/validation.md)."""
    from tunespec.core.calibration import correct_illuminants_from_meta
    from tunespec.core.metering import as_calibrated
    from tunespec.core.wiener import on_integration_grid

    if "led_correction" in meta or "spd_shift_nm" in meta:
        illuminants = as_calibrated(illuminants, sensitivity.grid)
    corrected = correct_illuminants_from_meta(illuminants, meta, spd_shift_nm)
    return on_integration_grid(corrected, sensitivity, grid)


def white_background(
    responses: Responses,
    illuminants: Spectra,
    sensitivity: Spectra,
    meta: Mapping[str, Any],
) -> dict[str, float] | None:
    """The white background's reflectance by Eq. 1 under each of the responses'
    lights (:func:`board_reflectance` of their ``white_rgb``); ``None`` when the
    responses carry no white level."""
    return board_reflectance(
        responses.white_rgb, responses.illuminants, illuminants, sensitivity, meta
    )


def board_reflectance(
    white_rgb: Any,
    lights: Sequence[str],
    illuminants: Spectra,
    sensitivity: Spectra,
    meta: Mapping[str, Any],
) -> dict[str, float] | None:
    """The white background's reflectance by Eq. 1 under each light
    (``core.plausibility.white_reflectance``; NaN ones left out): its level
    ``white_rgb`` (n_lights, 3, linear) over a perfect white's, with the illuminants
    corrected as the calibration found (:func:`estimation_lighting`, where both
    are known). ``None`` where the two share no range or without a level."""
    return sample_board(white_rgb, lights, illuminants, sensitivity, meta)[0]


def sample_board(
    white_rgb: Any,
    lights: Sequence[str],
    illuminants: Spectra,
    sensitivity: Spectra,
    meta: Mapping[str, Any],
) -> tuple[dict[str, float] | None, tuple[str, ...]]:
    """:func:`board_reflectance`, and what the white background's channels say of
    the sample's linearity (``core.plausibility.board_bend_warning``; ``()``:
    nothing) on the same lighting. The latter is for the estimates no Eq. 1 check
    of the targets covers: patches without a covariance, every per-pixel image.
    ``(None, ())`` without a white level (``white_rgb`` None)."""
    from tunespec.core.plausibility import (
        board_bend_warning,
        white_reflectance,
        white_response,
    )

    lit = (
        None
        if white_rgb is None
        else _board_lighting(lights, illuminants, sensitivity, meta)
    )
    if lit is None:
        return None, ()
    rho = white_reflectance(white_rgb, *lit)
    said = board_bend_warning(white_rgb, white_response(*lit))
    return (
        {name: float(r) for name, r in zip(lights, rho, strict=True) if np.isfinite(r)},
        () if said is None else (said,),
    )


def _board_lighting(
    lights: Sequence[str],
    illuminants: Spectra,
    sensitivity: Spectra,
    meta: Mapping[str, Any],
) -> tuple[Spectra, Spectra] | None:
    """``lights`` corrected as the calibration found and the sensitivities, on one
    grid where both are known (Eq. 1 as the estimate integrates it,
    ``wiener.integration_grid``); None where they share no range."""
    step = sensitivity.step_nm
    lo = max(sensitivity.wavelength_nm[0], illuminants.wavelength_nm[0])
    hi = min(sensitivity.wavelength_nm[-1], illuminants.wavelength_nm[-1])
    if hi - lo < step:
        return None
    overlap = Grid(float(lo), float(lo + np.floor((hi - lo) / step) * step), step)
    illum, sens, _ = estimation_lighting(illuminants, sensitivity, meta, overlap)
    return illum.select(list(lights)), sens


def sample_scale_record(
    white_rgb: Any,
    lights: Sequence[str],
    illuminants: Spectra,
    sensitivity: Spectra,
    meta: Mapping[str, Any],
    *,
    force: bool = False,
) -> dict[str, Any]:
    """:func:`check_sample_scale` of a session's white level ``white_rgb`` (linear,
    under ``lights``) as the per-pixel images record it: ``white_scale`` (its text),
    ``forced`` (the override, with ``force``; without, an ``Implausible``) and
    ``warnings`` (:func:`sample_board`'s)."""
    from tunespec.core.plausibility import Checks

    checks = Checks(force=force)
    board, said = sample_board(white_rgb, lights, illuminants, sensitivity, meta)
    ratios = check_sample_scale(checks, board, meta)
    return {
        "white_scale": sample_scale_text(ratios),
        "forced": list(checks.overridden),
        "warnings": list(said),
    }
