"""The whole measurement as steps the CLI and the GUI wizard share, and the demo.

Steps (each usable on its own, each with ``progress``/``should_stop`` where it takes
time):

1. :func:`capture_chart` - the ColorChecker SG under every LED (dark, white, target);
2. :func:`process` - dark, flat field (Eq. 2), corners, ROI statistics -> responses
   and illuminants (measured SPD x exposure);
3. :func:`calibrate` - camera sensitivities (``core.sensitivity``) and Table 1;
4. :func:`capture_sample` - the sample target the same way;
5. :func:`estimate` - Wiener reflectances (Eq. 5-6, the SG as prior) and, with a
   reference, Table 2 (:func:`evaluate`);
6. :func:`export` - CSV, rawtoaces JSON, Argyll ``.ti3`` and the HTML/PDF report.

:func:`run_demo` runs them all on the simulated bench (no hardware, no network) and
compares with the bench's truth; :func:`run_config` runs them from a JSON or TOML
configuration on any bench, resuming sessions that already exist.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tunespec.core.colorimetry import ReflectanceStats, reflectance_stats
from tunespec.core.datasets import load_colorchecker_sg, resource_path
from tunespec.core.errors import InputError
from tunespec.core.export import (
    export_measurement,
    write_colorimetry_csv,
    write_sensitivity_meta,
)
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import (
    check_output_dir,
    dumps_json,
    loads_json,
    loads_toml,
    read_text,
    shown,
    valid_number,
    valid_seed,
)
from tunespec.core.processing import ProcessedSession, process_session, write_processed
from tunespec.core.progress import ProgressFn, StopFn, report
from tunespec.core.session import Session, atomic_write_text
from tunespec.core.spectra import (
    DEFAULT_GRID,
    Grid,
    Spectra,
    read_spectra_csv,
    write_spectra_csv,
)
from tunespec.devices.capture import FrameCallback, capture, new_session
from tunespec.devices.registry import (
    DEFAULT_SIM_RESOLUTION,
    Bench,
    layout_reflectances,
    open_bench,
    parse_resolution,
    sim_scene,
)

#: Sensitivity methods a configuration may name (``core.sensitivity.SENSITIVITY_METHODS``
#: without importing scipy; tests/test_cli_startup.py keeps them equal).
METHOD_CHOICES = ("bayes", "pca", "smooth")

if TYPE_CHECKING:
    # the estimators import scipy (a third of a second): imported where they run,
    # so that loading a configuration (and failing on it) answers at once
    from tunespec.core.sensitivity import SensitivityEstimate
    from tunespec.core.stats import CalibrationReport, PredictionStats
    from tunespec.core.uncertainty import ReflectanceUncertainty
    from tunespec.core.wiener import WienerEstimate

__all__ = [
    "DEMO_RESOLUTION",
    "ESTIMATION_GRID",
    "Calibration",
    "DemoResult",
    "Estimation",
    "RunResult",
    "bench_for_target",
    "calibrate",
    "capture_chart",
    "capture_sample",
    "capture_target",
    "chart_layout",
    "check_config",
    "estimate",
    "evaluate",
    "export",
    "load_config",
    "process",
    "run_config",
    "run_demo",
    "sample_layout",
    "sample_reference",
]

#: Default resolution of ``tunespec demo``: a quarter of the 5D Mark III's sides.
DEMO_RESOLUTION = DEFAULT_SIM_RESOLUTION
#: Grid of reflectance estimation and Table 2: the band the 22 LEDs cover (410-700 nm
#: peaks) and CIE colorimetry needs. Outside it no LED carries information and a
#: reflectance is only the prior's extrapolation, so the spectral RMS there measures
#: the prior, not the instrument. Sensitivities are still estimated on the working
#: grid (``DEFAULT_GRID``) for the exports.
ESTIMATION_GRID = Grid(400.0, 700.0, 5.0)


def chart_layout() -> TargetLayout:
    """The shipped ColorChecker SG layout (corners unknown: found in the images)."""
    return TargetLayout.load(resource_path("layouts", "colorchecker_sg.json"))


def sample_layout() -> TargetLayout:
    """The shipped sample target: the eight CMY Neugebauer primaries."""
    return TargetLayout.load(resource_path("layouts", "neugebauer_cmy.json"))


def sample_reference(grid: Grid = DEFAULT_GRID) -> Spectra:
    """Reference reflectances of the shipped sample target (the simulation's truth)."""
    return read_spectra_csv(resource_path("charts", "neugebauer_cmy_model.csv"), grid)


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
    """

    estimate: SensitivityEstimate
    report: CalibrationReport

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

    @property
    def reflectance(self) -> Spectra:
        return self.wiener.reflectance


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
        if self.table2 is not None:
            out["table2_delta_e00_mean"] = self.table2.mean_delta_e00
            out["table2_delta_e00_max"] = self.table2.max_delta_e00
            out["table2_spectral_rms_mean"] = self.table2.mean_spectral_rms
            out["table2"] = self.table2.as_dict()
        out.update(self.truth)  # plain floats, per session or channel
        return out

    def format_text(self) -> str:
        """Table 1 and Table 2 as the terminal shows them."""
        parts = [self.table1.format_table("Table 1 - ColorChecker SG, RGB prediction")]
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
    same = bench.stage.bench_options()  # type: ignore[attr-defined]
    scene = sim_scene(layout, reflectances, **same)
    camera = bench.camera.looking_at(scene, seed=seed)  # type: ignore[attr-defined]
    return Bench(bench.light, camera, scene, camera.truth())  # type: ignore[attr-defined]


def capture_target(
    bench: Bench,
    session_dir: str | PathLike[str],
    layout: TargetLayout,
    *,
    exposure: str | float | Mapping[str, float] = "auto",
    iso: int = 100,
    brackets: Sequence[float] = (1.0,),
    n_darks: int = 1,
    resume: bool = True,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    on_frame: FrameCallback | None = None,
) -> tuple[Session, tuple[str, ...]]:
    """Capture (or resume) one session of ``layout`` on ``bench``.

    Returns
    -------
    (session, warnings)
    """
    root = Path(session_dir)
    if (root / "manifest.json").is_file():
        if not resume:
            raise InputError("a session already exists here", path=root)
        session = Session.open(root)
        if session.layout is None:
            session.set_layout(layout.with_corners(None))
    else:
        session = new_session(
            root,
            bench.light,
            bench.camera,
            layout=layout.with_corners(None),
            exposure=exposure,
            iso=iso,
            brackets=brackets,
            n_darks=n_darks,
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
    **kwargs: Any,
) -> ProcessedSession:
    """:func:`tunespec.core.processing.process_session`; with ``out_dir``, also write
    the ``responses.csv`` and ``illuminants.csv`` that calibrate/estimate read."""
    processed = process_session(
        session, progress=progress, should_stop=should_stop, **kwargs
    )
    if out_dir is not None:
        out = Path(out_dir)
        write_processed(processed, out / "responses.csv", out / "illuminants.csv")
    return processed


def calibrate(
    chart: ProcessedSession,
    reflectances: Spectra | None = None,
    *,
    method: str | None = None,
    grid: Grid = DEFAULT_GRID,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    **options: Any,
) -> Calibration:
    """Camera sensitivities from the chart's responses (``core.sensitivity``) + Table 1.

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
    est = estimate_camera_sensitivity(
        chart.responses,
        illum,
        refl,
        progress=progress,
        should_stop=should_stop,
        **options,
    )
    rep = calibration_report(est, chart.responses, illum, refl)
    return Calibration(est, rep)


def estimate(
    sample: ProcessedSession,
    sensitivity: Spectra,
    *,
    prior: Spectra | None = None,
    reference: Spectra | None = None,
    grid: Grid = ESTIMATION_GRID,
    spd_shift_nm: float | None = None,
    calibration: SensitivityEstimate | None = None,
) -> Estimation:
    """Wiener reflectances of the sample (Eq. 5-6; prior default: the SG) and Table 2.

    ``spd_shift_nm`` is the spectroradiometer's wavelength shift fitted at calibration
    (``SensitivityEstimate.spd_shift_nm``); the sample's SPDs come from the same
    instrument, so it is undone on them too. ``None`` takes it from
    ``sensitivity.meta`` (the per-LED corrections of a ``"bayes"`` calibration, else
    its common shift; :func:`~tunespec.core.sensitivity.correct_illuminants_from_meta`).
    With ``calibration`` carrying a covariance, the standard uncertainties of the
    reflectances and their CIELAB are computed too (:mod:`tunespec.core.uncertainty`).
    """
    from tunespec.core.sensitivity import correct_illuminants_from_meta
    from tunespec.core.uncertainty import reflectance_uncertainty
    from tunespec.core.wiener import wiener_reflectance

    prior = prior if prior is not None else load_colorchecker_sg(grid)
    illuminants = correct_illuminants_from_meta(
        sample.illuminants, sensitivity.meta, spd_shift_nm
    )
    est = wiener_reflectance(
        sample.responses,
        illuminants.resample(grid, average=True),
        sensitivity.resample(grid),
        prior.resample(grid),
    )
    table2 = None if reference is None else evaluate(est.reflectance, reference)
    unc = None
    if calibration is not None and calibration.covariance is not None:
        unc = reflectance_uncertainty(
            est, sample.responses, sample.illuminants, calibration, prior.resample(grid)
        )
    return Estimation(est, table2, unc)


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
) -> dict[str, Path]:
    """Write every export (``core.export``) and, if asked, the HTML/PDF report.

    Files: the chart's ``chart_responses.csv`` / ``chart_illuminants.csv``, the
    ``core.export`` set (sensitivities, reflectances, the sample's responses and
    illuminants, Tables 1-2, ``.ti3``) and ``report.html`` / ``report.pdf``.
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
        )
    )
    if calibration.estimate.covariance is not None:
        write_sensitivity_meta(
            files["sensitivities_csv"],
            calibration.sensitivity,
            calibration.estimate.covariance,
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
        from tunespec.core.report import ReportData, write_report

        data = ReportData(
            title="TuneSpec measurement report",
            devices={k: dict(v) for k, v in (devices or {}).items()},
            settings=dict(settings or {}),
            illuminants=sample.illuminants,
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
            flags=tuple(warnings),
            exports={k: p.name for k, p in files.items()},
        )
        html, pdf = write_report(out, data)
        files["report_html"], files["report_pdf"] = html, pdf
    return files


# -- orchestration ---------------------------------------------------------------------
class _Stages:
    """Splits one progress callback over weighted stages."""

    def __init__(
        self, progress: ProgressFn | None, weights: Mapping[str, float]
    ) -> None:
        self._progress = progress
        total = sum(weights.values())
        self._start: dict[str, float] = {}
        self._width: dict[str, float] = {}
        acc = 0.0
        for name, w in weights.items():
            self._start[name] = acc / total
            self._width[name] = w / total
            acc += w
        self.timings_s: dict[str, float] = {}

    def __call__(self, name: str) -> ProgressFn:
        start, width = self._start[name], self._width[name]

        def fn(fraction: float) -> None:
            report(self._progress, start + width * fraction)

        return fn

    def timed(self, name: str, func: Callable[[ProgressFn], Any]) -> Any:
        t0 = time.perf_counter()
        try:
            return func(self(name))
        finally:
            self.timings_s[name] = time.perf_counter() - t0
            report(self._progress, self._start[name] + self._width[name])


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

    cam = bench.camera
    width, height = cam.resolution  # type: ignore[attr-defined]
    r0, r1, c0, c1 = flat_window((height // 2, width // 2))
    yy, xx = np.mgrid[r0:r1, c0:c1]
    xy = np.stack([2.0 * xx + 0.5, 2.0 * yy + 0.5], axis=-1)
    shading = float(np.mean(cam.shading(xy)))  # type: ignore[attr-defined]
    absolute = bench.truth["absolute_sensitivity"].resample(grid)
    return absolute.with_values(absolute.values * shading)


def _relative_rms(estimated: Spectra, truth: Spectra) -> dict[str, float]:
    out = {}
    for name in ("R", "G", "B"):
        t = truth[name]
        e = np.interp(truth.wavelength_nm, estimated.wavelength_nm, estimated[name])
        out[name] = float(np.sqrt(np.mean((e - t) ** 2)) / np.max(t))
    return out


def _run(
    bench: Bench,
    out: Path,
    *,
    chart_layout_: TargetLayout,
    chart_reflectances: Spectra | None,
    sample_layout_: TargetLayout,
    sample_reflectances: Spectra | None,
    reference: Spectra | None,
    exposure: str | float | Mapping[str, float],
    brackets: Sequence[float],
    iso: int,
    seed: int,
    method: str | None,
    prior: Spectra | None,
    grid: Grid,
    estimation_grid: Grid,
    report_files: bool,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
    on_frame: FrameCallback | None,
) -> RunResult:
    stages = _Stages(progress, _STAGE_WEIGHTS)
    warnings: list[str] = []
    # a simulated bench is opened showing the chart; hardware shows what the
    # operator puts there (the stage asks)
    chart_bench = bench

    def capturing(
        which: str, on: Bench, layout: TargetLayout, exposure_: Any
    ) -> Callable[[ProgressFn], Session]:
        def run(p: ProgressFn) -> Session:
            s, w = capture_target(
                on,
                out / which,
                layout,
                exposure=exposure_,
                brackets=brackets,
                iso=iso,
                progress=p,
                should_stop=should_stop,
                on_frame=on_frame,
            )
            warnings.extend(f"{which} capture: {x}" for x in w)
            return s

        return run

    chart_session: Session = stages.timed(
        "capture_chart", capturing("chart", chart_bench, chart_layout_, exposure)
    )
    chart: ProcessedSession = stages.timed(
        "process_chart",
        lambda p: process(
            chart_session, out_dir=None, progress=p, should_stop=should_stop
        ),
    )
    warnings.extend(f"chart: {w}" for w in chart.warnings)
    cal: Calibration = stages.timed(
        "calibrate",
        lambda p: calibrate(
            chart,
            chart_reflectances,
            method=method,
            grid=grid,
            progress=p,
            should_stop=should_stop,
        ),
    )
    if cal.estimate.excluded_patches:
        warnings.append(
            f"calibration left out {len(cal.estimate.excluded_patches)} saturated "
            "patch(es)"
        )
    sample_bench = bench_for_target(
        bench, sample_layout_, sample_reflectances, seed=seed + 1
    )
    # the same board and LEDs: the chart's metered exposures suit the sample too
    chart_exposures = {c: t[0] for c, t in chart_session.settings.exposures_s.items()}

    sample_session: Session = stages.timed(
        "capture_sample",
        capturing(
            "sample",
            sample_bench,
            sample_layout_,
            chart_exposures if exposure == "auto" else exposure,
        ),
    )
    sample: ProcessedSession = stages.timed(
        "process_sample",
        lambda p: process(sample_session, progress=p, should_stop=should_stop),
    )
    warnings.extend(f"sample: {w}" for w in sample.warnings)
    est: Estimation = stages.timed(
        "estimate",
        lambda p: estimate(
            sample,
            cal.sensitivity,
            prior=prior,
            reference=reference,
            grid=estimation_grid,
            calibration=cal.estimate,
        ),
    )
    truth: dict[str, Any] = {}
    truth_sens = None
    if bench.simulated:
        truth_sens = _true_sensitivity(chart_bench, grid)
        truth["sensitivity_rel_rms"] = _relative_rms(cal.sensitivity, truth_sens)
        truth["corner_error_px"] = {
            "chart": _corner_error_px(chart_bench, chart),
            "sample": _corner_error_px(sample_bench, sample),
        }
        chart_bench.camera.write_truth(out / "truth")  # type: ignore[attr-defined]
    files: dict[str, Path] = stages.timed(
        "export",
        lambda p: export(
            out,
            calibration=cal,
            estimation=est,
            chart=chart,
            sample=sample,
            reference=reference,
            truth_sensitivity=truth_sens,
            devices=chart_session.devices,
            settings={
                "calibration grid": str(grid),
                "estimation grid": str(estimation_grid),
                "sensitivity method": str(cal.estimate.method),
                "exposure": str(exposure),
                "chart corners": chart.corners_source,
                "sample corners": sample.corners_source,
            },
            warnings=warnings,
            report=report_files,
        ),
    )
    if sample_bench is not bench:
        sample_bench.camera.close()
    result = RunResult(
        out_dir=out,
        calibration=cal,
        estimation=est,
        chart=chart,
        sample=sample,
        files=files,
        timings_s=dict(stages.timings_s),
        warnings=tuple(warnings),
        truth=truth,
    )
    summary = out / "summary.json"
    atomic_write_text(summary, dumps_json(result.summary()))
    files["summary_json"] = summary
    report(progress, 1.0)
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
) -> RunResult:
    """The full measurement on the simulated bench, compared with its truth.

    Captures the ColorChecker SG under all 22 LEDs, processes it, calibrates the
    camera (Table 1), captures the CMY Neugebauer sample target, estimates its
    reflectances with the SG as prior and compares them with the truth (Table 2), and
    writes the exports and the report into ``out_dir``. Re-running on the same folder
    resumes the sessions there.

    Parameters
    ----------
    out_dir
        Output folder (sessions ``chart/`` and ``sample/``, exports, report).
    progress, should_stop
        Hooks over the whole run.
    seed
        Seeds the simulated light source and cameras.
    resolution
        Simulated camera ``(width, height)``.
    report_files
        Also write the HTML/PDF report.
    on_frame
        Called after every captured frame (live view).
    """
    out = Path(out_dir)
    t0 = time.perf_counter()
    with open_bench("sim", resolution=resolution, seed=seed) as bench:
        result = _run(
            bench,
            out,
            chart_layout_=chart_layout(),
            chart_reflectances=None,
            sample_layout_=sample_layout(),
            sample_reflectances=sample_reference(),
            reference=sample_reference(),
            exposure="auto",
            brackets=(1.0,),
            iso=100,
            seed=seed,
            method=None,
            prior=None,
            grid=DEFAULT_GRID,
            estimation_grid=ESTIMATION_GRID,
            report_files=report_files,
            progress=progress,
            should_stop=should_stop,
            on_frame=on_frame,
        )
    result.timings_s["total"] = time.perf_counter() - t0
    return result


# -- configuration-driven runs ---------------------------------------------------------
def load_config(path: str | PathLike[str]) -> dict[str, Any]:
    """Read a run configuration (``.json`` or ``.toml``).

    Keys (all optional)::

        out = "run"                          # output folder, relative to the file
        [bench]    light = "sim", camera = "sim", resolution = "1536x1024", seed = 0
        [capture]  exposure = "auto" | seconds, brackets = [1.0], iso = 100
        [chart]    layout = FILE (default the SG), reflectances = FILE
        [sample]   layout = FILE (default the CMY target), reflectances = FILE,
                   reference = FILE (for Table 2)
        [calibrate] method = "smooth", grid = "380:730:5"
        [estimate] prior = FILE (default the SG), grid = "400:700:5"
        [export]   report = true

    Raises
    ------
    InputError
        Unreadable file, bad syntax, unknown sections or keys.
    """
    path = Path(path)
    text = read_text(path)
    if path.suffix.lower() == ".toml":
        cfg = loads_toml(text, path=path)
    else:
        cfg = loads_json(text, path=path)
    if not isinstance(cfg, dict):
        raise InputError("expected a table/object at the top", path=path)
    known = {
        "out": None,
        "bench": {"light", "camera", "resolution", "seed"},
        "capture": {"exposure", "brackets", "iso"},
        "chart": {"layout", "reflectances"},
        "sample": {"layout", "reflectances", "reference"},
        "calibrate": {"method", "grid"},
        "estimate": {"prior", "grid"},
        "export": {"report"},
    }
    for key, value in cfg.items():
        if key not in known:
            raise InputError(
                f"unknown section {shown(key)} (known: {', '.join(known)})", path=path
            )
        allowed = known[key]
        if allowed is not None:
            if not isinstance(value, dict):
                raise InputError(f"{key}: expected a table/object", path=path)
            bad = set(value) - allowed
            if bad:
                raise InputError(
                    f"{key}: unknown key(s) {', '.join(sorted(bad))} (known: "
                    f"{', '.join(sorted(allowed))})",
                    path=path,
                )
    cfg["_path"] = str(path)
    return cfg


def run_config(
    config: Mapping[str, Any] | str | PathLike[str],
    *,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    prompt: Callable[[str], None] | None = None,
    on_frame: FrameCallback | None = None,
) -> RunResult:
    """Capture -> process -> calibrate -> estimate -> export, from a configuration.

    Paths in the configuration are relative to its file. Sessions that already exist
    in the output folder are resumed, so a run interrupted by a crash continues where
    it stopped.
    """
    cfg = dict(config) if isinstance(config, Mapping) else load_config(config)
    base = Path(cfg.get("_path", ".")).parent if "_path" in cfg else Path(".")
    check_config(cfg)

    def rel(p: str | None) -> Path | None:
        return None if p is None else (base / p)

    bench_cfg = cfg.get("bench", {})
    cap = cfg.get("capture", {})
    cal_cfg = cfg.get("calibrate", {})
    grid = Grid.parse(cal_cfg["grid"]) if "grid" in cal_cfg else DEFAULT_GRID
    est_cfg = cfg.get("estimate", {})
    est_grid = Grid.parse(est_cfg["grid"]) if "grid" in est_cfg else ESTIMATION_GRID
    chart_cfg, sample_cfg = cfg.get("chart", {}), cfg.get("sample", {})
    chart_path = rel(chart_cfg.get("layout"))
    sample_path = rel(sample_cfg.get("layout"))
    c_layout = TargetLayout.load(chart_path) if chart_path else chart_layout()
    s_layout = TargetLayout.load(sample_path) if sample_path else sample_layout()

    def spectra(p: str | None) -> Spectra | None:
        q = rel(p)
        return None if q is None else read_spectra_csv(q, grid)

    c_refl = spectra(chart_cfg.get("reflectances"))
    if c_refl is None and chart_path is not None:
        c_refl = layout_reflectances(c_layout, chart_path, grid)
    s_refl = spectra(sample_cfg.get("reflectances"))
    reference = spectra(sample_cfg.get("reference"))
    light = str(bench_cfg.get("light", "sim"))
    if reference is None and sample_path is None and light.startswith("sim"):
        reference = sample_reference(grid)
    if s_refl is None and light.startswith("sim"):
        s_refl = (
            layout_reflectances(s_layout, sample_path, grid)
            if sample_path
            else sample_reference(grid)
        )
    src = cfg.get("_path")
    exposure = cap.get("exposure", "auto")
    if not isinstance(exposure, str):
        exposure = _cfg_number(exposure, "capture.exposure", src)
    res = bench_cfg.get("resolution")
    resolution = None if res is None else parse_resolution(res)
    brackets = cap.get("brackets", [1.0])
    if not isinstance(brackets, list | tuple):
        raise InputError(
            f"capture.brackets: expected a list of numbers, got {shown(brackets)}",
            path=src,
        )
    seed = _cfg_int(bench_cfg.get("seed", 0), "bench.seed", src)
    out = base / str(cfg.get("out", "run"))
    t0 = time.perf_counter()
    with open_bench(
        light,
        bench_cfg.get("camera"),
        layout=c_layout,
        reflectances=c_refl,
        resolution=resolution,
        seed=seed,
        prompt=prompt,
    ) as bench:
        result = _run(
            bench,
            out,
            chart_layout_=c_layout,
            chart_reflectances=c_refl,
            sample_layout_=s_layout,
            sample_reflectances=s_refl,
            reference=reference,
            exposure=exposure,
            brackets=tuple(_cfg_number(b, "capture.brackets", src) for b in brackets),
            iso=_cfg_int(cap.get("iso", 100), "capture.iso", src),
            seed=seed,
            method=cal_cfg.get("method"),
            prior=spectra(cfg.get("estimate", {}).get("prior")),
            grid=grid,
            estimation_grid=est_grid,
            report_files=cfg.get("export", {}).get("report", True),
            progress=progress,
            should_stop=should_stop,
            on_frame=on_frame,
        )
    result.timings_s["total"] = time.perf_counter() - t0
    return result


def _cfg_number(value: Any, key: str, source: str | None) -> float:
    """A configuration value that must be a number (one-line error otherwise)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{key}: expected a number, got {shown(value)}", path=source)
    return float(value)


def _cfg_int(value: Any, key: str, source: str | None) -> int:
    """A configuration value that must be an integer (one-line error otherwise)."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{key}: expected an integer, got {shown(value)}", path=source)
    return value


#: Configuration keys whose values are text (paths, specs, grids, names).
_CONFIG_STRINGS = {
    "bench": ("light", "camera", "resolution"),
    "chart": ("layout", "reflectances"),
    "sample": ("layout", "reflectances", "reference"),
    "calibrate": ("method", "grid"),
    "estimate": ("prior", "grid"),
}


def check_config(cfg: Mapping[str, Any]) -> None:
    """Check every value of a configuration before anything runs.

    Raises
    ------
    InputError
        Naming the file and the key: a section that is not a table, a text key that
        is not text, a bad seed, resolution, exposure, bracket, ISO, method or grid,
        or an ``out`` that is an existing file.
    """
    src = cfg.get("_path")
    for section, keys in _CONFIG_STRINGS.items():
        table = cfg.get(section, {})
        if not isinstance(table, Mapping):
            raise InputError(f"{section}: expected a table/object", path=src)
        for key in keys:
            value = table.get(key)
            if value is not None and not isinstance(value, str):
                raise InputError(
                    f"{section}.{key}: expected a string, got {shown(value)}", path=src
                )
    out = cfg.get("out", "run")
    if not isinstance(out, str | PathLike):
        raise InputError(f"out: expected a folder name, got {shown(out)}", path=src)
    base = Path(src).parent if src else Path(".")
    try:
        check_output_dir(base / out, "out")
    except InputError as exc:
        raise InputError(exc.message, path=src) from None
    # every value checked before anything is captured (a typo must not cost a chart)
    bench = cfg.get("bench", {})
    valid_seed(bench.get("seed", 0), "bench.seed", path=src)
    if bench.get("resolution") is not None:
        try:
            parse_resolution(bench["resolution"])
        except InputError as exc:
            raise InputError(f"bench.resolution: {exc.message}", path=src) from None
    cap = cfg.get("capture", {})
    if not isinstance(cap, Mapping):
        raise InputError("capture: expected a table/object", path=src)
    exposure = cap.get("exposure", "auto")
    if isinstance(exposure, str):
        if exposure != "auto":
            raise InputError(
                f'capture.exposure: expected "auto" or seconds, got {shown(exposure)}',
                path=src,
            )
    else:
        valid_number(exposure, "capture.exposure", path=src, lo=0, hi=1e4, lo_open=True)
    brackets = cap.get("brackets", [1.0])
    if not isinstance(brackets, list | tuple) or not 1 <= len(brackets) <= 16:
        raise InputError(
            f"capture.brackets: expected a list of 1 to 16 numbers, got {shown(brackets)}",
            path=src,
        )
    for b in brackets:
        valid_number(b, "capture.brackets", path=src, lo=0, hi=1, lo_open=True)
    valid_number(
        cap.get("iso", 100), "capture.iso", path=src, lo=1, hi=1e7, integer=True
    )
    method = cfg.get("calibrate", {}).get("method")
    if method is not None and method not in METHOD_CHOICES:
        raise InputError(
            f"calibrate.method: {shown(method)} is not one of "
            f"{', '.join(METHOD_CHOICES)}",
            path=src,
        )
    for section in ("calibrate", "estimate"):
        grid = cfg.get(section, {}).get("grid")
        if grid is not None:
            try:
                Grid.parse(grid)
            except InputError as exc:
                raise InputError(f"{section}.grid: {exc.message}", path=src) from None
    report_files = cfg.get("export", {}).get("report", True)
    if not isinstance(report_files, bool):
        raise InputError(
            f"export.report: expected true or false, got {shown(report_files)}",
            path=src,
        )
