"""``run(plan)``: the steps of a measurement in order, on one bench.

Like a bluesky plan run by its RunEngine: the :class:`~tunespec.app.pipeline.plan.Plan`
says what to do, :func:`run` opens the bench it names, runs the steps
(:mod:`tunespec.app.pipeline.steps`) with one progress bar split over them, scores a
simulated bench against its truth, and writes the measurement folder
(:class:`~tunespec.app.pipeline.folder.MeasurementFolder`). Sessions that already exist
in the folder are resumed, so a run interrupted by a crash continues where it stopped.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tunespec.app.pipeline.engine import connect
from tunespec.app.pipeline.folder import (
    CHART_CHOICE_FILE,
    DEFAULT_THRESHOLD_RGB_MEAN,
    MeasurementFolder,
    self_check_dict,
    write_measurement_doc,
)
from tunespec.app.pipeline.jobs import (
    CalibrateInputs,
    EstimateInputs,
    Stages,
    calibrate_job,
    estimate_job,
)
from tunespec.app.pipeline.plan import (
    DEMO_CHART_CHOICE,
    DEMO_RESOLUTION,
    Plan,
    demo_plan,
    plan_from_config,
)
from tunespec.app.pipeline.record import (
    MeasurementRecord,
    light_status_items,
    record_summary,
    update_record,
)
from tunespec.app.pipeline.steps import (
    Calibration,
    Estimation,
    bench_for_target,
    capture_target,
    export,
)
from tunespec.core.errors import InputError
from tunespec.core.io.session import Session
from tunespec.core.processing import ProcessedSession
from tunespec.core.progress import ProgressFn, StopFn, report
from tunespec.core.spectra import Grid, Spectra
from tunespec.core.verdict import calibration_verdict
from tunespec.devices.capture import FrameCallback
from tunespec.devices.registry import Bench, open_bench

if TYPE_CHECKING:
    from tunespec.core.colorimetry import ReflectanceStats
    from tunespec.core.stats import PredictionStats

__all__ = ["DemoResult", "RunResult", "run", "run_config", "run_demo"]


# -- results ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RunResult:
    """What a full run produced.

    Parameters
    ----------
    out_dir
        Where everything was written.
    calibration, estimation
        The step results.
    chart, sample
        Processed sessions (responses, illuminants, corners used).
    files
        Export kind -> path.
    timings_s
        Wall time per step.
    warnings
        Everything the steps warned about.
    truth
        For a simulated bench: ``corner_error_px`` per session and
        ``sensitivity_rel_rms`` (estimated vs. true, per channel).
    """

    out_dir: Path
    calibration: Calibration
    estimation: Estimation
    chart: ProcessedSession
    sample: ProcessedSession
    files: dict[str, Path] = field(default_factory=dict)
    timings_s: dict[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    truth: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def table1(self) -> PredictionStats:
        return self.calibration.table1

    @property
    def table2(self) -> ReflectanceStats | None:
        return self.estimation.table2

    def summary(self) -> dict[str, Any]:
        """The headline numbers and both tables, JSON-ready."""
        t1 = self.table1
        out: dict[str, Any] = {
            "table1_rgb_rms_mean": float(t1.mean[3]),
            "table1_rgb_rms_max": float(t1.max[3]),
            "table1_rgb_rms_p95": float(t1.p95[3]),
            "table1": t1.as_dict(),
            "sensitivity_method": str(self.calibration.estimate.method),
            "excluded_patches": list(self.calibration.estimate.excluded_patches),
            "timings_s": {k: round(v, 3) for k, v in self.timings_s.items()},
            "warnings": list(self.warnings),
        }
        checked = self_check_dict(self.calibration.self_check)
        if checked is not None:
            out["self_check"] = checked
        outcome, why = calibration_verdict(
            float(t1.mean[3]), DEFAULT_THRESHOLD_RGB_MEAN, checked
        )
        out["verdict"] = {"outcome": outcome, "why": why}
        if self.table2 is not None:
            out["table2_delta_e00_mean"] = self.table2.mean_delta_e00
            out["table2_delta_e00_max"] = self.table2.max_delta_e00
            out["table2_spectral_rms_mean"] = self.table2.mean_spectral_rms
            out["table2"] = self.table2.as_dict()
        out.update(self.truth)  # plain floats, per session or channel
        if self.provenance:  # the measurement record (app.pipeline.record)
            out["provenance"] = self.provenance
        return out

    def format_text(self) -> str:
        """Table 1 and Table 2 as the terminal shows them."""
        chart = self.chart.layout.name
        parts = [self.table1.format_table(f"Table 1 - {chart}, RGB prediction")]
        checked = self.calibration.self_check
        if checked is not None and hasattr(checked, "format_text"):
            parts.append(checked.format_text())
        if self.table2 is not None:
            parts.append(
                "Table 2 - sample target vs. reference (CIEDE2000 D50, spectral RMS)\n"
                + self.table2.format_table()
            )
        if "sensitivity_rel_rms" in self.truth:
            rr = self.truth["sensitivity_rel_rms"]
            parts.append(
                "Sensitivities vs. the bench's truth (relative RMS): "
                + ", ".join(f"{k} {v:.2%}" for k, v in rr.items())
            )
        if "corner_error_px" in self.truth:
            ce = self.truth["corner_error_px"]
            parts.append(
                "Automatic corners vs. truth (max, mosaic px): "
                + ", ".join(f"{k} {v:.2f}" for k, v in ce.items())
            )
        return "\n\n".join(parts)


#: The result of :func:`run_demo`.
DemoResult = RunResult


# -- orchestration ---------------------------------------------------------------------
#: How a refusal names the configuration's override.
_FORCE_HINT = "force = true in the configuration"
_STAGE_WEIGHTS = {
    "capture_chart": 30.0,
    "process_chart": 6.0,
    "calibrate": 6.0,
    "capture_sample": 25.0,
    "process_sample": 4.0,
    "estimate": 1.0,
    "export": 8.0,
}


def _corner_error_px(bench: Bench, processed: ProcessedSession) -> float:
    """Largest distance of the corners used from the simulated bench's true ones."""
    used = np.asarray(processed.layout.corners_px, dtype=np.float64)
    return float(np.max(np.abs(used - bench.truth["corners_px"])))


def _true_sensitivity(bench: Bench, grid: Grid) -> Spectra:
    """The sensitivity calibration should recover on this simulated bench.

    The flat field normalises every frame to the mean of the white frame's centre
    window (Eq. 2), so the responses carry the bench's shading (fall-off times
    vignetting) averaged over that window.
    """
    from tunespec.core.processing import flat_window

    cam = bench.sim_camera
    width, height = cam.resolution
    r0, r1, c0, c1 = flat_window((height // 2, width // 2))
    yy, xx = np.mgrid[r0:r1, c0:c1]
    xy = np.stack([2.0 * xx + 0.5, 2.0 * yy + 0.5], axis=-1)
    shading = float(np.mean(cam.shading(xy)))
    absolute = bench.truth["absolute_sensitivity"].resample(grid)
    return absolute.with_values(absolute.values * shading)


def _relative_rms(estimated: Spectra, truth: Spectra) -> dict[str, float]:
    out = {}
    for name in ("R", "G", "B"):
        t = truth[name]
        e = np.interp(truth.wavelength_nm, estimated.wavelength_nm, estimated[name])
        out[name] = float(np.sqrt(np.mean((e - t) ** 2)) / np.max(t))
    return out


def _score_truth(
    folder: MeasurementFolder,
    plan: Plan,
    benches: tuple[Bench, Bench],
    processed: tuple[ProcessedSession, ProcessedSession],
    cal: Calibration,
) -> tuple[dict[str, Any], Spectra | None]:
    """A simulated bench's truth: sensitivity and corner errors, ``truth/`` written."""
    chart_bench, sample_bench = benches
    if not chart_bench.simulated:
        return {}, None
    truth_sens = _true_sensitivity(chart_bench, plan.grid)
    truth: dict[str, Any] = {
        "sensitivity_rel_rms": _relative_rms(cal.sensitivity, truth_sens),
        "corner_error_px": {
            "chart": _corner_error_px(chart_bench, processed[0]),
            "sample": _corner_error_px(sample_bench, processed[1]),
        },
    }
    chart_bench.sim_camera.write_truth(folder.truth_dir)
    return truth, truth_sens


def _write_plan(folder: MeasurementFolder, plan: Plan) -> None:
    """``measurement.json`` first: an interrupted run opens and resumes in the GUI."""
    exposure = plan.exposure if isinstance(plan.exposure, str | float) else "auto"
    write_measurement_doc(
        folder,
        chart_layout=plan.chart_layout,
        sample_layout=plan.sample_layout,
        capture={
            "exposure": exposure,
            "iso": plan.iso,
            "n_darks": plan.n_darks,
            "repeats": plan.repeats,
        },
        method=plan.method,
    )


def _provenance(folder: MeasurementFolder, plan: Plan, bench: Bench) -> dict[str, str]:
    """The plan's choices the report's provenance lists."""
    out = {
        "measurement folder": str(folder.root.resolve()),
        "light source": plan.light,
        "camera": plan.camera or "default for the light source",
    }
    if bench.simulated:
        width, height = bench.sim_camera.resolution
        out["seed"] = str(plan.seed)
        out["resolution"] = f"{width}x{height}"
    return out


def _capture(
    folder: MeasurementFolder,
    plan: Plan,
    which: str,
    bench: Bench,
    exposure: Any,
    hooks: tuple[Stages, FrameCallback | None],
) -> Session:
    """Capture (or resume) one session of the measurement (``steps.capture_target``)."""
    stages, on_frame = hooks
    layout = plan.chart_layout if which == "chart" else plan.sample_layout

    def capturing(p: ProgressFn | None) -> Session:
        session, _ = capture_target(
            bench,
            folder.session_dir(which),
            layout,
            exposure=exposure,
            brackets=plan.brackets,
            repeats=plan.repeats,
            n_darks=plan.n_darks,
            iso=plan.iso,
            progress=p,
            should_stop=stages.should_stop,
            on_frame=on_frame,
        )
        return session

    session: Session = stages.timed(f"capture_{which}", capturing)
    return session


def _run_on(
    bench: Bench,
    plan: Plan,
    *,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
    on_frame: FrameCallback | None,
    scheduler: Any = None,
) -> RunResult:
    """Every step of ``plan`` on an open ``bench`` (the Dask steps on ``scheduler``)."""
    weights = {
        **_STAGE_WEIGHTS,
        **({"images": 20.0} if plan.images else {}),
        **({"chart choice": 90.0} if plan.chart_choice and plan.report else {}),
    }
    stages = Stages(progress, weights, should_stop)
    hooks = (stages, on_frame)
    folder = MeasurementFolder.at(plan.out_dir)
    _write_plan(folder, plan)
    record = update_record(folder.root, plan.record)
    light_state = light_status_items(bench.light)  # its warm-up, before capturing
    # a simulated bench is opened showing the chart; hardware shows what the
    # operator puts there (the stage asks)
    chart_session = _capture(folder, plan, "chart", bench, plan.exposure, hooks)
    # the chart's extraction is checked against its reference data too
    calibrated = calibrate_job(
        CalibrateInputs(
            folder.chart_dir,
            folder.calibration_dir,
            method=plan.method,
            threshold=DEFAULT_THRESHOLD_RGB_MEAN,
            reflectances=plan.chart_reflectances,
            check_extraction=plan.chart_reflectances is not None,
            grid=plan.grid,
            force=plan.force,
            force_hint=_FORCE_HINT,
        ),
        should_stop=should_stop,
        stages=stages,
    )
    cal: Calibration = calibrated.calibration
    chart: ProcessedSession = calibrated.chart
    sample_bench = bench_for_target(
        bench, plan.sample_layout, plan.sample_reflectances, seed=plan.seed + 1
    )
    # the same board and LEDs: the chart's metered exposures suit the sample too
    chart_exposures = {c: t[0] for c, t in chart_session.settings.exposures_s.items()}
    sample_exposure = chart_exposures if plan.exposure == "auto" else plan.exposure
    _capture(folder, plan, "sample", sample_bench, sample_exposure, hooks)
    estimated = estimate_job(
        EstimateInputs(
            folder.sample_dir,
            folder.estimate_dir,
            cal.sensitivity,
            reference=plan.reference,
            calibration=cal.estimate,
            prior=plan.prior,
            grid=plan.estimation_grid,
            force=plan.force,
            force_hint=_FORCE_HINT,
        ),
        should_stop=should_stop,
        stages=stages,
    )
    est: Estimation = estimated.estimation
    sample: ProcessedSession = estimated.sample
    warnings = (
        *(f"chart: {w}" for w in calibrated.warnings),
        *(f"sample: {w}" for w in estimated.warnings),
    )
    truth, truth_sens = _score_truth(
        folder, plan, (bench, sample_bench), (chart, sample), cal
    )
    settings = _settings(plan, cal, chart, sample, est)
    files = _export_step(
        folder,
        plan,
        stages,
        results=(cal, est, chart, sample),
        truth_sensitivity=truth_sens,
        devices=chart_session.devices,
        settings=settings,
        warnings=warnings,
        provenance={**_provenance(folder, plan, bench), **light_state},
        record=record,
    )
    if plan.images:
        files["images_provenance"] = stages.timed(
            "images", lambda p: _images(folder, plan, scheduler, p, should_stop)
        )
    if sample_bench is not bench:
        sample_bench.camera.close()
    result = RunResult(
        out_dir=folder.root,
        calibration=cal,
        estimation=est,
        chart=chart,
        sample=sample,
        files=files,
        timings_s=dict(stages.timings_s),
        warnings=warnings,
        truth=truth,
        provenance={
            **record_summary(
                record,
                chart_session.devices,
                chart_layout=chart.layout,
                settings=settings,
            ),
            "light_status": light_state,
        },
    )
    files["summary_json"] = folder.write_summary(result.summary())
    report(progress, 1.0)
    return result


def _settings(
    plan: Plan,
    cal: Calibration,
    chart: ProcessedSession,
    sample: ProcessedSession,
    est: Estimation,
) -> dict[str, str]:
    """The run's settings as the report and ``summary.json`` list them."""
    return {
        "calibration grid": str(plan.grid),
        "estimation grid": est.grid_text,
        "sensitivity method": str(cal.estimate.method),
        "exposure": str(plan.exposure),
        "chart corners": chart.corners_source,
        "sample corners": sample.corners_source,
    }


def _export_step(
    folder: MeasurementFolder,
    plan: Plan,
    stages: Stages,
    *,
    results: tuple[Calibration, Estimation, ProcessedSession, ProcessedSession],
    truth_sensitivity: Any,
    devices: Any,
    settings: dict[str, str],
    warnings: tuple[str, ...],
    provenance: dict[str, Any],
    record: Any,
) -> dict[str, Path]:
    """The chart choice (when asked for with a report) and the exports, timed."""
    cal, est, chart, sample = results
    choice = None
    if plan.chart_choice and plan.report:
        choice = stages.timed("chart choice", lambda p: _chart_choice(folder, plan, p))
    files: dict[str, Path] = stages.timed(
        "export",
        lambda p: export(
            folder.export_dir,
            calibration=cal,
            estimation=est,
            chart=chart,
            sample=sample,
            reference=plan.reference,
            truth_sensitivity=truth_sensitivity,
            devices=devices,
            settings=settings,
            warnings=warnings,
            report=plan.report,
            provenance=provenance,
            sessions={"chart": folder.chart_dir, "sample": folder.sample_dir},
            input_files=plan.input_files,
            threshold_rgb_mean=DEFAULT_THRESHOLD_RGB_MEAN,
            chart_reflectances=plan.chart_reflectances,
            chart_choice=choice,
            record=record,
        ),
    )
    return files


def _chart_choice(
    folder: MeasurementFolder, plan: Plan, progress: ProgressFn | None
) -> dict[str, Any]:
    """The report's chart comparison (:mod:`tunespec.app.pipeline.chart_choice`),
    kept in ``export/chart_choice.json``: read back when a resumed run finds it for
    the same charts and seed, else computed on benches of the plan's seed and
    resolution in a scratch folder that is removed again."""
    import shutil
    import tempfile

    from tunespec.app.pipeline.chart_choice import compare_charts, load_chart_comparison

    path = folder.export_dir / CHART_CHOICE_FILE
    if path.is_file():
        kept = load_chart_comparison(path)
        if kept.get("seed") == plan.seed and len(kept["scores"]) == len(
            plan.chart_choice
        ):
            return kept
    if plan.light != "sim":
        raise InputError("chart_choice compares charts on the simulated bench only")
    scratch = Path(tempfile.mkdtemp(prefix="chart-choice-", dir=folder.root))
    try:
        comparison = compare_charts(
            scratch, plan.chart_choice, seed=plan.seed,
            resolution=plan.resolution, progress=progress,
        )  # fmt: skip
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    folder.export_dir.mkdir(parents=True, exist_ok=True)
    comparison.save(path)
    return comparison.to_dict()


def _images(
    folder: MeasurementFolder,
    plan: Plan,
    scheduler: Any,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> Path:
    """The sample's per-pixel images (``app.pipeline.image``) in ``export/images/``,
    from the calibration just written, on ``scheduler`` (``engine.connect``'s);
    returns their ``provenance.json``."""
    from tunespec.app.pipeline.image import ImageSettings, estimate_images

    out = folder.export_dir / "images"
    estimate_images(
        folder.sample_dir,
        folder.calibration_dir / "sensitivity.csv",
        out,
        settings=ImageSettings(grid=plan.estimation_grid, force=plan.force),
        scheduler=scheduler,
        progress=progress,
        should_stop=should_stop,
    )
    return out / "provenance.json"


def run(
    plan: Plan,
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    prompt: Callable[[str], None] | None = None,
    on_frame: FrameCallback | None = None,
) -> RunResult:
    """Capture -> process -> calibrate -> capture sample -> estimate -> export.

    Opens the bench ``plan`` names, runs every step on it and closes it. Re-running
    the same plan resumes the sessions already in ``plan.out_dir``.

    Parameters
    ----------
    plan
        What to measure and how.
    progress, should_stop
        Hooks over the whole run.
    prompt
        For hardware: how to ask the operator to change the target.
    on_frame
        Called after every captured frame (live view).
    """
    t0 = time.perf_counter()
    # a cluster is connected to before anything is captured: a wrong or unreachable
    # address fails at once, not after the captures
    with (
        connect(plan.scheduler if plan.images else None) as scheduler,
        open_bench(
            plan.light,
            plan.camera,
            layout=plan.chart_layout,
            reflectances=plan.chart_reflectances,
            resolution=plan.resolution,
            seed=plan.seed,
            prompt=prompt,
        ) as bench,
    ):
        result = _run_on(
            bench,
            plan,
            progress=progress,
            should_stop=should_stop,
            on_frame=on_frame,
            scheduler=scheduler,
        )
    result.timings_s["total"] = time.perf_counter() - t0
    return result


def run_demo(
    out_dir: str | PathLike[str],
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    seed: int = 0,
    resolution: tuple[int, int] = DEMO_RESOLUTION,
    report_files: bool = True,
    on_frame: FrameCallback | None = None,
    chart_choice: bool = False,
    record: MeasurementRecord | None = None,
) -> RunResult:
    """The full measurement on the simulated bench, compared with its truth.

    ``run(demo_plan(...))``: captures the ColorChecker SG under all 22 LEDs,
    processes it, calibrates the camera (Table 1), captures the CMY Neugebauer sample
    target, estimates its reflectances with the SG as prior and compares them with
    the truth (Table 2), and writes the exports and the report into ``out_dir``.
    Re-running on the same folder resumes the sessions there. ``chart_choice``:
    the report also compares calibrating on a ColorChecker 24 with the SG
    (:data:`~tunespec.app.pipeline.plan.DEMO_CHART_CHOICE`, on benches of the same
    seed). ``record``: the operator's fields (``--operator``...) for the folder's
    measurement record.
    """
    plan = demo_plan(
        out_dir, seed=seed, resolution=resolution, report=report_files,
        chart_choice=DEMO_CHART_CHOICE if chart_choice else (), record=record,
    )  # fmt: skip
    return run(plan, progress=progress, should_stop=should_stop, on_frame=on_frame)


def run_config(
    config: Mapping[str, Any] | str | PathLike[str],
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    prompt: Callable[[str], None] | None = None,
    on_frame: FrameCallback | None = None,
    out: str | PathLike[str] | None = None,
    scheduler: str | None = None,
    record: MeasurementRecord | None = None,
) -> RunResult:
    """``run(plan_from_config(config))`` (``tunespec run CONFIG``); ``out`` and
    ``scheduler`` are the command line's ``--out`` and ``--scheduler``, ``record``
    its ``--operator``... (replacing the fields of ``[provenance]`` it gives)."""
    plan = plan_from_config(config, out=out, scheduler=scheduler)
    if record is not None:
        plan = replace(plan, record=plan.record.updated(record))
    return run(
        plan,
        progress=progress,
        should_stop=should_stop,
        prompt=prompt,
        on_frame=on_frame,
    )
