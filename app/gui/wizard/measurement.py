"""The measurement the wizard works on: its folder, sessions, results and jobs.

A measurement folder holds everything of one operator run::

    MEASUREMENT/
      measurement.json   what the wizard needs to resume (layouts, capture options)
      chart/             capture session of the chart (tunespec.core.io.session)
      sample/            capture session of the sample target
      calibration/       estimated sensitivities and Table 1 (calibrate step)
      estimate/          estimated reflectances and Table 2 (estimate step)
      export/            the exports and the report (export step)

The pages run the pipeline's jobs (:mod:`tunespec.app.pipeline.jobs`: calibrate,
estimate, export) off the GUI thread, and the capture job at the bottom on the
device thread: it drives ``pipeline.capture_target`` and adds what the page shows
(the phase's progress and time left, the frames, the SPDs). They return frozen
results; the pages store those in :class:`Measurement` on the GUI thread.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from PySide6.QtCore import QObject, Signal

from tunespec.app.gui.settings import AppSettings
from tunespec.app.gui.workers import DeviceContext, DeviceController
from tunespec.app.pipeline.folder import (
    CALIBRATION_DIR,
    CHART_DIR,
    ESTIMATE_DIR,
    EXPORT_DIR,
    MEASUREMENT_FILE,
    SAMPLE_DIR,
    CalibrationResult,
    EstimateResult,
    ExportResult,
    MeasurementFolder,
    measurement_reference,
    read_calibration,
    read_capture_warnings,
    read_estimate,
    read_exports_index,
    read_measurement_doc,
    write_measurement_doc,
)
from tunespec.core.datasets import resource_path
from tunespec.core.errors import InputError
from tunespec.core.io.cht import load_layout
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import dumps_json
from tunespec.core.progress import (
    Cancelled,
    ProgressFn,
    StopFn,
)
from tunespec.core.spectra import Spectra

__all__ = [  # the results and folder names are re-exported from app.pipeline.folder
    "CALIBRATION_DIR",
    "CHART_DIR",
    "ESTIMATE_DIR",
    "EXPORT_DIR",
    "MEASUREMENT_FILE",
    "SAMPLE_DIR",
    "CalibrationResult",
    "CaptureOptions",
    "EstimateResult",
    "ExportResult",
    "Measurement",
    "PhaseResult",
]

log = logging.getLogger(__name__)

#: Capture kinds in the order of the capture sequence (devices.capture).
PHASES = ("dark", "white", "target")


# -- results ---------------------------------------------------------------------------
@dataclass(frozen=True)
class CaptureOptions:
    """How the sessions are captured.

    Parameters
    ----------
    exposure
        ``"auto"`` (metered per LED on the white background) or seconds for all.
    iso
        ISO speed.
    n_darks
        Dark frames per distinct exposure.
    repeats
        Frames per LED, averaged (:func:`tunespec.devices.capture.new_session`).
    """

    exposure: str | float = "auto"
    iso: int = 100
    n_darks: int = 1
    repeats: int = 1

    def to_dict(self) -> dict[str, Any]:
        return {
            "exposure": self.exposure,
            "iso": self.iso,
            "n_darks": self.n_darks,
            "repeats": self.repeats,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CaptureOptions:
        """From :meth:`to_dict` (a malformed exposure falls back to ``"auto"``)."""
        exposure: str | float = "auto"
        with contextlib.suppress(TypeError, ValueError):
            exposure = float(d.get("exposure", "auto"))
        return cls(
            exposure,
            int(d.get("iso", 100)),
            int(d.get("n_darks", 1)),
            int(d.get("repeats", 1)),
        )


@dataclass(frozen=True)
class PhaseResult:
    """A capture step done.

    Parameters
    ----------
    kind
        ``"dark"``, ``"white"``, ``"target"`` or ``"all"`` (a whole session).
    captured
        Frame ids taken by this run.
    n_frames
        Frames of this kind the session now holds.
    warnings
        Notes from the capture (e.g. weak LEDs).
    elapsed_s
        Wall time of the run.
    """

    kind: str
    captured: tuple[str, ...]
    n_frames: int
    warnings: tuple[str, ...] = ()
    elapsed_s: float = 0.0

    def summary(self, noun: str, session: str = "session") -> str:
        """The line shown to the operator: ``"...; the {session} holds n {noun}."``."""
        text = (
            f"{len(self.captured)} frame(s) taken in {self.elapsed_s:.1f} s; the "
            f"{session} holds {self.n_frames} {noun}."
        )
        return text  # the warnings are in the page's badge


# -- the model --------------------------------------------------------------------------
class Measurement(QObject):
    """State shared by the wizard pages; lives on the GUI thread.

    Parameters
    ----------
    controller
        The device controller (device jobs run there).
    settings
        Persistent settings (capture options, layouts, thresholds).
    """

    #: The measurement folder changed: the new folder.
    folder_changed = Signal(object)
    #: A page wants the layout editor to edit this layout (chart or sample).
    layout_needed = Signal(object)
    #: Calibration finished or restored: the :class:`CalibrationResult`.
    calibrated = Signal(object)
    #: Estimate finished or restored: the :class:`EstimateResult`.
    estimated = Signal(object)
    #: A result is no longer valid (its inputs were retaken, or another measurement
    #: was opened): ``"calibration"``, ``"estimate"`` or ``"export"``.
    result_cleared = Signal(str)

    def __init__(
        self, controller: DeviceController, settings: AppSettings | None = None
    ) -> None:
        super().__init__()
        self.controller = controller
        self.settings = settings or AppSettings()
        self.folder: Path | None = None
        #: (folder, document) last written by :meth:`save`.
        self._saved: tuple[Path, str] | None = None
        self.chart_layout = _load_layout(
            self.settings.get("layout/chart_path"), "colorchecker_sg.json"
        )
        self.sample_layout = _load_layout(
            self.settings.get("layout/sample_path"), "neugebauer_cmy.json"
        )
        self.capture_options = CaptureOptions.from_dict(
            {
                "exposure": self.settings.get("capture/exposure"),
                "iso": self.settings.get("capture/iso"),
                "n_darks": self.settings.get("capture/n_darks"),
                "repeats": self.settings.get("capture/repeats"),
            }
        )
        self.method = self.settings.get("calibration/method")
        self.threshold = self.settings.get("calibration/threshold_rgb_mean")
        ref = self.settings.get("estimate/reference_path")
        self.reference_path: Path | None = Path(ref) if ref else None
        self.current_target = "chart"
        self.calibration: CalibrationResult | None = None
        self.estimate: EstimateResult | None = None
        self.export: ExportResult | None = None
        #: Opens the devices when the connect step runs (the main window sets it to
        #: its device panel's connect, so the specs chosen there are used).
        self.connector: Callable[[], None] = self._default_connect
        #: Asks the operator where measurements go (the wizard sets it to a folder
        #: dialog); ``None``: not chosen.
        self.folder_chooser: Callable[[], Path | None] = lambda: None
        self.sim_options: dict[str, Any] = {}

    # -- folder ---------------------------------------------------------------------
    def require_folder(self) -> Path:
        """The measurement folder; a fresh one if none is open.

        It goes into the folder where measurements go (``session/root_dir``); the
        first time, :attr:`folder_chooser` asks the operator for it, and it is
        remembered.

        Raises
        ------
        InputError
            The operator did not choose a folder.
        """
        if self.folder is None:
            root = self.settings.get("session/root_dir")
            if not root or not Path(root).is_dir():
                chosen = self.folder_chooser()
                if chosen is None:
                    raise InputError(
                        "no measurement folder: choose where measurements go "
                        "(New… or Open / resume…)"
                    )
                root = str(chosen)
                self.settings.set("session/root_dir", root)
            folder = Path(root) / f"measurement-{time.strftime('%Y%m%d-%H%M%S')}"
            n = 1
            while folder.exists():  # two within a second
                n += 1
                folder = folder.with_name(f"{folder.name.split('_')[0]}_{n}")
            self.new(folder)
        assert self.folder is not None
        return self.folder

    def new(self, folder: str | Path) -> None:
        """Start a new measurement in ``folder`` (empty or not yet existing)."""
        folder = Path(folder)
        if (folder / MEASUREMENT_FILE).exists():
            raise InputError(
                "a measurement already exists here: open it to resume", path=folder
            )
        if folder.exists() and any(folder.iterdir()):
            raise InputError(
                "the folder is not empty: choose an empty one", path=folder
            )
        folder.mkdir(parents=True, exist_ok=True)
        self.folder = folder
        self.forget_all()
        self.save()
        self.settings.remember_measurement(folder)
        log.info("new measurement in %s", folder)
        self.folder_changed.emit(folder)

    def open(self, folder: str | Path) -> None:
        """Reopen the measurement in ``folder`` (its pages then restore themselves)."""
        folder = Path(folder)
        doc = read_measurement_doc(MeasurementFolder(folder))
        path = folder / MEASUREMENT_FILE
        self.folder = folder
        self.chart_layout = TargetLayout.from_dict(
            doc["chart_layout"], source=str(path)
        )
        self.sample_layout = TargetLayout.from_dict(
            doc["sample_layout"], source=str(path)
        )
        self.capture_options = CaptureOptions.from_dict(doc.get("capture", {}))
        self.method = doc.get("method", self.method)
        self.threshold = float(doc.get("threshold_rgb_mean", self.threshold))
        # a reference outside the folder only from a measurement made or opened on
        # this computer before, or the operator's own last choice
        ref = doc.get("reference_path")
        known = str(folder.resolve()) in self.settings.get("session/recent").split("\n")
        self.reference_path = measurement_reference(
            MeasurementFolder(folder),
            ref,
            allowed=ref if known else self.settings.get("estimate/reference_path"),
        )
        self.forget_all()
        self.settings.remember_measurement(folder)
        self.folder_changed.emit(folder)
        self.layout_needed.emit(self.current_layout)

    def forget(self, which: str) -> None:
        """Drop the ``"calibration"``, ``"estimate"`` or ``"export"`` result (in
        memory only: a step whose inputs were retaken must be run again)."""
        if getattr(self, which) is not None:
            setattr(self, which, None)
            self.result_cleared.emit(which)

    def forget_all(self) -> None:
        """Drop every result (another measurement)."""
        for which in ("calibration", "estimate", "export"):
            self.forget(which)

    def save(self) -> None:
        """Write ``measurement.json`` (atomically), unless it holds this already.

        Every step saves when it starts; an unchanged document is not written again
        (the atomic write's fsyncs cost the GUI thread up to tens of ms on a busy
        disk).
        """
        if self.folder is None:
            return
        fields = {
            "chart_layout": self.chart_layout,
            "sample_layout": self.sample_layout,
            "capture": self.capture_options.to_dict(),
            "method": self.method,
            "threshold_rgb_mean": self.threshold,
            "reference_path": self.reference_path,
        }
        doc = {
            **fields,
            "chart_layout": self.chart_layout.to_dict(),
            "sample_layout": self.sample_layout.to_dict(),
            "reference_path": str(self.reference_path or ""),
        }
        key = (self.folder, dumps_json(doc))
        if key == self._saved and (self.folder / MEASUREMENT_FILE).is_file():
            return
        write_measurement_doc(MeasurementFolder(self.folder), **fields)
        self._saved = key

    def save_settings(self) -> None:
        """Remember the options for the next measurement."""
        s = self.settings
        s.set("capture/exposure", str(self.capture_options.exposure))
        s.set("capture/iso", self.capture_options.iso)
        s.set("capture/n_darks", self.capture_options.n_darks)
        s.set("capture/repeats", self.capture_options.repeats)
        s.set("calibration/method", self.method)
        s.set("calibration/threshold_rgb_mean", self.threshold)
        s.set("estimate/reference_path", str(self.reference_path or ""))

    def path(self, *parts: str) -> Path:
        """A path inside the measurement folder."""
        return self.require_folder().joinpath(*parts)

    # -- layouts --------------------------------------------------------------------
    @property
    def current_layout(self) -> TargetLayout:
        """The layout of the target in front of the camera now."""
        return (
            self.chart_layout if self.current_target == "chart" else self.sample_layout
        )

    def edit_target(self, which: str) -> None:
        """Make ``"chart"`` or ``"sample"`` the layout the editor edits."""
        if which != self.current_target:
            self.current_target = which
            self.layout_needed.emit(self.current_layout)

    def set_current_layout(self, target_layout: TargetLayout) -> None:
        """The editor changed the current target's layout.

        Kept in memory (a drag changes it many times a second); written with the
        measurement when a step starts or the window closes.
        """
        if self.current_target == "chart":
            self.chart_layout = target_layout
        else:
            self.sample_layout = target_layout

    # -- state on disk (for resume) -----------------------------------------------
    def session(self, which: str) -> Any:
        """The chart or sample session, or None if not started."""
        from tunespec.core.io.session import MANIFEST_NAME, Session

        if self.folder is None:
            return None
        root = self.folder / (CHART_DIR if which == "chart" else SAMPLE_DIR)
        return Session.open(root) if (root / MANIFEST_NAME).exists() else None

    def capture_warnings(self, which: str) -> tuple[str, ...]:
        """The warnings the captures of the chart or sample session raised."""
        if self.folder is None:
            return ()
        return read_capture_warnings(MeasurementFolder(self.folder).session_dir(which))

    def shorten_exposure(self, which: str = "chart") -> Path | None:
        """Put the ``which`` session aside (its frames are kept, renamed
        ``<session>.clipped-<time>``) and shorten the exposure of the next one: a
        fixed exposure to a quarter, a metered one metered again. Returns where
        the old session went (None if there was none)."""
        from dataclasses import replace

        root = self.path(CHART_DIR if which == "chart" else SAMPLE_DIR)
        moved = None
        if root.exists():
            moved = root.with_name(f"{root.name}.clipped-{time.strftime('%H%M%S')}")
            n = 1
            while moved.exists():
                n += 1
                moved = moved.with_name(f"{moved.name.split('_')[0]}_{n}")
            root.rename(moved)
            log.warning("%s session with clipped frames kept as %s", which, moved)
        opts = self.capture_options
        if opts.exposure != "auto":
            self.capture_options = replace(
                opts, exposure=max(0.001, round(float(opts.exposure) / 4, 4))
            )
        self.save()
        return moved

    def phase_complete(self, which: str, kind: str | None) -> bool:
        """Whether the session holds every frame of ``kind`` (None: every frame)."""
        session = self.session(which)
        if session is None or not session.settings.resolved:
            return False
        return not any(kind in (None, s.kind) for s in session.missing(verify=False))

    def restore_calibration(self) -> CalibrationResult | None:
        """The calibration saved in the folder, or None."""
        if self.folder is None:
            return None
        result = read_calibration(
            self.folder / CALIBRATION_DIR, self.folder / CHART_DIR
        )
        if result is not None:
            self.calibration = result
            self.calibrated.emit(result)
        return result

    def restore_estimate(self) -> EstimateResult | None:
        """The estimate saved in the folder, or None."""
        if self.folder is None:
            return None
        result = read_estimate(self.folder / ESTIMATE_DIR, self.folder / SAMPLE_DIR)
        if result is not None:
            self.estimate = result
            self.estimated.emit(result)
        return result

    def restore_export(self) -> ExportResult | None:
        """The exports in the folder, or None."""
        if self.folder is None:
            return None
        folder = self.folder / EXPORT_DIR
        paths = read_exports_index(folder)
        if paths is None:
            return None
        self.export = ExportResult(paths, folder)
        return self.export

    def reference(self) -> Spectra | None:
        """Reference reflectances for Table 2, or None.

        The operator's file if chosen; on the simulated bench the sample's true
        reflectances (what the simulated scene was built from).
        """
        if self.reference_path is not None:
            return read_spectra_csv(self.reference_path)
        session = self.session("sample")
        light = (session.devices if session is not None else {}).get("light", {})
        if light.get("vendor") == "TuneSpec":  # simulated bench: the truth is known
            from tunespec.devices.registry import layout_reflectances

            return layout_reflectances(self.sample_layout)
        return None

    # -- connecting -------------------------------------------------------------------
    def _default_connect(self) -> None:
        self.controller.open_devices("sim", "sim", **self.sim_options)


# -- jobs ----------------------------------------------------------------------------------
def _load_layout(path: str, shipped: str) -> TargetLayout:
    if path:
        try:
            return load_layout(path)
        except InputError as exc:
            log.warning(
                "cannot load the remembered layout, using the shipped one: %s", exc
            )
    return TargetLayout.load(resource_path("layouts", shipped))


def _levels_of(light: Any, channel: str | None) -> np.ndarray | None:
    names = [c.name for c in light.channels()]
    if channel not in names:
        return None
    levels = np.zeros(len(names))
    levels[names.index(channel)] = 1.0
    return levels


def _bench_showing(context: DeviceContext, target_layout: TargetLayout) -> Any:
    """The bench with ``target_layout`` in front of the camera.

    On hardware the operator places the target (the page told them, the stage asks);
    on the simulated bench ``pipeline.bench_for_target`` gives a camera looking at a
    scene of that target, which then becomes the controller's bench.
    """
    from tunespec.app.pipeline.jobs import bench_for_target

    bench = context.bench
    shown = getattr(bench.stage, "layout", None)
    if not bench.simulated or (shown is not None and shown.name == target_layout.name):
        return bench
    log.info("simulated bench: now showing %s", target_layout.name)
    seed = int(context.options.get("seed", 0)) + 1
    return context.replace_bench(bench_for_target(bench, target_layout, seed=seed))


def _frames_of(kind: str | None, n_channels: int, n_brackets: int, n_darks: int) -> int:
    """Frames of ``kind`` a session will hold before its exposures are known (an
    upper bound for the darks: one per LED exposure)."""
    lit = n_channels * n_brackets
    per_kind = {"dark": lit * n_darks, "white": lit, "target": lit}
    return per_kind[kind] if kind is not None else sum(per_kind.values())


#: The latest time a frame took beyond its exposure (s), seen by any capture of
#: this program: the first frames of the next phase are estimated with it.
_LAST_OVERHEAD_S: list[float] = []


class _PhaseProgress:
    """The progress and the time left of one capture phase: metering (while the
    exposures are unknown), then the frames of the phase.

    ``capture()`` reports one step per metered channel, then one per frame. The
    time left is taken from the exposures actually chosen (the session's, as soon
    as they are metered; the mean metered so far for the channels still to
    meter): every frame left costs its exposure (when the camera really waits it
    out: hardware, or the simulated bench in real time) plus what a frame took
    beyond its exposure so far, and every channel still to meter what metering one
    took so far. The fraction is the time elapsed over elapsed plus left, and
    never goes back; before any time is known, it counts steps (before metering
    the frames left are an upper bound, replaced by the real count from the
    session when the exposures are known).

    Parameters
    ----------
    waits
        Whether a frame takes its exposure time.
    remaining
        Called with the seconds left (NaN while unknown) after each step.
    session_now
        The session as it is on disk now (None before the first frame).
    """

    def __init__(
        self,
        kind: str | None,
        session: Any,
        n_channels: int,
        options: CaptureOptions,
        progress: ProgressFn | None,
        *,
        waits: bool = False,
        remaining: Callable[[float], None] | None = None,
        session_now: Callable[[], Any] | None = None,
    ) -> None:
        self._kind = kind
        self._progress = progress
        self._remaining = remaining
        self._session_now = session_now
        self._waits = bool(waits)
        self.done = 0
        self._last = 0.0
        self._t0 = self._t_stage = time.monotonic()
        self._frame_in_stage = False
        #: Seconds each metered channel took; seconds beyond the exposure a frame took.
        self.meter_s: list[float] = []
        self.overhead_s: list[float] = []
        self._meter_done = 0
        #: Exposures (s) of the phase's frames still missing; None while unknown.
        self.exposures_left: list[float] | None = None
        self._metered: list[float] = []
        self._n_frames_per_channel = 1
        if session is None:
            self._n_meter = n_channels
            self.frames_left = _frames_of(
                kind, n_channels, options.repeats, options.n_darks
            )
        elif not session.settings.resolved:
            settings = session.settings
            n = len(settings.channels)
            self._n_meter = n - sum(
                c in settings.exposures_s for c in settings.channels
            )
            self.frames_left = _frames_of(
                kind, n, len(settings.bracket_factors), settings.n_darks
            )
            self._note_metered(session)
        else:
            self._n_meter = 0
            self.frame_taken(session)

    @property
    def n_meter_left(self) -> int:
        """Channels still to meter."""
        return max(0, self._n_meter - self._meter_done)

    def _note_metered(self, session: Any) -> None:
        """The exposures metered so far (their mean stands in for the others)."""
        if session is None:
            return
        exposures = session.settings.exposures_s
        self._metered = [float(t) for ts in exposures.values() for t in ts]

    def stage_started(self) -> None:
        """A metering or a frame starts now (``capture()``'s ``on_stage``)."""
        self._t_stage = time.monotonic()
        self._frame_in_stage = False

    def frame_taken(self, session: Any, exposure_s: float | None = None) -> None:
        """A frame of ``exposure_s`` was committed; count the frames of the phase
        still missing in ``session`` (once its exposures are resolved)."""
        if exposure_s is not None:
            wall = time.monotonic() - self._t_stage
            over = max(0.0, wall - (exposure_s if self._waits else 0.0))
            self.overhead_s.append(over)
            _LAST_OVERHEAD_S[:] = [over]
            self._frame_in_stage = True
        if session is not None and session.settings.resolved:
            self._n_meter = self._meter_done = 0
            missing = session.missing(verify=False)
            mine = [s for s in missing if self._kind in (None, s.kind)]
            self.frames_left = len(mine)
            self.exposures_left = [float(s.exposure_s) for s in mine]

    def remaining_s(self) -> float:
        """Seconds left (NaN while unknown)."""
        over = (
            float(np.median(self.overhead_s))
            if self.overhead_s
            else _LAST_OVERHEAD_S[0]
            if _LAST_OVERHEAD_S
            else None
        )
        mean_t = float(np.mean(self._metered)) if self._metered else None
        if over is None and self.meter_s and mean_t is not None:
            # no frame yet: a metering shot is a frame too (most channels need one)
            over = max(0.0, float(np.mean(self.meter_s)) - self._waited(mean_t))
        left = 0.0
        if self.n_meter_left:
            if not self.meter_s:
                return float("nan")
            left += self.n_meter_left * float(np.mean(self.meter_s))
        if self.frames_left:
            exposures = self.exposures_left
            if exposures is None:
                if mean_t is None and self._waits:
                    return float("nan")
                exposures = [mean_t or 0.0] * self.frames_left
            if over is None:
                return float("nan")
            left += sum(self._waited(t) + over for t in exposures)
        return left

    def _waited(self, exposure_s: float) -> float:
        return exposure_s if self._waits else 0.0

    def step(self) -> None:
        """One step done; report the fraction and the time left."""
        self.done += 1
        if not self._frame_in_stage and self.n_meter_left:
            # a metering step: the stage was that channel's metering
            self.meter_s.append(time.monotonic() - self._t_stage)
            self._meter_done += 1
            if self._session_now is not None:
                now = self._session_now()
                self._note_metered(now)
                # all metered: the frames left and their exposures are known
                self.frame_taken(now)
        self._frame_in_stage = False
        remaining = self.remaining_s()
        if np.isfinite(remaining):
            elapsed = time.monotonic() - self._t0
            fraction = elapsed / max(1e-9, elapsed + remaining)
        else:
            left = self.n_meter_left + self.frames_left
            fraction = self.done / max(1, self.done + left)
        self._last = max(self._last, min(fraction, 1.0))
        if self._progress is not None:
            self._progress(self._last)
        if self._remaining is not None:
            self._remaining(remaining)


def capture_job(
    context: DeviceContext,
    root: Path,
    target_layout: TargetLayout,
    options: CaptureOptions,
    kind: str | None,
    *,
    exposure: Any = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> PhaseResult:
    """Capture one phase (``kind``) of a session, or the whole session (None).

    ``pipeline.capture_target`` runs the capture sequence (resuming the session) and
    is stopped as soon as every frame of ``kind`` is in: a cancelled capture keeps
    its frames and the next phase resumes from there. A phase that is already
    complete is taken again (``pipeline.capture.Resume.retake_phase``: the one
    rule of resume and retake, which ``tunespec capture`` and ``run`` share). What
    it does now (``"metering LED495, 7 of 22"``) and its warnings go to the page as
    they happen (``context.set_stage``, ``context.warn``). Device thread.

    Parameters
    ----------
    exposure
        Overrides ``options.exposure`` (e.g. the chart's metered exposures for the
        sample: same board, same LEDs).
    """
    from tunespec.app.pipeline.jobs import capture_target
    from tunespec.core.io.session import MANIFEST_NAME, Session

    t0 = time.monotonic()
    bench = _bench_showing(context, target_layout)
    light = bench.light

    def session_now() -> Session | None:
        return Session.open(root) if (root / MANIFEST_NAME).exists() else None

    session = session_now()
    # a frame takes its exposure on hardware, and on the simulated bench in real time
    waits = not bench.simulated or bool(context.options.get("realtime", False))
    meter = _PhaseProgress(
        kind,
        session,
        len(light.channels()),
        options,
        progress,
        waits=waits,
        remaining=context.set_remaining,
        session_now=session_now,
    )
    phase_done = [False]
    captured: list[str] = []

    def on_frame(record: Any, path: Path) -> None:
        captured.append(record.id)
        context.show_frame(path)
        now = session_now()
        if now is None:
            return
        if record.spd_file is not None:
            context.show_spd(
                partial(now.read_spd, record), _levels_of(light, record.channel)
            )
        meter.frame_taken(now, float(record.exposure_s))
        if kind is not None and now.settings.resolved and meter.frames_left == 0:
            phase_done[0] = True

    def stop() -> bool:
        return phase_done[0] or bool(should_stop and should_stop())

    def on_stage(text: str) -> None:
        meter.stage_started()
        context.set_stage(text)

    warnings: tuple[str, ...] = ()
    try:
        session, warnings = capture_target(
            bench,
            root,
            target_layout,
            exposure=options.exposure if exposure is None else exposure,
            iso=options.iso,
            n_darks=options.n_darks,
            repeats=options.repeats,
            retake_phase=kind or "all",
            progress=lambda _f: meter.step(),
            should_stop=stop,
            on_frame=on_frame,
            on_warning=context.warn,
            on_stage=on_stage,
        )
    except Cancelled:
        if not phase_done[0] or (should_stop and should_stop()):
            raise
        session = session_now()
    assert session is not None
    n_frames = sum(kind in (None, f.kind) and f.status == "ok" for f in session.frames)
    return PhaseResult(
        kind or "all", tuple(captured), n_frames, warnings, time.monotonic() - t0
    )
