"""The steps of a measurement, shared by ``tunespec run``/``demo`` and the GUI wizard.

Each step is a function of frozen inputs returning a frozen result; the ones that take
time accept ``progress`` and ``should_stop`` (``core.progress``):

1. :func:`capture_target` (:func:`capture_chart`, :func:`capture_sample`) - a session
   under every LED (dark, white, target), resumed where it exists;
2. :func:`process` - dark, flat field (Eq. 2), corners, ROI statistics -> responses
   and illuminants (measured SPD x exposure);
3. :func:`calibrate` - camera sensitivities (``core.sensitivity``) and Table 1; the
   calibrate chain on responses (fit, Table 1, self-check) is :func:`fit_calibration`;
4. :func:`estimate` - Wiener reflectances (Eq. 5-6, the SG as prior) and, with a
   reference, Table 2 (:func:`evaluate`); the estimate chain on responses (correct
   the illuminants, integrate, Wiener, uncertainty) is :func:`estimate_reflectance`;
5. :func:`export` - CSV, rawtoaces JSON, Argyll ``.ti3`` and the HTML/PDF report.

The capture step and the one place resume and retake are decided
(:func:`~tunespec.app.pipeline.capture.open_for_capture`) are in
:mod:`tunespec.app.pipeline.capture` (named here too). The front ends call these steps
through :mod:`tunespec.app.pipeline.jobs`; :func:`tunespec.app.pipeline.run.run`
loops over them for a :class:`~tunespec.app.pipeline.plan.Plan`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tunespec.app.pipeline.capture import (
    CaptureSettings,
    Resume,
    bench_for_target,
    capture_chart,
    capture_sample,
    capture_session,
    capture_target,
    open_for_capture,
    recorded_bench_options,
)
from tunespec.app.pipeline.folder import (
    CHART_CHOICE_FILE,
    write_exports_index,
)
from tunespec.app.pipeline.lighting import (
    check_sample_scale,
    estimation_lighting,
    sample_board,
    sample_scale_text,
    white_background,
)
from tunespec.app.pipeline.plan import ESTIMATION_GRID
from tunespec.app.pipeline.processing import process_session, write_processed
from tunespec.core.colorimetry import ReflectanceStats, reflectance_stats
from tunespec.core.datasets import load_colorchecker_sg
from tunespec.core.errors import InputError
from tunespec.core.io.camera_export import export_camera_characterisation
from tunespec.core.io.export import export_measurement, write_colorimetry_csv
from tunespec.core.io.session import MANIFEST_NAME, Session
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.processing import ProcessedSession
from tunespec.core.progress import ProgressFn, StopFn, sub_progress
from tunespec.core.spectra import CALIBRATION_GRID, Grid, Spectra

if TYPE_CHECKING:
    # the estimators import scipy (a third of a second): imported where they run,
    # so that loading a configuration (and failing on it) answers at once
    from tunespec.core.plausibility import Checks
    from tunespec.core.responses import Responses
    from tunespec.core.selfcheck import SelfCheck
    from tunespec.core.sensitivity import SensitivityEstimate
    from tunespec.core.stats import CalibrationReport, PredictionStats
    from tunespec.core.uncertainty import ReflectanceUncertainty
    from tunespec.core.wiener import WienerEstimate

__all__ = [
    "Calibration",
    "CaptureSettings",
    "Estimation",
    "Resume",
    "bench_for_target",
    "calibrate",
    "capture_chart",
    "capture_sample",
    "capture_session",
    "capture_target",
    "estimate",
    "estimate_reflectance",
    "estimation_lighting",
    "evaluate",
    "export",
    "fit_calibration",
    "open_for_capture",
    "process",
    "recorded_bench_options",
    "session_provenance",
    "table1_by_patch",
    "write_uncertainty",
]


# -- results ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Calibration:
    """Estimated camera sensitivities and how well they predict the chart (Table 1).

    Parameters
    ----------
    estimate
        :class:`tunespec.core.sensitivity.SensitivityEstimate`.
    report
        :class:`tunespec.core.stats.CalibrationReport`; ``report.training`` is Table 1.
    self_check
        :class:`tunespec.core.selfcheck.SelfCheck` (or its ``as_dict()`` form, as a
        restored calibration has it); ``None`` when not run.
    """

    estimate: SensitivityEstimate
    report: CalibrationReport
    #: Table 1 per patch: the mean over the LEDs of the RGB error (RMS over R, G, B,
    #: full scale); their mean is Table 1's RGB mean.
    patch_rgb_error: Mapping[str, float] | None = None
    self_check: SelfCheck | Mapping[str, Any] | None = None

    @property
    def sensitivity(self) -> Spectra:
        return self.estimate.sensitivity

    @property
    def table1(self) -> PredictionStats:
        """Table 1 (:class:`~tunespec.core.stats.PredictionStats`)."""
        return self.report.training


@dataclass(frozen=True, eq=False)
class Estimation:
    """Wiener reflectances of a target and, with a reference, Table 2."""

    wiener: WienerEstimate
    table2: ReflectanceStats | None = None
    uncertainty: ReflectanceUncertainty | None = None
    #: Plausibility checks overridden (``force = true``), one line each.
    forced: tuple[str, ...] = ()
    #: The sample's white background by Eq. 1 over the chart session's, per light
    #: (``core.plausibility.check_white_scale``); None where not compared.
    white_scale: Mapping[str, float] | None = None
    #: What the estimate found doubtful in its inputs, one line each
    #: (``core.plausibility.board_bend_warning``).
    warnings: tuple[str, ...] = ()

    @property
    def white_scale_text(self) -> str:
        """:attr:`white_scale` as the report's provenance says it, ``""`` without."""
        return sample_scale_text(self.white_scale)

    @property
    def reflectance(self) -> Spectra:
        return self.wiener.reflectance

    @property
    def solved_grid(self) -> Grid:
        """Where Eq. 5 solved: the reflectances' grid, or the wider one it is cut
        from (``core.wiener.support_grid``)."""
        return (self.wiener.support or self.wiener).reflectance.grid

    @property
    def grid_text(self) -> str:
        """The reflectances' grid and where Eq. 5 solved, as the reports list them:
        ``400:700:5 (solved on 380:730:5)``."""
        grid, solved = self.reflectance.grid, self.solved_grid
        return f"{grid}" + ("" if solved == grid else f" (solved on {solved})")


# -- steps -----------------------------------------------------------------------------
def process(
    session: Session,
    *,
    out_dir: str | PathLike[str] | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    force: bool = False,
    reference_xyz: Any = None,
    preview: str | PathLike[str] | None = None,
    **kwargs: Any,
) -> ProcessedSession:
    """:func:`tunespec.core.processing.process_session`; with ``out_dir``, also write
    the ``responses.csv`` and ``illuminants.csv`` that calibrate/estimate read.

    A session whose patch extraction fails its check
    (:func:`tunespec.core.extraction.check_extraction`: ROIs across patch edges,
    patches out of the reference's order, with ``reference_xyz``: the chart's
    reference XYZ in layout order) is refused with an ``InputError``; ``force``
    keeps it (the failure stays in ``ProcessedSession.warnings``). ``preview``: a
    PNG of the outline and the ROIs, written before a refusal (it shows why).
    """
    processed = process_session(
        session, progress=progress, should_stop=should_stop, **kwargs
    ).checked(reference_xyz)
    if preview is not None:
        from tunespec.app.pipeline.extract import session_preview

        session_preview(session, processed, preview)
    refuse_failed_check(processed, session.root, force=force)
    if out_dir is not None:
        out = Path(out_dir)
        write_processed(processed, out / "responses.csv", out / "illuminants.csv")
    return processed


def refuse_failed_check(
    processed: ProcessedSession, where: str | PathLike[str], *, force: bool = False
) -> None:
    """InputError when ``processed.check`` failed, unless ``force``."""
    check = processed.check
    if check is None or check.ok or force:
        return
    raise InputError(
        f"patch extraction refused (layout {processed.layout.name!r}, corners "
        f"{processed.corners_source}): {check.summary()}; check the chart's layout "
        "and corners (--layout, --corners), or --force to keep it",
        path=where,
    )


def calibrate(
    chart: ProcessedSession,
    reflectances: Spectra | None = None,
    *,
    method: str | None = None,
    grid: Grid = CALIBRATION_GRID,
    check: bool = False,
    checks: Checks | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    **options: Any,
) -> Calibration:
    """Camera sensitivities from the chart's responses (``core.sensitivity``) + Table 1.

    With ``check`` the calibration's self-check follows
    (:func:`tunespec.core.selfcheck.self_check`: residuals against the noise model,
    the LED corrections, the light's reading noise and a second calibration without
    every 5th patch, which about doubles the step's time). Table 1 and the
    sensitivities are the same either way.

    Parameters
    ----------
    chart
        The processed chart session.
    reflectances
        The chart's reflectances (default the shipped ColorChecker SG).
    method
        A method of ``SENSITIVITY_METHODS`` (default: the library's default).
    grid
        Working wavelength grid.
    checks
        :func:`fit_calibration`'s.
    options
        More arguments for ``estimate_camera_sensitivity``.
    """
    refl = reflectances if reflectances is not None else load_colorchecker_sg(grid)
    refl = refl.resample(grid)
    illum = chart.illuminants.resample(grid, average=True)
    if method is not None:
        options["method"] = method
    return fit_calibration(
        _with_reference(chart.responses, refl),
        illum,
        refl,
        reported_illuminants=chart.illuminants,
        check=check,
        checks=checks,
        progress=progress,
        should_stop=should_stop,
        **options,
    )


def fit_calibration(
    responses: Responses,
    illuminants: Spectra,
    reflectances: Spectra,
    *,
    reported_illuminants: Spectra | None = None,
    hold_out_every: int | None = None,
    check: bool = False,
    checks: Checks | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    **options: Any,
) -> Calibration:
    """The calibrate chain, written once: fit the sensitivities
    (``core.sensitivity.estimate_camera_sensitivity``), Table 1 (and the held-aside
    patches' statistics), Table 1 per patch and, with ``check``, the self-check.

    :func:`calibrate` (``run``, ``demo``, the wizard) and ``tunespec calibrate``
    call it.

    Parameters
    ----------
    responses
        The chart's responses.
    illuminants, reflectances
        On the working grid (the illuminants band-averaged onto it).
    reported_illuminants
        The illuminants as the spectroradiometer reported them (the self-check's
        reading noise).
    hold_out_every
        Fit without every N-th patch (``split_patches``, offset N-1); Table 1's
        held-out rows and the self-check's left-out patches are those.
    checks
        The plausibility checks of the fit (default: refuse, no override): a chart
        whose responses bend more than a raw sensor's
        (:func:`~tunespec.core.plausibility.check_chart_linearity`).
    options
        More arguments for ``estimate_camera_sensitivity``.
    """
    from tunespec.core.plausibility import (
        Checks,
        calibration_fit_warning,
        check_chart_linearity,
    )
    from tunespec.core.sensitivity import estimate_camera_sensitivity
    from tunespec.core.stats import calibration_report, split_patches

    held: tuple[str, ...] = ()
    fit = responses
    if hold_out_every:
        fit_names, held = split_patches(
            responses.patches, every=hold_out_every, offset=hold_out_every - 1
        )
        fit = responses.subset(list(fit_names))
    est = estimate_camera_sensitivity(
        fit,
        illuminants,
        reflectances,
        progress=sub_progress(progress, 0.0, 0.5) if check else progress,
        should_stop=should_stop,
        **options,
    )
    checks = checks if checks is not None else Checks()
    checks(check_chart_linearity, est.params)
    rep = calibration_report(
        est, responses, illuminants, reflectances, held_out_patches=held
    )
    from tunespec.core.selfcheck import finding_lines, held_out_of, self_check

    checked = None
    if check:
        held_out = None
        if held:
            held_out = held_out_of(
                est, responses, illuminants, reflectances, held, hold_out_every
            )
        refit = {**options, "method": est.method}
        checked = self_check(
            est,
            fit,
            illuminants,
            reflectances,
            reported_illuminants=reported_illuminants,
            fit=lambda r: estimate_camera_sensitivity(
                r,
                illuminants,
                reflectances,
                should_stop=should_stop,
                replicates=0,
                **refit,
            ),
            held_out=held_out,
            progress=sub_progress(progress, 0.5, 1.0),
            should_stop=should_stop,
        )
    per_patch = table1_by_patch(est, fit, illuminants, reflectances)
    reported = illuminants if reported_illuminants is None else reported_illuminants
    findings = [
        w
        for w in (
            calibration_fit_warning(
                float(rep.training.as_dict()["RGB"]["mean"]), responses.rgb
            ),
            *finding_lines(checked.warnings if checked else ()),
        )
        if w
    ]
    notes = {"forced": list(checks.overridden), "warnings": findings}
    est = replace(
        est,
        white_background=_white_background(est, responses, reported),
        provenance={**est.provenance, **{k: v for k, v in notes.items() if v}},
    ).synced()
    return Calibration(est, rep, per_patch, self_check=checked)


def _white_background(
    est: SensitivityEstimate, responses: Responses, illuminants: Spectra
) -> dict[str, float] | None:
    """The chart session's white background by Eq. 1 (light ->
    :func:`white_background`), which the side file keeps for the estimate's scale
    check; ``None`` when the responses carry no white level."""
    from tunespec.core.calibration import linearise_from_meta

    sens = est.sensitivity
    # linear, as the estimate's responses are when it compares them
    responses = linearise_from_meta(responses, sens.meta)
    return white_background(responses, illuminants, sens, sens.meta)


def _with_reference(responses: Any, refl: Spectra) -> Any:
    """The responses of the patches with reference data (a Passport's creative
    panel has none in the shipped ColorChecker data); all of them when every patch
    has, and an InputError naming the first missing ones when fewer than half do."""
    have = [p for p in responses.patches if p in refl.names]
    if len(have) == len(responses.patches):
        return responses
    if 2 * len(have) < len(responses.patches):
        missing = [p for p in responses.patches if p not in refl.names]
        raise InputError(
            f"{len(missing)} of {len(responses.patches)} patches have no reference "
            f"data ({', '.join(missing[:6])} ...): give the chart's reflectances "
            "(--reflectances, or reflectances = in the configuration's [chart])"
        )
    return responses.subset(have)


def table1_by_patch(
    estimate: SensitivityEstimate,
    responses: Any,
    illuminants: Spectra,
    reflectances: Spectra,
) -> dict[str, float]:
    """Table 1's RGB error per fitted patch (the report's map and worst patches).

    For each patch the mean over its LEDs of the per-stimulus error
    ``sqrt(mean_c (c - c_hat)^2)`` (the paper's Table 1, "RGB" row), with Eq. 1
    predicting ``c_hat`` from the estimated sensitivities
    (:func:`tunespec.core.calibration.predict_responses`), the illuminants corrected
    as the calibration found. Patches the fit left out are not listed.
    """
    from tunespec.core.calibration import predict_responses

    skip = set(estimate.excluded_patches)
    patches = [p for p in responses.patches if p not in skip]
    measured = estimate.linearise(responses.subset(patches))
    predicted = predict_responses(
        estimate.sensitivity,
        estimate.correct_illuminants(illuminants),
        reflectances,
        patches=patches,
        illuminant_names=measured.illuminants,
    )
    err = np.sqrt(np.mean((measured.rgb - predicted.rgb) ** 2, axis=2))
    return {p: float(e) for p, e in zip(patches, np.mean(err, axis=1), strict=True)}


def session_provenance(
    sessions: Mapping[str, str | PathLike[str]],
    processed: Mapping[str, ProcessedSession] | None = None,
) -> tuple[dict[str, str], dict[str, float], list[tuple[str, str]]]:
    """What the report's provenance says about the capture sessions.

    Parameters
    ----------
    sessions
        Role (``"chart"``, ``"sample"``) -> session folder.
    processed
        Role -> the session as processed: the f-number its raw files state
        (``ProcessedSession.aperture``, which the manifest does not keep).

    Returns
    -------
    (items, exposures_s, input_files)
        Session folders, their creation time, frame counts, aperture ("f/8", or
        "not recorded" when the raw files state none; only for a role in
        ``processed``) and fingerprints; the first session's exposure per LED (s,
        first bracket, at ISO 100: times its gain, as Eq. 1's illuminants have it);
        every manifest with its SHA-256 (a manifest lists the SHA-256 of each of
        its frames).
    """
    from tunespec.core.io.raw import f_number_text
    from tunespec.core.io.session import sha256_file
    from tunespec.core.processing import light_scale

    items: dict[str, str] = {}
    exposures: dict[str, float] = {}
    files: list[tuple[str, str]] = []
    for role, folder in sessions.items():
        root = Path(folder)
        if not (root / MANIFEST_NAME).is_file():
            continue
        session = Session.open(root)
        settings = session.settings
        ok = session.ok_frames()
        items[f"{role} session"] = str(root.resolve())
        items[f"{role} captured (UTC)"] = str(session.manifest.get("created_utc", ""))
        items[f"{role} frames"] = (
            f"{len(ok)} ({sum(f.kind == 'dark' for f in ok)} dark), ISO "
            f"{settings.iso}, exposure {settings.exposure_mode}"
        )
        if processed is not None and role in processed:
            items[f"{role} aperture"] = f_number_text(processed[role].aperture)
        items[f"{role} frames fingerprint (SHA-256)"] = session.fingerprint()
        files.append(
            (str(root.resolve() / MANIFEST_NAME), sha256_file(root / MANIFEST_NAME))
        )
        if not exposures:
            # as Eq. 1's illuminants count them (the gain too)
            exposures = {
                c: light_scale(t[0], settings.iso)
                for c, t in settings.exposures_s.items()
            }
    return items, exposures, files


def estimate(
    sample: ProcessedSession,
    sensitivity: Spectra,
    *,
    prior: Spectra | None = None,
    reference: Spectra | None = None,
    grid: Grid = ESTIMATION_GRID,
    spd_shift_nm: float | None = None,
    calibration: SensitivityEstimate | None = None,
    checks: Checks | None = None,
) -> Estimation:
    """Wiener reflectances of the sample (Eq. 5-6; prior default: the SG) and Table 2.

    ``spd_shift_nm`` is the spectroradiometer's wavelength shift fitted at calibration
    (``SensitivityEstimate.spd_shift_nm``); the sample's SPDs come from the same
    instrument, so it is undone on them too. ``None`` takes it from
    ``sensitivity.meta`` (the per-LED corrections of a ``"bayes"`` calibration, else
    its common shift; :func:`~tunespec.core.calibration.correct_illuminants_from_meta`).
    With ``calibration`` carrying a covariance, the standard uncertainties of the
    reflectances and their CIELAB are computed too (:mod:`tunespec.core.uncertainty`).
    ``checks`` (default: refuse, no override) runs the plausibility checks of the
    responses against Eq. 1 first (:func:`tunespec.core.plausibility.check_estimate_inputs`).
    """
    prior = prior if prior is not None else load_colorchecker_sg()
    est = estimate_reflectance(
        sample.responses,
        sample.illuminants,
        sensitivity,
        prior,
        grid,
        spd_shift_nm=spd_shift_nm,
        calibration=calibration,
        checks=checks,
    )
    if reference is None:
        return est
    return replace(est, table2=evaluate(est.reflectance, reference))


def estimate_reflectance(
    responses: Responses,
    illuminants: Spectra,
    sensitivity: Spectra,
    prior: Spectra,
    grid: Grid,
    *,
    meta: Mapping[str, Any] | None = None,
    spd_shift_nm: float | None = None,
    calibration: SensitivityEstimate | None = None,
    uncertainty_from_meta: bool = False,
    checks: Checks | None = None,
    responses_path: str | PathLike[str] | None = None,
    noise_std: float | None = None,
    center_prior: bool = True,
    clip: bool = True,
) -> Estimation:
    """The estimate chain, written once: undo the light source's metering errors
    the calibration found on the illuminants
    (:func:`~tunespec.core.calibration.correct_illuminants_from_meta`), put them and
    the sensitivities on the integration grid (``on_integration_grid``), check the
    responses against Eq. 1 (``check_estimate_inputs``), Wiener (Eq. 5-6) and, with
    a ``calibration`` carrying a covariance, the standard uncertainties and whether
    the responses fit any reflectance through Eq. 1 (``check_response_consistency``).

    :func:`estimate` (``run``, ``demo``, the wizard) and ``tunespec estimate`` call
    it.

    Parameters
    ----------
    responses, illuminants
        The sample's responses and its illuminants as measured (any grid).
    sensitivity
        Absolute sensitivities, on their own grid.
    prior
        Training reflectances (resampled here onto ``grid`` and, where they reach
        further, the range beyond it that Eq. 1 integrates:
        ``core.wiener.support_grid``).
    grid
        The reflectances' grid.
    meta
        The calibration's corrections (``sensitivity.meta`` when ``None``; the
        side file's as ``read_sensitivity_meta`` gives it; ``{}`` for none).
    spd_shift_nm
        A wavelength shift to undo instead of the calibration's.
    calibration, uncertainty_from_meta
        The calibration whose covariance gives the standard uncertainties, or
        (``uncertainty_from_meta``) the one ``meta`` holds (``calibrate``'s side
        file: ``core.calibration.Calibration.from_meta``).
    checks
        The plausibility checks (default: refuse, no override).
    noise_std, center_prior, clip
        :func:`~tunespec.core.wiener.wiener_reflectance`'s.
    """
    from tunespec.core.calibration import linearise_from_meta
    from tunespec.core.plausibility import (
        Checks,
        check_calibration_grid,
        check_estimate_inputs,
        check_response_consistency,
    )
    from tunespec.core.uncertainty import wiener_with_uncertainty

    meta = sensitivity.meta if meta is None else meta
    # the sensor's non-linearity, undone as the calibration undid it in the chart's
    responses = linearise_from_meta(responses, meta)
    checks = checks if checks is not None else Checks()
    checks(check_calibration_grid, sensitivity.wavelength_nm, meta)
    illum_fine, sens_fine, _ = estimation_lighting(
        illuminants, sensitivity, meta, grid, spd_shift_nm=spd_shift_nm
    )
    check_estimate_inputs(
        checks, responses, illum_fine, sens_fine, responses_path=responses_path
    )
    board, said = sample_board(
        responses.white_rgb, responses.illuminants, illuminants, sensitivity, meta
    )
    white_scale = check_sample_scale(checks, board, meta)
    if calibration is None and uncertainty_from_meta:
        from tunespec.core.calibration import Calibration as FileCalibration

        calibration = FileCalibration.from_meta(sensitivity, meta)
    est, unc = wiener_with_uncertainty(
        responses,
        illum_fine,
        sens_fine,
        prior,
        illuminants,
        calibration,
        noise_std=noise_std,
        center_prior=center_prior,
        clip=clip,
        grid=grid,
    )
    if unc is not None and unc.chi2_per_response is not None:
        checks(
            check_response_consistency,
            unc.chi2_per_response,
            unc.misfit_by_light,
            responses.illuminants,
        )
        said = ()  # Eq. 1 checked the targets themselves
    return Estimation(est, None, unc, tuple(checks.overridden), white_scale, said)


def write_uncertainty(
    estimation: Estimation,
    reflectances_std_csv: str | PathLike[str],
    colorimetry_csv: str | PathLike[str],
) -> tuple[Path, Path]:
    """The reflectances' standard uncertainties (a spectra CSV) and their XYZ and
    CIELAB with theirs (``write_colorimetry_csv``): the one writer ``export`` and
    ``tunespec estimate`` share. ``estimation.uncertainty`` must be there."""
    unc = estimation.uncertainty
    assert unc is not None
    std = Path(reflectances_std_csv)
    write_spectra_csv(estimation.reflectance.with_values(unc.reflectance_std), std)
    return std, write_colorimetry_csv(
        Path(colorimetry_csv), estimation.reflectance.names, unc
    )


def evaluate(estimated: Spectra, reference: Spectra) -> ReflectanceStats:
    """Table 2 (:func:`tunespec.core.colorimetry.reflectance_stats`)."""
    return reflectance_stats(estimated, reference)


def export(
    out_dir: str | PathLike[str],
    *,
    calibration: Calibration,
    estimation: Estimation,
    chart: ProcessedSession,
    sample: ProcessedSession,
    reference: Spectra | None = None,
    truth_sensitivity: Spectra | None = None,
    devices: Mapping[str, Mapping[str, str]] | None = None,
    settings: Mapping[str, str] | None = None,
    warnings: Sequence[str] = (),
    report: bool = True,
    provenance: Mapping[str, str] | None = None,
    sessions: Mapping[str, str | PathLike[str]] | None = None,
    input_files: Sequence[str | PathLike[str]] = (),
    threshold_rgb_mean: float | None = None,
    chart_reflectances: Spectra | None = None,
    chart_choice: Mapping[str, Any] | None = None,
    record: Any = None,
) -> dict[str, Path]:
    """Write every export (``core.io.export``) and, if asked, the HTML/PDF report
    (with the "Chart choice" section when ``chart_choice``, a
    ``chart_choice.json`` document, is given).

    The chart's camera ``.ti3`` (for ArgyllCMS ``colprof``) and the camera transforms
    (ACES IDT, CCMs for D50/D65/A) come from ``chart_reflectances`` (default: the
    ColorChecker SG) and the calibration
    (:func:`~tunespec.core.io.camera_export.export_camera_characterisation`).

    Files: the chart's ``chart_responses.csv`` / ``chart_illuminants.csv``, the
    ``core.io.export`` set (sensitivities, reflectances, the sample's responses and
    illuminants, Tables 1-2, ``.ti3``) and ``report.html`` / ``report.pdf``, and
    last ``exports.json`` listing them
    (:func:`~tunespec.app.pipeline.folder.write_exports_index`). A measurement puts
    them in its ``export/`` folder (``MeasurementFolder.export_dir``), whichever
    front end runs the step.

    The report's provenance: ``provenance`` (seed, resolution, configuration...),
    the ``sessions`` (:func:`session_provenance`) and the SHA-256 of every file of
    ``input_files`` (layouts, references, the configuration). Its verdict compares
    Table 1's RGB mean with ``threshold_rgb_mean``; ``record`` (the folder's
    :class:`~tunespec.app.pipeline.record.MeasurementRecord`) is its first page.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    write_processed(chart, out / "chart_responses.csv", out / "chart_illuminants.csv")
    files["chart_responses_csv"] = out / "chart_responses.csv"
    files["chart_illuminants_csv"] = out / "chart_illuminants.csv"
    cam = (devices or {}).get("camera", {})
    files.update(
        export_measurement(
            out,
            sensitivity=calibration.sensitivity,
            reflectance=estimation.reflectance,
            responses=sample.responses,
            table1=calibration.table1,
            table2=estimation.table2,
            reference=None
            if reference is None
            else reference.select(estimation.reflectance.names, source="reference"),
            illuminants=sample.illuminants,
            manufacturer=cam.get("vendor", ""),
            model=cam.get("model", ""),
            uncertainty=estimation.uncertainty,
            sensitivity_covariance=calibration.estimate.covariance,
        )
    )
    files.update(
        export_camera_characterisation(
            out,
            sensitivity=calibration.sensitivity,
            chart=chart_reflectances
            if chart_reflectances is not None
            else load_colorchecker_sg(calibration.sensitivity.grid),
            responses=chart.responses,
            illuminants=chart.illuminants,
        ).paths
    )
    if estimation.uncertainty is not None:
        files["reflectances_uncertainty_csv"], files["colorimetry_csv"] = (
            write_uncertainty(
                estimation,
                out / "reflectances_uncertainty.csv",
                out / "colorimetry.csv",
            )
        )
    if report:
        files["report_html"], files["report_pdf"] = _write_report(
            out,
            files,
            calibration=calibration,
            estimation=estimation,
            chart=chart,
            sample=sample,
            reference=reference,
            truth_sensitivity=truth_sensitivity,
            devices=devices or {},
            settings=settings or {},
            warnings=warnings,
            provenance=provenance or {},
            sessions=sessions or {},
            input_files=input_files,
            threshold_rgb_mean=threshold_rgb_mean,
            chart_choice=chart_choice,
            record=record,
        )
    if chart_choice is not None and (out / CHART_CHOICE_FILE).is_file():
        files["chart_choice_json"] = out / CHART_CHOICE_FILE
    write_exports_index(out, files)
    return files


def _write_report(
    out: Path,
    files: Mapping[str, Path],
    *,
    calibration: Calibration,
    estimation: Estimation,
    chart: ProcessedSession,
    sample: ProcessedSession,
    reference: Spectra | None,
    truth_sensitivity: Spectra | None,
    devices: Mapping[str, Mapping[str, str]],
    settings: Mapping[str, str],
    warnings: Sequence[str],
    provenance: Mapping[str, str],
    sessions: Mapping[str, str | PathLike[str]],
    input_files: Sequence[str | PathLike[str]],
    threshold_rgb_mean: float | None,
    chart_choice: Mapping[str, Any] | None,
    record: Any = None,
) -> tuple[Path, Path]:
    """``report.html`` and ``report.pdf`` of :func:`export` (``app.report``); the
    LED spectra shown as spectral radiance (measured radiance x exposure over the
    sample session's exposure per LED)."""
    from tunespec.app.report.report import ReportData, write_report
    from tunespec.core.io.session import sha256_file
    from tunespec.core.uncertainty import budget_summary

    unc = estimation.uncertainty
    items, exposures, inputs = session_provenance(
        sessions, {"chart": chart, "sample": sample}
    )
    inputs += [(str(Path(f).resolve()), sha256_file(f)) for f in input_files]
    sample_dir = sessions.get("sample")
    _, sample_exposures, _ = session_provenance(
        {} if sample_dir is None else {"sample": sample_dir}
    )
    data = ReportData(
        title="TuneSpec measurement report",
        devices={k: dict(v) for k, v in devices.items()},
        settings=dict(settings),
        illuminants=sample.illuminants,
        illuminant_exposures_s=sample_exposures,
        sensitivity=calibration.sensitivity,
        sensitivity_reference=truth_sensitivity,
        sensitivity_reference_label="simulation truth",
        sensitivity_method=str(calibration.estimate.method),
        reflectance=estimation.reflectance,
        reflectance_reference=reference,
        table1=calibration.table1,
        table2=estimation.table2,
        responses=chart.responses,
        excluded_patches=tuple(calibration.estimate.excluded_patches),
        clipped_patches=tuple(estimation.wiener.clipped),
        sensitivity_std=calibration.estimate.std,
        reflectance_std=None if unc is None else unc.reflectance_std,
        lab=None if unc is None else unc.lab,
        lab_std=None if unc is None else unc.lab_std,
        chi2_per_response=None if unc is None else unc.chi2_per_response,
        led_correction=calibration.estimate.led_correction,
        uncertainty_budget=None if unc is None else budget_summary(unc),
        flags=tuple(warnings),
        exports={k: p.name for k, p in files.items()},
        threshold_rgb_mean=threshold_rgb_mean,
        self_check=calibration.self_check,
        table1_patches=calibration.patch_rgb_error,
        chart_layout=chart.layout,
        provenance={
            **dict(provenance),
            **items,
            **(
                {"sample's white background over the chart's (Eq. 1)": white}
                if (white := estimation.white_scale_text)
                else {}
            ),
        },
        exposures_s=exposures,
        input_files=tuple(inputs),
        chart_choice=chart_choice,
        record=record,
    )
    return write_report(out, data)
