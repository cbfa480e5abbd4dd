"""One measurement folder layout, the same for ``tunespec run``/``demo`` and the GUI.

::

    OUT/
      measurement.json  what a front end needs to resume (layouts, capture options,
                        method, threshold): :func:`write_measurement_doc`
      chart/            the chart's capture session (``core.io.session``)
      sample/           the sample target's session
      calibration/      sensitivities and Table 1 (:func:`write_calibration`)
      estimate/         reflectances, their references, Table 2 (:func:`write_estimate`)
      export/           every export and the report, whoever ran the export step
                        (``tunespec run``/``demo`` or the GUI wizard);
                        ``exports.json`` lists them (:func:`write_exports_index`)
      truth/            a simulated bench's truth (``tunespec run``/``demo``)
      summary.json      the headline numbers and Tables 1-2 (``tunespec run``/``demo``)

Folders written before the exports moved under ``export/`` (``tunespec run``/``demo``
put them at the root) still open and resume: the exports are not an input of any
step, so the wizard and ``tunespec run`` simply write them again under ``export/``.

Every path of a measurement is named here once, and every result has one writer and
one reader here: a measurement taken by the CLI opens in the GUI wizard (its
calibration and estimate restore there) and the CLI resumes the wizard's sessions.
Results store the fingerprint of the session they came from, so a result whose frames
were retaken since is recognised as stale.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from tunespec.core.errors import InputError
from tunespec.core.io.export import read_sensitivity_meta, write_sensitivities_csv
from tunespec.core.io.session import MANIFEST_NAME, atomic_write_text
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import dumps_json, read_json
from tunespec.core.spectra import Spectra
from tunespec.core.verdict import calibration_verdict

__all__ = [
    "CALIBRATION_DIR",
    "CHART_DIR",
    "DEFAULT_THRESHOLD_RGB_MEAN",
    "ESTIMATE_DIR",
    "EXPORT_DIR",
    "MEASUREMENT_FILE",
    "MEASUREMENT_FORMAT",
    "SAMPLE_DIR",
    "CalibrationResult",
    "EstimateResult",
    "ExportResult",
    "MeasurementFolder",
    "add_capture_warnings",
    "clear_capture_warnings",
    "read_calibration",
    "read_capture_warnings",
    "read_estimate",
    "read_exports_index",
    "read_measurement_doc",
    "self_check_dict",
    "session_fingerprint",
    "step_warnings",
    "write_calibration",
    "write_estimate",
    "write_exports_index",
    "write_measurement_doc",
]

log = logging.getLogger(__name__)

MEASUREMENT_FILE = "measurement.json"
MEASUREMENT_FORMAT = "tunespec-measurement"
CHART_DIR, SAMPLE_DIR = "chart", "sample"
CALIBRATION_DIR, ESTIMATE_DIR, EXPORT_DIR = "calibration", "estimate", "export"
#: The warnings of a session's capture, beside its manifest: a capture that is
#: resumed does not meter again, so a weak LED would otherwise be forgotten.
CAPTURE_WARNINGS_FILE = "capture_warnings.json"
#: The index of the export step's files in ``export/``: export kind -> file name.
EXPORTS_INDEX_FILE = "exports.json"
#: The report's chart comparison (``app.pipeline.chart_choice``) in ``export/``.
CHART_CHOICE_FILE = "chart_choice.json"
#: Pass/fail limit on Table 1's RGB mean (full scale) when none is chosen.
DEFAULT_THRESHOLD_RGB_MEAN = 0.005


# -- results ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """The calibrate step: sensitivities and Table 1.

    Parameters
    ----------
    sensitivity : Spectra R, G, B
        Estimated sensitivities (absolute scale).
    table1 : PredictionStats
        Response prediction error on the fitted patches.
    threshold
        Pass/fail limit on Table 1's RGB mean (full scale).
    method
        Estimation method.
    layout
        The chart layout with the corners used (mosaic pixels).
    excluded_patches
        Patches left out of the fit (saturated).
    warnings
        Processing notes and the self-check's findings (``self-check: ...``).
    elapsed_s
        Wall time of processing and estimation.
    self_check
        The self-check's ``as_dict()`` (:mod:`tunespec.core.selfcheck`), or ``None``
        when it did not run.
    calibration, chart
        ``pipeline.Calibration`` and the processed chart session; ``None`` when the
        result was restored from disk (the export step recomputes them).
    """

    sensitivity: Spectra
    table1: Any
    threshold: float
    method: str
    layout: TargetLayout
    excluded_patches: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    elapsed_s: float = 0.0
    calibration: Any = None
    chart: Any = None
    self_check: Mapping[str, Any] | None = None

    @classmethod
    def from_step(
        cls,
        cal: Any,
        chart: Any,
        *,
        threshold: float,
        warnings: tuple[str, ...],
        elapsed_s: float = 0.0,
    ) -> CalibrationResult:
        """The result of the calibrate step: ``cal`` (``steps.Calibration``) of the
        processed ``chart``; the self-check's findings join ``warnings``."""
        from tunespec.core.selfcheck import finding_lines

        checked = self_check_dict(getattr(cal, "self_check", None))
        found = () if checked is None else tuple(checked.get("warnings", ()))
        return cls(
            sensitivity=cal.sensitivity,
            table1=cal.table1,
            threshold=float(threshold),
            method=str(cal.estimate.method),
            layout=chart.layout,
            excluded_patches=tuple(cal.estimate.excluded_patches),
            warnings=(*warnings, *finding_lines(found)),
            elapsed_s=elapsed_s,
            calibration=cal,
            chart=chart,
            self_check=checked,
        )

    @property
    def verdict(self) -> str:
        """``"PASS"``, ``"PASS with warnings"`` or ``"FAIL"``: the report's rule
        (:func:`tunespec.core.verdict.calibration_verdict`), so the wizard, the CLI
        and the report agree; :attr:`verdict_reason` says why."""
        return self.verdict_reason[0]

    @property
    def verdict_reason(self) -> tuple[str, str]:
        """``(verdict, why)``: Table 1, the left-out patches and the self-check."""
        return calibration_verdict(self.rgb_mean, self.threshold, self.self_check)

    @property
    def rgb_mean(self) -> float:
        """Table 1's RGB mean, the number compared with :attr:`threshold`."""
        return float(self.table1.mean[3])

    @property
    def passed(self) -> bool:
        """Whether Table 1's RGB mean is within the threshold."""
        return self.rgb_mean <= self.threshold


@dataclass(frozen=True, eq=False)
class EstimateResult:
    """The estimate step: reflectances and, with references, Table 2.

    Parameters
    ----------
    reflectance : Spectra
        Estimated reflectances named by patch.
    table2 : ReflectanceStats or None
        Deviation from the references.
    reference : Spectra or None
        The references of the estimated patches.
    layout
        The sample layout with the corners used.
    clipped
        Patches whose estimate was clipped to [0, 1].
    warnings
        Processing notes.
    elapsed_s
        Wall time.
    estimation, sample
        ``pipeline.Estimation`` and the processed sample session; ``None`` when
        restored from disk.
    """

    reflectance: Spectra
    table2: Any = None
    reference: Spectra | None = None
    layout: TargetLayout | None = None
    clipped: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    elapsed_s: float = 0.0
    estimation: Any = None
    sample: Any = None

    @classmethod
    def from_step(
        cls,
        est: Any,
        sample: Any,
        *,
        reference: Spectra | None,
        warnings: tuple[str, ...],
        elapsed_s: float = 0.0,
    ) -> EstimateResult:
        """The result of the estimate step: ``est`` (``steps.Estimation``) of the
        processed ``sample``, with the ``reference`` of its patches (Table 2)."""
        return cls(
            reflectance=est.reflectance,
            table2=est.table2,
            reference=reference,
            layout=sample.layout,
            clipped=tuple(est.wiener.clipped),
            warnings=warnings,
            elapsed_s=elapsed_s,
            estimation=est,
            sample=sample,
        )


@dataclass(frozen=True)
class ExportResult:
    """The export step: export kind -> file."""

    paths: dict[str, Path] = field(default_factory=dict)
    folder: Path | None = None


# -- the folder ------------------------------------------------------------------------
@dataclass(frozen=True)
class MeasurementFolder:
    """The paths of one measurement below ``root``."""

    root: Path

    @classmethod
    def at(cls, root: str | PathLike[str]) -> MeasurementFolder:
        """The folder at ``root`` (nothing is created)."""
        return cls(Path(root))

    def session_dir(self, which: str) -> Path:
        """The capture session of ``which`` (``"chart"`` or ``"sample"``)."""
        if which not in (CHART_DIR, SAMPLE_DIR):
            raise ValueError(f"unknown session {which!r}")
        return self.root / which

    @property
    def chart_dir(self) -> Path:
        return self.root / CHART_DIR

    @property
    def sample_dir(self) -> Path:
        return self.root / SAMPLE_DIR

    @property
    def calibration_dir(self) -> Path:
        return self.root / CALIBRATION_DIR

    @property
    def estimate_dir(self) -> Path:
        return self.root / ESTIMATE_DIR

    @property
    def export_dir(self) -> Path:
        return self.root / EXPORT_DIR

    @property
    def truth_dir(self) -> Path:
        return self.root / "truth"

    @property
    def summary_path(self) -> Path:
        return self.root / "summary.json"

    @property
    def measurement_path(self) -> Path:
        return self.root / MEASUREMENT_FILE

    def has_session(self, which: str) -> bool:
        """Whether a capture of ``which`` was started here."""
        return (self.session_dir(which) / MANIFEST_NAME).is_file()

    def write_summary(self, summary: dict[str, Any]) -> Path:
        """Write ``summary.json`` atomically (standard JSON, never NaN)."""
        self.root.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self.summary_path, dumps_json(summary))
        return self.summary_path


def write_measurement_doc(
    folder: MeasurementFolder,
    *,
    chart_layout: TargetLayout,
    sample_layout: TargetLayout,
    capture: dict[str, Any],
    method: str | None,
    threshold_rgb_mean: float = DEFAULT_THRESHOLD_RGB_MEAN,
    reference_path: str | PathLike[str] | None = None,
) -> Path:
    """Write ``measurement.json`` atomically: what a front end needs to resume."""
    doc = {
        "format": MEASUREMENT_FORMAT,
        "version": 1,
        "chart_layout": chart_layout.to_dict(),
        "sample_layout": sample_layout.to_dict(),
        "capture": dict(capture),
        "method": method,
        "threshold_rgb_mean": threshold_rgb_mean,
        "reference_path": str(reference_path) if reference_path else None,
    }
    folder.root.mkdir(parents=True, exist_ok=True)
    atomic_write_text(folder.measurement_path, dumps_json(doc, indent=1))
    return folder.measurement_path


def read_measurement_doc(folder: MeasurementFolder) -> dict[str, Any]:
    """``measurement.json`` as :func:`write_measurement_doc` wrote it.

    Raises
    ------
    InputError
        No such file, or not a measurement file.
    """
    path = folder.measurement_path
    if not path.exists():
        raise InputError(
            f"not a TuneSpec measurement (no {MEASUREMENT_FILE})", path=folder.root
        )
    doc = read_json(path)
    if not isinstance(doc, dict) or doc.get("format") != MEASUREMENT_FORMAT:
        raise InputError(
            f"not a measurement file (format != {MEASUREMENT_FORMAT!r})", path=path
        )
    return doc


def measurement_reference(
    folder: MeasurementFolder, value: Any, *, allowed: Any = None
) -> Path | None:
    """The reference file ``measurement.json`` names (``reference_path``), held to
    the rule of files named in project files: inside the measurement folder (a
    relative path, no link out), or the file the operator chose on this computer
    (``allowed``, the front end's own remembered choice). Anything else is not read:
    a folder received from someone else cannot make TuneSpec open ``/etc/shadow``.
    """
    from tunespec.core.limits import contained_path

    if not value or not isinstance(value, str):
        return None
    if allowed and str(allowed) == value:
        return Path(value)
    try:
        found = contained_path(
            value, "reference_path", bases=(folder.root,), path=folder.measurement_path
        )
    except InputError:
        return None
    return found[0]


# -- warnings ----------------------------------------------------------------------------
def read_capture_warnings(session_dir: str | PathLike[str]) -> tuple[str, ...]:
    """Every warning the captures of the session at ``session_dir`` raised so far."""
    path = Path(session_dir) / CAPTURE_WARNINGS_FILE
    if not path.is_file():
        return ()
    try:
        doc = read_json(path)
    except InputError as exc:
        log.warning("cannot read the capture warnings: %s", exc)
        return ()
    items = doc.get("warnings", []) if isinstance(doc, dict) else []
    return tuple(str(w) for w in items if isinstance(w, str))


def add_capture_warnings(
    session_dir: str | PathLike[str], warnings: Sequence[str]
) -> tuple[str, ...]:
    """Add ``warnings`` (each once) to the session's store; returns them all."""
    known = read_capture_warnings(session_dir)
    new = [w for w in dict.fromkeys(warnings) if w not in known]
    if not new:
        return known
    out = (*known, *new)
    path = Path(session_dir) / CAPTURE_WARNINGS_FILE
    atomic_write_text(path, dumps_json({"warnings": list(out)}, indent=1))
    return out


def clear_capture_warnings(session_dir: str | PathLike[str]) -> None:
    """Forget the warnings of an earlier capture (a new session starts here)."""
    (Path(session_dir) / CAPTURE_WARNINGS_FILE).unlink(missing_ok=True)


def step_warnings(
    session_dir: str | PathLike[str],
    processed: Any,
    excluded_patches: Sequence[str] = (),
) -> tuple[str, ...]:
    """What a calibrate or estimate step reports: its session's capture warnings,
    the processing's and the patches the calibration left out, each once."""
    capture = (f"capture: {w}" for w in read_capture_warnings(session_dir))
    found = getattr(processed, "warnings", ())
    excluded = (
        [f"calibration left out {len(excluded_patches)} saturated patch(es)"]
        if excluded_patches
        else []
    )
    return tuple(dict.fromkeys((*capture, *found, *excluded)))


def self_check_dict(check: Any) -> dict[str, Any] | None:
    """A calibration's self-check as its JSON form: a
    :class:`~tunespec.core.selfcheck.SelfCheck`'s ``as_dict()``, a mapping (read
    back from ``calibration.json``) as it is, anything else ``None``."""
    if check is None:
        return None
    if isinstance(check, Mapping):
        return dict(check)
    return check.as_dict() if hasattr(check, "as_dict") else None


# -- one writer and one reader per result ----------------------------------------------
def session_fingerprint(session_root: Path) -> str | None:
    """The session's :meth:`~tunespec.core.io.session.Session.fingerprint` (None: none)."""
    from tunespec.core.io.session import Session

    try:
        return Session.open(session_root).fingerprint()
    except InputError:
        return None


def _is_current(doc: dict[str, object], session_root: Path, what: str) -> bool:
    """False (with a log line) if the session changed since ``doc`` was computed."""
    saved = doc.get("session_fingerprint")
    if saved is None or saved == session_fingerprint(session_root):
        return True
    log.warning(
        "the %s was computed from frames that have since been retaken: run it again",
        what,
    )
    return False


def own_file(folder: Path, name: str) -> Path:
    """``folder / name``, a result file of the measurement folder: a plain name, and
    neither it nor ``folder`` a link (a folder received from someone else could
    point a result at any file; the writers replace such links).

    Raises
    ------
    InputError
        Naming the file.
    """
    path = Path(folder) / name
    if (
        not name
        or Path(name).name != name
        or name in (".", "..")
        or path.is_symlink()
        or Path(folder).is_symlink()
    ):
        raise InputError(
            "a link or a path out of the measurement folder: not read", path=path
        )
    return path


def write_calibration(
    out_dir: Path, result: CalibrationResult, fingerprint: str | None = None
) -> None:
    from tunespec.core.io.session import atomic_write_text

    out_dir.mkdir(parents=True, exist_ok=True)
    # with the fitted SPD shift (and the covariance) beside it, which the CSV cannot
    # hold (pipeline.estimate and the export need them)
    covariance = getattr(
        getattr(result.calibration, "estimate", None), "covariance", None
    )
    write_sensitivities_csv(out_dir / "sensitivity.csv", result.sensitivity, covariance)
    if result.chart is not None:
        _write_processed(out_dir, result.chart)
    doc = {
        "table1": result.table1.as_dict(),
        "threshold_rgb_mean": result.threshold,
        "passed": result.passed,
        "method": result.method,
        "layout": result.layout.to_dict(),
        "excluded_patches": list(result.excluded_patches),
        "warnings": list(result.warnings),
        "session_fingerprint": fingerprint,
    }
    if result.self_check is not None:
        doc["self_check"] = dict(result.self_check)
    # written last: its presence marks the step done
    atomic_write_text(out_dir / "calibration.json", dumps_json(doc, indent=1))


def read_calibration(folder: Path, chart_root: Path) -> CalibrationResult | None:
    from tunespec.core.stats import STAT_ROWS, PredictionStats

    try:
        doc = read_json(own_file(folder, "calibration.json"))
        if not _is_current(doc, chart_root, "calibration"):
            return None
        own_file(folder, "sensitivity.csv.meta.json")
        csv = own_file(folder, "sensitivity.csv")
        sensitivity = read_spectra_csv(csv, allow_negative=True)
        side = read_sensitivity_meta(csv)
        extra = {"spd_shift_nm": repr(side.get("spd_shift_nm", 0.0))}
        if "led_correction" in side:
            extra["led_correction"] = json.dumps(side["led_correction"])
        sensitivity = Spectra(
            sensitivity.wavelength_nm,
            sensitivity.values,
            sensitivity.names,
            {**sensitivity.meta, **extra},
        )
        t = doc["table1"]
        table1 = PredictionStats(
            mean=np.array([t[r]["mean"] for r in STAT_ROWS]),
            max=np.array([t[r]["max"] for r in STAT_ROWS]),
            p95=np.array([t[r]["p95"] for r in STAT_ROWS]),
            n_stimuli=int(t["n_stimuli"]),
        )
        return CalibrationResult(
            sensitivity=sensitivity,
            table1=table1,
            threshold=float(doc["threshold_rgb_mean"]),
            method=str(doc["method"]),
            layout=TargetLayout.from_dict(doc["layout"]),
            excluded_patches=tuple(doc.get("excluded_patches", ())),
            warnings=tuple(doc.get("warnings", ())),
            self_check=self_check_dict(doc.get("self_check")),
        )
    except (OSError, ValueError, KeyError, InputError) as exc:
        log.warning("no usable calibration in %s: %s", folder, exc)
        return None


def write_estimate(
    out_dir: Path, result: EstimateResult, fingerprint: str | None = None
) -> None:
    from tunespec.core.io.session import atomic_write_text

    out_dir.mkdir(parents=True, exist_ok=True)
    write_spectra_csv(result.reflectance, out_dir / "reflectance.csv")
    if result.sample is not None:
        _write_processed(out_dir, result.sample)
    if result.reference is not None:
        write_spectra_csv(result.reference, out_dir / "reference.csv")
    doc = {
        "layout": None if result.layout is None else result.layout.to_dict(),
        "clipped": list(result.clipped),
        "warnings": list(result.warnings),
        "session_fingerprint": fingerprint,
    }
    atomic_write_text(out_dir / "estimate.json", dumps_json(doc, indent=1))


def read_estimate(folder: Path, sample_root: Path) -> EstimateResult | None:
    from tunespec.core.colorimetry import reflectance_stats  # scipy-free, but heavy

    try:
        doc = read_json(own_file(folder, "estimate.json"))
        if not _is_current(doc, sample_root, "estimate"):
            return None
        reflectance = read_spectra_csv(own_file(folder, "reflectance.csv"))
        reference = None
        if own_file(folder, "reference.csv").is_file():
            reference = read_spectra_csv(folder / "reference.csv")
        table2 = (
            None
            if reference is None
            else reflectance_stats(reflectance.select(reference.names), reference)
        )
        layout = doc.get("layout")
        return EstimateResult(
            reflectance=reflectance,
            table2=table2,
            reference=reference,
            layout=None if layout is None else TargetLayout.from_dict(layout),
            clipped=tuple(doc.get("clipped", ())),
            warnings=tuple(doc.get("warnings", ())),
        )
    except (OSError, ValueError, KeyError, InputError) as exc:
        log.warning("no usable estimate in %s: %s", folder, exc)
        return None


def write_exports_index(out_dir: Path, files: Mapping[str, Path]) -> Path:
    """Write ``exports.json`` (export kind -> file name) atomically, last: its
    presence marks the export step done."""
    index = Path(out_dir) / EXPORTS_INDEX_FILE
    names = {k: Path(p).name for k, p in files.items()}
    atomic_write_text(index, dumps_json(names, indent=1))
    return index


def read_exports_index(out_dir: Path) -> dict[str, Path] | None:
    """The exports :func:`write_exports_index` listed in ``out_dir``; ``None`` when
    there is no index, it is unreadable, or a file it lists is missing."""
    index = Path(out_dir) / EXPORTS_INDEX_FILE
    if not index.is_file():
        return None
    try:
        doc = read_json(own_file(Path(out_dir), EXPORTS_INDEX_FILE))
        paths = {str(k): own_file(Path(out_dir), str(v)) for k, v in doc.items()}
    except (InputError, AttributeError, TypeError) as exc:
        log.warning("no usable exports in %s: %s", out_dir, exc)
        return None
    if not all(p.is_file() for p in paths.values()):
        return None
    return paths


# -- the processed sessions beside a result (the export needs no raw frame again) ------
PROCESSED_FILES = ("responses.csv", "illuminants.csv")


def _write_processed(out_dir: Path, processed: Any) -> None:
    from tunespec.app.pipeline.processing import write_processed

    write_processed(processed, *(out_dir / name for name in PROCESSED_FILES))


def read_processed(
    result_dir: Path, layout: TargetLayout, warnings: tuple[str, ...] = ()
) -> Any:
    """The processed session a calibrate or estimate step left in ``result_dir``.

    The corners are the layout's (``corners_source = "layout"``), as they were used.
    Returns ``None`` when the files are not there (a folder of an older version).
    """
    from tunespec.core.io.responses_csv import read_responses_csv
    from tunespec.core.processing import ProcessedSession

    try:
        responses_csv, illuminants_csv = (
            own_file(result_dir, n) for n in PROCESSED_FILES
        )
    except InputError:
        return None  # done again, and the links replaced
    if not (responses_csv.is_file() and illuminants_csv.is_file()):
        return None
    return ProcessedSession(
        responses=read_responses_csv(responses_csv),
        illuminants=read_spectra_csv(illuminants_csv),
        layout=layout,
        corners_source="layout",
        warnings=warnings,
    )
