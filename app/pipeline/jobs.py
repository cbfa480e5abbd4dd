"""The jobs every front end runs: one step of a measurement each, Qt-free.

``tunespec capture | process | calibrate | estimate``, ``run``/``demo``
(:mod:`tunespec.app.pipeline.run`) and the GUI wizard call these; they parse their
arguments or hold Qt state, and nothing more. A job takes frozen inputs (a
dataclass) and a progress/cancel handle (``progress``, ``should_stop``:
:mod:`tunespec.core.progress`; or the run's :class:`Stages`), runs the steps of
:mod:`tunespec.app.pipeline.steps` and writes its result with the one writer of
:mod:`tunespec.app.pipeline.folder`:

- :func:`capture_job` - open the bench by its specs and capture, resume or retake a
  session (``capture.capture_session``; resume and retake decided by
  ``capture.open_for_capture``, for the wizard's and ``run``'s open benches too);
- :func:`process_job` - a session's responses and illuminants into CSV files;
- :func:`calibrate_job` - process the chart session, the calibrate chain
  (``steps.fit_calibration``) and ``calibration/``;
- :func:`estimate_job` - process the sample session, the estimate chain
  (``steps.estimate_reflectance``), Table 2 and ``estimate/``;
- :func:`export_job` - every export and the report (``steps.export``) from the
  results, restored from the folder when they come from disk.

The chains on files (``tunespec calibrate``/``estimate`` on CSV files) are
:func:`fit_calibration` and :func:`estimate_reflectance`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from tunespec.app.pipeline.capture import (
    CaptureSettings,
    Resume,
    bench_for_target,
    capture_session,
    capture_target,
    recorded_bench_options,
)
from tunespec.app.pipeline.folder import (
    CALIBRATION_DIR,
    CHART_DIR,
    DEFAULT_THRESHOLD_RGB_MEAN,
    ESTIMATE_DIR,
    MEASUREMENT_FILE,
    SAMPLE_DIR,
    CalibrationResult,
    EstimateResult,
    ExportResult,
    read_processed,
    session_fingerprint,
    step_warnings,
    write_calibration,
    write_estimate,
)
from tunespec.app.pipeline.plan import ESTIMATION_GRID
from tunespec.app.pipeline.steps import (
    Calibration,
    Estimation,
    calibrate,
    estimate,
    estimate_reflectance,
    evaluate,
    export,
    fit_calibration,
    process,
    table1_by_patch,
    write_uncertainty,
)
from tunespec.core.errors import InputError
from tunespec.core.io.session import Session, SessionLock
from tunespec.core.layout import TargetLayout
from tunespec.core.plausibility import Checks
from tunespec.core.progress import (
    ProgressFn,
    StopFn,
    check_stop,
    progress_ranges,
    report,
    sub_progress,
)
from tunespec.core.spectra import CALIBRATION_GRID, Grid, Spectra

__all__ = [
    "CalibrateInputs",
    "CaptureInputs",
    "CaptureSettings",
    "EstimateInputs",
    "ExportInputs",
    "ProcessInputs",
    "Resume",
    "Stages",
    "bench_for_target",
    "calibrate_job",
    "capture_job",
    "capture_session",
    "capture_target",
    "estimate_job",
    "estimate_reflectance",
    "export_job",
    "find_session_corners",
    "fit_calibration",
    "predicted_table1",
    "process_job",
    "reference_and_table2",
    "restore_calibration_steps",
    "sensitivity_methods",
    "write_uncertainty",
]

#: How a step's result names a plausibility check accepted with ``force``.
_FORCED = "accepted with force = true:"


# -- the progress/cancel handle --------------------------------------------------------
class Stages:
    """One progress callback split over weighted stages, cancel, and each stage's
    wall time: the handle a job reports through. A job alone makes its own; ``run``
    passes one over the whole measurement, so a job's stages are the run's."""

    def __init__(
        self,
        progress: ProgressFn | None,
        weights: Mapping[str, float],
        should_stop: StopFn | None = None,
    ) -> None:
        self.progress = progress
        self.should_stop = should_stop
        self._ranges = progress_ranges(weights)
        self.timings_s: dict[str, float] = {}

    def timed(self, name: str, func: Callable[[ProgressFn | None], Any]) -> Any:
        """``func(progress of the stage)``, timed; the bar at the stage's end after."""
        start, stop = self._ranges[name]
        t0 = time.perf_counter()
        try:
            return func(sub_progress(self.progress, start, stop))
        finally:
            self.timings_s[name] = time.perf_counter() - t0
            report(self.progress, stop)


# -- capture ---------------------------------------------------------------------------
@dataclass(frozen=True)
class CaptureInputs:
    """A capture by device specs (``tunespec capture``).

    Parameters
    ----------
    session_dir
        The session folder.
    layout
        The target's layout (``None``: the session's, which a new session needs).
    settings, resume
        How a new session is captured; what is done with one that is there.
    light, camera, layout_path, resolution, seed
        ``devices.registry.open_bench``'s (a resumed simulated session keeps its
        own resolution and seed: ``steps.recorded_bench_options``).
    """

    session_dir: Path
    layout: TargetLayout | None = None
    settings: CaptureSettings = field(default_factory=CaptureSettings)
    resume: Resume = field(default_factory=lambda: Resume("new"))
    light: str = "sim"
    camera: str | None = None
    layout_path: Path | None = None
    resolution: tuple[int, int] | None = None
    seed: int | None = None


def capture_job(
    inputs: CaptureInputs,
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    on_warning: Callable[[str], None] | None = None,
) -> Any:
    """Open the bench and capture, resume or retake the session; returns
    ``devices.capture.CaptureResult``. The session's lock is held from before the
    session is created until the capture ends."""
    from tunespec.devices.registry import open_bench

    root = Path(inputs.session_dir)
    inputs.resume.session_exists(root)  # before the lock makes the folder
    with SessionLock(root):
        exists = inputs.resume.session_exists(root)
        layout = inputs.layout
        if layout is None and exists:
            layout = Session.open(root).layout
        if layout is None:
            raise InputError("--layout is needed for a new session")
        resolution, seed = recorded_bench_options(
            root, resolution=inputs.resolution, seed=inputs.seed
        )
        with open_bench(
            inputs.light,
            inputs.camera,
            layout=layout.with_corners(None),
            layout_path=inputs.layout_path,
            resolution=resolution,
            seed=0 if seed is None else seed,
        ) as bench:
            _, result = capture_session(
                bench,
                root,
                layout,
                inputs.settings,
                inputs.resume,
                progress=progress,
                should_stop=should_stop,
                on_warning=on_warning,
            )
    return result


# -- process ---------------------------------------------------------------------------
@dataclass(frozen=True)
class ProcessInputs:
    """``tunespec process``: a session's responses and illuminants into files.

    ``layout``, ``corners``, ``roi_fraction``, ``allow_incomplete`` and ``verify`` as
    ``core.processing.process_session`` takes them; ``reference_xyz`` checks the
    extraction against the chart's reference (``force`` keeps a failed one, flagged
    in the CSV); ``preview`` also writes the PNG of the outline and the ROIs."""

    session_dir: Path
    responses_csv: Path
    illuminants_csv: Path
    layout: TargetLayout | None = None
    corners: Any = None
    roi_fraction: float | None = None
    allow_incomplete: bool = False
    verify: bool = True
    reference_xyz: Any = None
    preview: Path | None = None
    force: bool = False


def process_job(
    inputs: ProcessInputs,
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> Any:
    """Process the session (``steps.process``) and write its responses and
    illuminants; returns the ``ProcessedSession``."""
    from tunespec.app.pipeline.extract import flag_forced_csv
    from tunespec.app.pipeline.processing import write_processed

    processed = process(
        Session.open(inputs.session_dir),
        layout=inputs.layout,
        corners=inputs.corners,
        roi_fraction=inputs.roi_fraction,
        allow_incomplete=inputs.allow_incomplete,
        verify=inputs.verify,
        reference_xyz=inputs.reference_xyz,
        preview=inputs.preview,
        force=inputs.force,
        progress=progress,
        should_stop=should_stop,
    )
    write_processed(processed, inputs.responses_csv, inputs.illuminants_csv)
    if processed.check is not None and not processed.check.ok:
        flag_forced_csv(inputs.responses_csv, processed.check)
    return processed


def _process_session(
    session_dir: Path,
    layout: TargetLayout | None,
    corners: str,
    *,
    reference_xyz: Any = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> Any:
    """``steps.process`` of a measurement's session, nothing written (the processed
    session goes to disk with the result that uses it). ``layout`` ``None``: the
    session's, its corners found; else that layout with corners ``"auto"``
    (found) or ``"editor"`` (its own)."""
    given = corners == "editor"
    options: dict[str, Any] = {}
    if layout is not None:
        options = {
            "layout": layout if given else layout.with_corners(None),
            "corners": "layout" if given else "auto",
        }
    processed = process(
        Session.open(session_dir),
        reference_xyz=reference_xyz,
        progress=progress,
        should_stop=should_stop,
        **options,
    )
    check_stop(should_stop)
    return processed


# -- calibrate -------------------------------------------------------------------------
@dataclass(frozen=True)
class CalibrateInputs:
    """The calibrate step of a measurement folder.

    Parameters
    ----------
    chart_dir, out_dir
        The chart's session and where the calibration goes (``calibration/``).
    layout, corners
        The chart's layout (``None``: the session's) and ``"auto"`` or
        ``"editor"`` corners.
    method
        Sensitivity method (``None``: the library's default).
    threshold
        Pass/fail limit on Table 1's RGB mean.
    reflectances
        The chart's reflectances (``None``: those its layout names); with
        ``check_extraction`` the extraction is checked against them.
    grid
        Working grid.
    force, force_hint
        Accept a fit that fails a plausibility check (a warning of the result), and
        how a refusal names that override.
    """

    chart_dir: Path
    out_dir: Path
    layout: TargetLayout | None = None
    corners: str = "auto"
    method: str | None = None
    threshold: float = DEFAULT_THRESHOLD_RGB_MEAN
    reflectances: Spectra | None = None
    check_extraction: bool = False
    grid: Grid = CALIBRATION_GRID
    force: bool = False
    force_hint: str = "--force"


#: A job alone: processing takes 60 % of the calibrate job's bar, 80 % of the
#: estimate's.
_CALIBRATE_STAGES = {"process_chart": 0.6, "calibrate": 0.4}
_ESTIMATE_STAGES = {"process_sample": 0.8, "estimate": 0.2}


def calibrate_job(
    inputs: CalibrateInputs,
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    stages: Stages | None = None,
) -> CalibrationResult:
    """Process the chart session, calibrate (with the self-check) and write
    ``calibration/`` (:func:`record_calibration`)."""
    from tunespec.devices.registry import layout_reflectances

    t0 = time.monotonic()
    stages = stages or Stages(progress, _CALIBRATE_STAGES)
    ref_xyz = None
    if inputs.check_extraction and inputs.reflectances is not None:
        from tunespec.app.pipeline.extract import reference_xyz

        layout = inputs.layout or Session.open(inputs.chart_dir).layout
        ref_xyz = reference_xyz(layout, inputs.reflectances)
    chart = stages.timed(
        "process_chart",
        lambda p: _process_session(
            inputs.chart_dir,
            inputs.layout,
            inputs.corners,
            reference_xyz=ref_xyz,
            progress=p,
            should_stop=should_stop,
        ),
    )
    refl = inputs.reflectances
    if refl is None:
        refl = layout_reflectances(inputs.layout or chart.layout, grid=inputs.grid)
    cal = stages.timed(
        "calibrate",
        lambda p: calibrate(
            chart,
            refl,
            method=inputs.method,
            grid=inputs.grid,
            check=True,
            checks=Checks(force=inputs.force, force_hint=inputs.force_hint),
            progress=p,
            should_stop=should_stop,
        ),
    )
    return record_calibration(
        inputs.chart_dir,
        inputs.out_dir,
        cal,
        chart,
        threshold=inputs.threshold,
        elapsed_s=time.monotonic() - t0,
    )


def record_calibration(
    chart_dir: Path,
    out_dir: Path,
    cal: Calibration,
    chart: Any,
    *,
    threshold: float,
    elapsed_s: float = 0.0,
) -> CalibrationResult:
    """The calibration's result written, once for every front end: its warnings
    (the chart's capture and processing, the patches left out, the self-check's
    findings, the checks accepted with ``force``, which the calibration keeps) and
    the session's fingerprint with it."""
    excluded = tuple(cal.estimate.excluded_patches)
    forced = cal.estimate.provenance.get("forced", ())
    result = CalibrationResult.from_step(
        cal,
        chart,
        threshold=threshold,
        warnings=step_warnings(chart_dir, chart, excluded)
        + tuple(f"{_FORCED} {f}" for f in forced),
        elapsed_s=elapsed_s,
    )
    write_calibration(out_dir, result, session_fingerprint(chart_dir))
    return result


def predicted_table1(
    responses: Any,
    sensitivity: Spectra,
    illuminants: Spectra,
    chart: Spectra,
    meta: Mapping[str, Any],
) -> Any:
    """Table 1 of sensitivities on a chart (``tunespec report --chart``): the
    responses Eq. 1 predicts from ``sensitivity`` under ``illuminants`` corrected as
    the calibration found (``meta``, its side file) against the measured ones; all
    on one grid."""
    from tunespec.core.calibration import (
        correct_illuminants_from_meta,
        linearise_from_meta,
        predict_responses,
    )
    from tunespec.core.stats import prediction_stats

    illum = correct_illuminants_from_meta(illuminants, meta)
    predicted = predict_responses(sensitivity, illum, chart)
    return prediction_stats(linearise_from_meta(responses, meta).rgb, predicted.rgb)


def sensitivity_methods() -> tuple[tuple[str, ...], str]:
    """The sensitivity methods and the library's default one (the wizard's choice)."""
    import inspect

    from tunespec.core.sensitivity import (
        SENSITIVITY_METHODS,
        estimate_camera_sensitivity,
    )

    default = (
        inspect.signature(estimate_camera_sensitivity).parameters["method"].default
    )
    return tuple(SENSITIVITY_METHODS), str(default)


def find_session_corners(session_dir: Path, layout: TargetLayout) -> Any:
    """Processing's own corner detection on a session
    (``core.processing.find_session_corners``): ``(found, target frame)``."""
    from tunespec.core.processing import find_session_corners as find

    return find(Session.open(session_dir), layout)


# -- estimate --------------------------------------------------------------------------
@dataclass(frozen=True)
class EstimateInputs:
    """The estimate step of a measurement folder.

    Parameters
    ----------
    sample_dir, out_dir
        The sample's session and where the estimate goes (``estimate/``).
    sensitivity
        The calibration's sensitivities (its corrections in ``meta``).
    layout, corners
        As :class:`CalibrateInputs`'s.
    reference
        Reference reflectances (Table 2 of the patches they name).
    calibration
        The ``SensitivityEstimate`` (with a covariance: standard uncertainties).
    prior, grid
        The Wiener prior (``None``: the ColorChecker SG) and the reflectances' grid.
    force, force_hint
        Keep responses the plausibility checks refuse, and the option a refusal
        names.
    """

    sample_dir: Path
    out_dir: Path
    sensitivity: Spectra
    layout: TargetLayout | None = None
    corners: str = "auto"
    reference: Spectra | None = None
    calibration: Any = None
    prior: Spectra | None = None
    grid: Grid = ESTIMATION_GRID
    force: bool = False
    force_hint: str = "--force"


def reference_and_table2(
    reflectance: Spectra, reference: Spectra | None
) -> tuple[Spectra | None, Any]:
    """The reference of the estimated patches it names and their Table 2
    (``None, None`` when it names none)."""
    if reference is None:
        return None, None
    names = [n for n in reflectance.names if n in reference.names]
    if not names:
        return None, None
    ref = reference.select(names)
    return ref, evaluate(reflectance.select(names), ref)


def estimate_job(
    inputs: EstimateInputs,
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    stages: Stages | None = None,
) -> EstimateResult:
    """Process the sample session, estimate its reflectances (Table 2 against the
    reference) and write ``estimate/`` (:func:`record_estimate`)."""
    t0 = time.monotonic()
    stages = stages or Stages(progress, _ESTIMATE_STAGES)
    sample = stages.timed(
        "process_sample",
        lambda p: _process_session(
            inputs.sample_dir,
            inputs.layout,
            inputs.corners,
            progress=p,
            should_stop=should_stop,
        ),
    )
    est: Estimation = stages.timed(
        "estimate",  # closed form: no progress to report
        lambda _p: estimate(
            sample,
            inputs.sensitivity,
            prior=inputs.prior,
            grid=inputs.grid,
            calibration=inputs.calibration,
            checks=Checks(force=inputs.force, force_hint=inputs.force_hint),
        ),
    )
    ref, table2 = reference_and_table2(est.reflectance, inputs.reference)
    est = replace(est, table2=table2)
    return record_estimate(
        inputs.sample_dir,
        inputs.out_dir,
        est,
        sample,
        reference=ref,
        elapsed_s=time.monotonic() - t0,
    )


def record_estimate(
    sample_dir: Path,
    out_dir: Path,
    est: Estimation,
    sample: Any,
    *,
    reference: Spectra | None,
    elapsed_s: float = 0.0,
) -> EstimateResult:
    """The estimate's result written, once for every front end: its warnings (the
    sample's capture and processing, the checks overridden) and the session's
    fingerprint with it."""
    warnings = (
        step_warnings(sample_dir, sample)
        + est.warnings
        + tuple(f"{_FORCED} {f}" for f in est.forced)
    )
    result = EstimateResult.from_step(
        est, sample, reference=reference, warnings=warnings, elapsed_s=elapsed_s
    )
    write_estimate(out_dir, result, session_fingerprint(sample_dir))
    return result


# -- export ----------------------------------------------------------------------------
@dataclass(frozen=True)
class ExportInputs:
    """The export step of a measurement folder.

    Parameters
    ----------
    out_dir, folder
        Where the exports go (``export/``) and the measurement folder.
    calibration, estimate
        The results (computed now, or restored from the folder).
    devices
        The sessions' devices (the report's provenance, the ``.ti3`` headers).
    provenance, input_files
        More for the report's provenance (``measurement.json`` is added).
    """

    out_dir: Path
    folder: Path
    calibration: CalibrationResult
    estimate: EstimateResult
    devices: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    provenance: Mapping[str, str] = field(default_factory=dict)
    input_files: Sequence[Path] = ()


def restore_calibration_steps(
    result_dir: Path, result: CalibrationResult, grid: Any = None
) -> tuple[Any, Calibration] | None:
    """The processed chart and the ``steps.Calibration`` of a restored result.

    Nothing is estimated again: the sensitivities, their covariance and LED
    corrections come from the files (``core.calibration.Calibration.load``),
    Table 1 is recomputed from them (``core.stats.calibration_report``). ``None``
    when the processed chart is not in ``result_dir``.
    """
    from dataclasses import replace

    from tunespec.core.calibration import Calibration as FileCalibration
    from tunespec.core.stats import calibration_report
    from tunespec.devices.registry import layout_reflectances

    chart = read_processed(result_dir, result.layout, result.warnings)
    if chart is None:
        return None
    csv = result_dir / "sensitivity.csv"
    est = FileCalibration.load(csv)
    # the sensitivities as restored (with the SPD shift in their meta) and what the
    # CSV cannot say: the method and the patches the fit left out
    est = replace(
        est,
        sensitivity=result.sensitivity,
        method=result.method,
        excluded_patches=result.excluded_patches,
    )
    work = grid or CALIBRATION_GRID
    refl = layout_reflectances(result.layout, grid=work).resample(work)
    illum = chart.illuminants.resample(work, average=True)
    rep = calibration_report(est, chart.responses, illum, refl)
    per_patch = table1_by_patch(est, chart.responses, illum, refl)
    return chart, Calibration(est, rep, per_patch, self_check=result.self_check)


def export_job(
    inputs: ExportInputs,
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> ExportResult:
    """Write every export and the report (``steps.export``).

    Results restored from disk lack the processed sessions: they are read back
    from beside the results (only the closed-form Wiener estimate is computed
    again, from the same numbers), or, for a folder of an older version,
    processed again from the sessions with the corners used then.
    """
    from tunespec.app.pipeline.record import read_record
    from tunespec.devices.registry import layout_reflectances

    folder, calibration, estimated = inputs.folder, inputs.calibration, inputs.estimate
    chart, cal = calibration.chart, calibration.calibration
    if (chart is None or cal is None) and (
        restored := restore_calibration_steps(folder / CALIBRATION_DIR, calibration)
    ) is not None:
        chart, cal = restored
    if chart is None or cal is None:  # a folder of an older version: process again
        chart = _process_session(
            folder / CHART_DIR, calibration.layout, "editor", should_stop=should_stop
        )
        cal = calibrate(
            chart,
            layout_reflectances(calibration.layout, grid=CALIBRATION_GRID),
            method=calibration.method,
            should_stop=should_stop,
        )
    report(progress, 0.3)
    sample, est = estimated.sample, estimated.estimation
    if sample is None or est is None:
        assert estimated.layout is not None
        sample = read_processed(
            folder / ESTIMATE_DIR, estimated.layout, estimated.warnings
        ) or _process_session(
            folder / SAMPLE_DIR, estimated.layout, "editor", should_stop=should_stop
        )
        est = estimate(sample, cal.sensitivity, reference=None)
        est = replace(est, table2=estimated.table2)
    report(progress, 0.5)
    check_stop(should_stop)
    files = export(
        inputs.out_dir,
        calibration=cal,
        estimation=est,
        chart=chart,
        sample=sample,
        # the exports need a reference for every patch; Table 2 may cover fewer
        reference=(
            estimated.reference
            if estimated.reference is not None
            and set(estimated.reflectance.names) <= set(estimated.reference.names)
            else None
        ),
        devices={k: dict(v) for k, v in inputs.devices.items()},
        settings={
            "sensitivity method": calibration.method,
            "estimation grid": est.grid_text,
            "Table 1 threshold (RGB mean)": f"{calibration.threshold:g}",
            "chart corners": chart.corners_source,
            "sample corners": sample.corners_source,
        },
        warnings=(
            *(f"chart: {w}" for w in calibration.warnings),
            *(f"sample: {w}" for w in estimated.warnings),
        ),
        provenance={
            "measurement folder": str(Path(folder).resolve()),
            **inputs.provenance,
        },
        sessions={"chart": folder / CHART_DIR, "sample": folder / SAMPLE_DIR},
        input_files=[folder / MEASUREMENT_FILE, *inputs.input_files],
        threshold_rgb_mean=calibration.threshold,
        record=read_record(folder),  # the "Measurement record..." dialog's fields
    )
    report(progress, 1.0)
    return ExportResult({k: Path(p) for k, p in files.items()}, Path(inputs.out_dir))
