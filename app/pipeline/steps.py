"""The steps of a measurement, shared by ``tunespec run``/``demo`` and the GUI wizard.

Each step is a function of frozen inputs returning a frozen result; the ones that take
time accept ``progress`` and ``should_stop`` (``core.progress``):

1. :func:`capture_target` (:func:`capture_chart`, :func:`capture_sample`) - a session
   under every LED (dark, white, target), resumed where it exists;
2. :func:`process` - dark, flat field (Eq. 2), corners, ROI statistics -> responses
   and illuminants (measured SPD x exposure);
3. :func:`calibrate` - camera sensitivities (``core.sensitivity``) and Table 1;
4. :func:`estimate` - Wiener reflectances (Eq. 5-6, the SG as prior) and, with a
   reference, Table 2 (:func:`evaluate`);
5. :func:`export` - CSV, rawtoaces JSON, Argyll ``.ti3`` and the HTML/PDF report.

:func:`tunespec.app.pipeline.run.run` loops over them for a
:class:`~tunespec.app.pipeline.plan.Plan`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tunespec.app.pipeline.folder import (
    CHART_CHOICE_FILE,
    add_capture_warnings,
    clear_capture_warnings,
    write_exports_index,
)
from tunespec.app.pipeline.plan import ESTIMATION_GRID, chart_layout, sample_layout
from tunespec.app.pipeline.processing import process_session, write_processed
from tunespec.core.colorimetry import ReflectanceStats, reflectance_stats
from tunespec.core.datasets import load_colorchecker_sg
from tunespec.core.errors import InputError
from tunespec.core.io.export import (
    export_camera_characterisation,
    export_measurement,
    write_colorimetry_csv,
)
from tunespec.core.io.session import Session
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.processing import ProcessedSession
from tunespec.core.progress import ProgressFn, StopFn, sub_progress
from tunespec.core.spectra import CALIBRATION_GRID, Grid, Spectra
from tunespec.devices.capture import (
    FrameCallback,
    capture,
    new_session,
    recorded_sim_camera,
)
from tunespec.devices.registry import Bench, sim_scene

if TYPE_CHECKING:
    # the estimators import scipy (a third of a second): imported where they run,
    # so that loading a configuration (and failing on it) answers at once
    from tunespec.core.plausibility import Checks
    from tunespec.core.selfcheck import SelfCheck
    from tunespec.core.sensitivity import SensitivityEstimate
    from tunespec.core.stats import CalibrationReport, PredictionStats
    from tunespec.core.uncertainty import ReflectanceUncertainty
    from tunespec.core.wiener import WienerEstimate

__all__ = [
    "Calibration",
    "Estimation",
    "bench_for_target",
    "calibrate",
    "capture_chart",
    "capture_sample",
    "capture_target",
    "estimate",
    "evaluate",
    "export",
    "process",
    "session_provenance",
    "table1_by_patch",
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

    @property
    def reflectance(self) -> Spectra:
        return self.wiener.reflectance


# -- steps -----------------------------------------------------------------------------
def bench_for_target(
    bench: Bench,
    layout: TargetLayout,
    reflectances: Spectra | None = None,
    *,
    seed: int = 1,
) -> Bench:
    """The bench with ``layout`` in front of the camera.

    On hardware the operator changes the target (the stage asks them), so the bench is
    returned as it is. A simulated bench gets the same simulated camera (same
    constants, light and clock; :meth:`SimCamera.looking_at`) looking at a scene with
    ``layout`` on the same board under the same light field
    (:meth:`SimScene.bench_options`).
    """
    if not bench.simulated:
        return bench
    # the same bench: camera pose, field of view, the light's fall-off, the white
    # board and the camera's sensor constants stay; only the target changes (a
    # scene or camera rebuilt from defaults would change the flat field and the
    # sensitivities between the calibration and the sample)
    same: dict[str, Any] = bench.sim_stage.bench_options()
    scene = sim_scene(layout, reflectances, **same)
    camera = bench.sim_camera.looking_at(scene, seed=seed)
    return Bench(bench.light, camera, scene, camera.truth())


def bench_as_recorded(bench: Bench, session: Session) -> Bench:
    """``bench`` with the simulated camera ``session`` was captured with (its
    resolution and seed: ``devices.capture.recorded_sim_camera``); hardware, or a
    camera already so, as it is. The one rule the CLI's and the GUI's resume and
    retake share."""
    recorded = recorded_sim_camera(session)
    if not bench.simulated or not recorded:
        return bench
    camera = bench.sim_camera
    seed = recorded.get("seed")
    resolution = recorded.get("resolution")
    same_seed = seed is None or camera.identity.serial == f"SIM-{seed}"
    if same_seed and resolution in (None, camera.resolution):
        return bench
    camera = camera.looking_at(bench.sim_stage, seed=seed, resolution=resolution)
    return Bench(bench.light, camera, bench.stage, camera.truth())


def capture_target(
    bench: Bench,
    session_dir: str | PathLike[str],
    layout: TargetLayout,
    *,
    exposure: str | float | Mapping[str, float] = "auto",
    iso: int = 100,
    brackets: Sequence[float] = (1.0,),
    n_darks: int = 1,
    repeats: int = 1,
    resume: bool = True,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    on_frame: FrameCallback | None = None,
    on_warning: Callable[[str], None] | None = None,
    on_stage: Callable[[str], None] | None = None,
) -> tuple[Session, tuple[str, ...]]:
    """Capture (or resume) one session of ``layout`` on ``bench``.

    Every warning is kept beside the session the moment it arises
    (:func:`~tunespec.app.pipeline.folder.add_capture_warnings`), so the calibrate
    and estimate steps report it even when the capture was resumed, by another
    front end, or interrupted.

    Parameters
    ----------
    on_warning, on_stage
        ``devices.capture.capture``'s hooks: each warning as it arises, and the
        stage that starts (``"metering LED495, 7 of 22"``).

    Returns
    -------
    (session, warnings)
        ``warnings``: those of this run.
    """
    root = Path(session_dir)

    def warned(text: str) -> None:
        add_capture_warnings(root, [text])
        if on_warning is not None:
            on_warning(text)

    if (root / "manifest.json").is_file():
        if not resume:
            raise InputError("a session already exists here", path=root)
        session = Session.open(root)
        if session.layout is None:
            session.set_layout(layout.with_corners(None))
        # the missing frames are taken as the others were: a simulated camera
        # gets the session's resolution and seed back (a camera that differs
        # otherwise is refused by capture() before its first frame)
        bench = bench_as_recorded(bench, session)
    else:
        clear_capture_warnings(root)  # of an earlier session in this folder
        session = new_session(
            root,
            bench.light,
            bench.camera,
            layout=layout.with_corners(None),
            exposure=exposure,
            iso=iso,
            brackets=brackets,
            n_darks=n_darks,
            repeats=repeats,
        )
    result = capture(
        session,
        bench.light,
        bench.camera,
        bench.stage,
        resume=True,
        progress=progress,
        should_stop=should_stop,
        on_frame=on_frame,
        on_warning=warned,
        on_stage=on_stage,
    )
    return session, result.warnings


def capture_chart(
    bench: Bench, session_dir: str | PathLike[str], **kwargs: Any
) -> tuple[Session, tuple[str, ...]]:
    """:func:`capture_target` of the ColorChecker SG (:func:`chart_layout`)."""
    return capture_target(bench, session_dir, chart_layout(), **kwargs)


def capture_sample(
    bench: Bench,
    session_dir: str | PathLike[str],
    layout: TargetLayout | None = None,
    **kwargs: Any,
) -> tuple[Session, tuple[str, ...]]:
    """:func:`capture_target` of the sample target (default :func:`sample_layout`)."""
    return capture_target(bench, session_dir, layout or sample_layout(), **kwargs)


def process(
    session: Session,
    *,
    out_dir: str | PathLike[str] | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    force: bool = False,
    reference_xyz: Any = None,
    **kwargs: Any,
) -> ProcessedSession:
    """:func:`tunespec.core.processing.process_session`; with ``out_dir``, also write
    the ``responses.csv`` and ``illuminants.csv`` that calibrate/estimate read.

    A session whose patch extraction fails its check
    (:func:`tunespec.core.extraction.check_extraction`: ROIs across patch edges,
    patches out of the reference's order, with ``reference_xyz``: the chart's
    reference XYZ in layout order) is refused with an ``InputError``; ``force``
    keeps it (the failure stays in ``ProcessedSession.warnings``).
    """
    processed = process_session(
        session, progress=progress, should_stop=should_stop, **kwargs
    ).checked(reference_xyz)
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
    options
        More arguments for ``estimate_camera_sensitivity``.
    """
    from tunespec.core.sensitivity import estimate_camera_sensitivity
    from tunespec.core.stats import calibration_report

    refl = reflectances if reflectances is not None else load_colorchecker_sg(grid)
    refl = refl.resample(grid)
    illum = chart.illuminants.resample(grid, average=True)
    if method is not None:
        options["method"] = method
    responses = _with_reference(chart.responses, refl)
    est = estimate_camera_sensitivity(
        responses,
        illum,
        refl,
        progress=sub_progress(progress, 0.0, 0.5) if check else progress,
        should_stop=should_stop,
        **options,
    )
    rep = calibration_report(est, responses, illum, refl)
    checked = None
    if check:
        from tunespec.core.selfcheck import self_check

        refit = {**options, "method": est.method}
        checked = self_check(
            est,
            responses,
            illum,
            refl,
            reported_illuminants=chart.illuminants,
            fit=lambda r: estimate_camera_sensitivity(
                r, illum, refl, should_stop=should_stop, **refit
            ),
            progress=sub_progress(progress, 0.5, 1.0),
            should_stop=should_stop,
        )
    per_patch = table1_by_patch(est, responses, illum, refl)
    return Calibration(est, rep, per_patch, self_check=checked)


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
    measured = responses.subset(patches)
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
) -> tuple[dict[str, str], dict[str, float], list[tuple[str, str]]]:
    """What the report's provenance says about the capture sessions.

    Parameters
    ----------
    sessions
        Role (``"chart"``, ``"sample"``) -> session folder.

    Returns
    -------
    (items, exposures_s, input_files)
        Session folders, their creation time, frame counts and fingerprints; the
        chart's exposure per LED (s, first bracket); every manifest with its
        SHA-256 (a manifest lists the SHA-256 of each of its frames).
    """
    from tunespec.core.io.session import MANIFEST_NAME, sha256_file

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
        items[f"{role} frames fingerprint (SHA-256)"] = session.fingerprint()
        files.append(
            (str(root.resolve() / MANIFEST_NAME), sha256_file(root / MANIFEST_NAME))
        )
        if not exposures:
            exposures = {c: float(t[0]) for c, t in settings.exposures_s.items()}
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
    from tunespec.core.calibration import correct_illuminants_from_meta
    from tunespec.core.plausibility import Checks, check_estimate_inputs
    from tunespec.core.uncertainty import reflectance_uncertainty
    from tunespec.core.wiener import on_integration_grid, wiener_reflectance

    prior = prior if prior is not None else load_colorchecker_sg(grid)
    illuminants = correct_illuminants_from_meta(
        sample.illuminants, sensitivity.meta, spd_shift_nm
    )
    illum_fine, sens_fine, _ = on_integration_grid(illuminants, sensitivity, grid)
    checks = checks if checks is not None else Checks()
    check_estimate_inputs(checks, sample.responses, illum_fine, sens_fine)
    est = wiener_reflectance(
        sample.responses, illum_fine, sens_fine, prior.resample(grid)
    )
    table2 = None if reference is None else evaluate(est.reflectance, reference)
    unc = None
    if calibration is not None and calibration.covariance is not None:
        unc = reflectance_uncertainty(
            est, sample.responses, sample.illuminants, calibration
        )
    return Estimation(est, table2, unc, tuple(checks.overridden))


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
    (:func:`~tunespec.core.io.export.export_camera_characterisation`).

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
    unc = estimation.uncertainty
    if unc is not None:
        names = estimation.reflectance.names
        files["reflectances_uncertainty_csv"] = out / "reflectances_uncertainty.csv"
        write_spectra_csv(
            estimation.reflectance.with_values(unc.reflectance_std),
            files["reflectances_uncertainty_csv"],
        )
        files["colorimetry_csv"] = write_colorimetry_csv(
            out / "colorimetry.csv", names, unc
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
    items, exposures, inputs = session_provenance(sessions)
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
        led_correction=calibration.estimate.led_correction,
        uncertainty_budget=None if unc is None else budget_summary(unc),
        flags=tuple(warnings),
        exports={k: p.name for k, p in files.items()},
        threshold_rgb_mean=threshold_rgb_mean,
        self_check=calibration.self_check,
        table1_patches=calibration.patch_rgb_error,
        chart_layout=chart.layout,
        provenance={**dict(provenance), **items},
        exposures_s=exposures,
        input_files=tuple(inputs),
        chart_choice=chart_choice,
        record=record,
    )
    return write_report(out, data)
