"""The operator's workstation: devices, measurement wizard, layout editor, spectra, log.

The window composes the widgets and wires their signals; every widget gets its
model or service in ``__init__`` (the device controller, the measurement), and the
window holds no measurement logic of its own.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import math
from pathlib import Path
from typing import Any

from PySide6.QtCore import QSettings, Qt, Slot
from PySide6.QtGui import QAction, QCloseEvent, QKeySequence
from PySide6.QtWidgets import (
    QDockWidget,
    QFileDialog,
    QGridLayout,
    QMainWindow,
    QMessageBox,
    QTabWidget,
    QWidget,
)

import tunespec.app.gui.qt_compat  # noqa: F401 (before any signal)
from tunespec.app.gui.editors.target_layout_editor import TargetLayoutEditor
from tunespec.app.gui.panels.device_panel import DevicePanel, format_error
from tunespec.app.gui.panels.gonio_panel import GonioPanel
from tunespec.app.gui.panels.log_panel import LogPanel
from tunespec.app.gui.panels.stats_table_panel import (
    show_table1,
    show_table2,
    table1_panel,
    table2_panel,
)
from tunespec.app.gui.plots.image_view import ImageView
from tunespec.app.gui.plots.reflectance_plot import ReflectancePlot
from tunespec.app.gui.plots.sensitivity_plot import SensitivityPlot
from tunespec.app.gui.plots.spd_plot import SpdPlot
from tunespec.app.gui.processes import start_process_server
from tunespec.app.gui.settings import AppSettings
from tunespec.app.gui.wizard.measurement import (
    CALIBRATION_DIR,
    CHART_DIR,
    SAMPLE_DIR,
    Measurement,
)
from tunespec.app.gui.wizard.wizard_panel import WizardPanel
from tunespec.app.gui.workers import (
    BenchInfo,
    DeviceController,
    Throttle,
    Worker,
    collect_on_gui_thread,
    gc_paused,
)
from tunespec.app.pipeline.engine import limit_blas_threads

__all__ = ["MainWindow"]

log = logging.getLogger(__name__)

TAB_MEASUREMENT, TAB_LAYOUT, TAB_SPECTRA, TAB_TABLES, TAB_IMAGE = range(5)

#: Where "Estimate spectral image" writes, inside the measurement folder.
IMAGES_DIR = "images"


class MainWindow(QMainWindow):
    """The TuneSpec main window.

    Parameters
    ----------
    settings
        Persistent settings (:class:`AppSettings` or a ``QSettings``); default the
        user's.
    opener
        Opens a bench from two spec strings (default: ``tunespec.devices.registry``);
        tests inject their own.
    sim_options
        Override the stored simulated-bench options (tests: ``realtime=False`` and
        a small resolution).
    """

    def __init__(
        self,
        settings: AppSettings | QSettings | None = None,
        *,
        opener: Any = None,
        sim_options: dict[str, Any] | None = None,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        # threads run Python from here on: Qt objects must die on this thread only
        collect_on_gui_thread()
        if not isinstance(settings, AppSettings):
            settings = AppSettings(settings)
        self.settings = settings
        self.setWindowTitle("TuneSpec — spectral reflectance workstation")
        self.resize(1400, 900)

        self.controller = DeviceController(opener)
        c = self.controller
        # connected first, so the window has taken in what the devices said before
        # a step that follows the same signal reports itself done (a signal from
        # the device thread is queued to each receiver in the order connected)
        c.devices_opened.connect(self._on_controller_devices_opened)
        c.devices_closed.connect(self._on_controller_devices_closed)
        c.spd_measured.connect(self._on_controller_spd_measured)
        c.frame_acquired.connect(self._on_controller_frame_acquired)
        c.errored.connect(self._on_controller_errored)
        self._truth: dict[str, Any] = {}
        self._last_preview: dict[str, Any] = {}
        options = {**settings.sim_options(), **(sim_options or {})}
        self.measurement = Measurement(self.controller, settings)

        self.log_panel = LogPanel()
        self.device_panel = DevicePanel(
            self.controller,
            light_specs=_spec_choices("light", settings.get("devices/light_spec")),
            camera_specs=_spec_choices("camera", settings.get("devices/camera_spec")),
            sim_options=options,
        )
        self.device_panel.realtime_changed.connect(
            self._on_device_panel_realtime_changed
        )
        self.measurement.connector = self.device_panel.connect_devices
        self.measurement.sim_options = options
        self.wizard_panel = WizardPanel(self.measurement)
        self.layout_editor = TargetLayoutEditor(self.measurement.chart_layout)
        self.spd_plot = SpdPlot()
        self.sensitivity_plot = SensitivityPlot()
        self.reflectance_plot = ReflectancePlot()
        self.table1_panel = table1_panel()
        self.table2_panel = table2_panel()
        self.image_view = ImageView()
        self.image_view.scheduler_edit.setText(settings.get("image/scheduler"))

        spectra = QWidget()
        grid = QGridLayout(spectra)
        grid.addWidget(self.spd_plot, 0, 0)
        grid.addWidget(self.sensitivity_plot, 0, 1)
        grid.addWidget(self.reflectance_plot, 1, 0, 1, 2)
        tables = QWidget()
        tgrid = QGridLayout(tables)
        tgrid.addWidget(self.table1_panel, 0, 0)
        tgrid.addWidget(self.table2_panel, 0, 1)
        self.tabs = QTabWidget()
        self.tabs.addTab(self.wizard_panel, "Measurement")
        self.tabs.addTab(self.layout_editor, "Target layout")
        self.tabs.addTab(spectra, "Spectra")
        self.tabs.addTab(tables, "Tables")
        self.tabs.addTab(self.image_view, "Spectral image")
        self.gonio_panel = GonioPanel()
        self.tabs.addTab(self.gonio_panel, "Gonio")
        self.setCentralWidget(self.tabs)

        self.device_dock = QDockWidget("Devices", self)
        self.device_dock.setObjectName("device_dock")
        self.device_dock.setWidget(self.device_panel)
        self.addDockWidget(Qt.DockWidgetArea.LeftDockWidgetArea, self.device_dock)
        # the live view gets its own dock so the channel list keeps its height
        self.live_dock = QDockWidget("Live view", self)
        self.live_dock.setObjectName("live_dock")
        self.live_dock.setWidget(self.device_panel.frame_plot)
        self.addDockWidget(Qt.DockWidgetArea.LeftDockWidgetArea, self.live_dock)
        self.splitDockWidget(self.device_dock, self.live_dock, Qt.Orientation.Vertical)
        self.log_dock = QDockWidget("Log", self)
        self.log_dock.setObjectName("log_dock")
        self.log_dock.setWidget(self.log_panel)
        self.addDockWidget(Qt.DockWidgetArea.BottomDockWidgetArea, self.log_dock)
        self.resizeDocks([self.log_dock], [150], Qt.Orientation.Vertical)
        self._build_menus()
        # Esc aborts the running step whichever tab is shown
        self.addAction(self.wizard_panel.abort_action)

        # redraw at most ~20 Hz however fast the devices report
        self._spd_throttle = Throttle(self.spd_plot.show_spd, parent=self.spd_plot)
        self._frame_throttle = Throttle(
            self.layout_editor.show_preview, parent=self.layout_editor
        )
        m = self.measurement
        m.layout_needed.connect(self._on_measurement_layout_needed)
        m.folder_changed.connect(self._on_measurement_folder_changed)
        m.calibrated.connect(self._on_measurement_calibrated)
        m.estimated.connect(self._on_measurement_estimated)
        m.result_cleared.connect(self._on_measurement_result_cleared)
        self.layout_editor.layout_changed.connect(self._on_layout_editor_layout_changed)
        self.layout_editor.layout_loaded.connect(self._on_layout_editor_layout_loaded)
        self.layout_editor.patch_selected.connect(self.reflectance_plot.select_patch)
        self.reflectance_plot.patch_selected.connect(self.layout_editor.select_patch)
        self.table2_panel.row_selected.connect(self.reflectance_plot.select_patch)
        self._restore_settings()
        # the first capture would otherwise import (and, without .pyc files, compile)
        # the pipeline on the device thread while the GUI waits for the GIL
        self.preloaded = False
        limit_blas_threads()
        self._preload = Worker(_preload_pipeline, hooks=False)
        self._preload.signals.finished.connect(self._on_preload_finished)
        self._preload.start()
        log.info("TuneSpec workstation ready")

    # -- menus ------------------------------------------------------------------------
    def _build_menus(self) -> None:
        file_menu = self.menuBar().addMenu("&File")
        self.new_action = QAction(
            "&New measurement…", self, shortcut=QKeySequence.StandardKey.New
        )
        self.open_action = QAction(
            "&Open / resume measurement…", self, shortcut=QKeySequence.StandardKey.Open
        )
        self.quit_action = QAction(
            "&Quit", self, shortcut=QKeySequence.StandardKey.Quit
        )
        file_menu.addAction(self.new_action)
        file_menu.addAction(self.open_action)
        file_menu.addMenu(self.wizard_panel.recent_menu)
        self.record_action = QAction("Measurement &record…", self)
        file_menu.addAction(self.record_action)
        file_menu.addSeparator()
        self.open_image_action = QAction("Spectral &image…", self)
        self.open_image_action.setToolTip("Show a folder of per-pixel images")
        self.estimate_image_action = QAction("&Estimate the spectral image", self)
        self.estimate_image_action.setToolTip(
            "Per-pixel reflectances of the measurement's sample (else chart) "
            "session with its calibration, into its images folder"
        )
        file_menu.addAction(self.open_image_action)
        file_menu.addAction(self.estimate_image_action)
        file_menu.addSeparator()
        file_menu.addAction(self.quit_action)
        edit_menu = self.menuBar().addMenu("&Edit")
        edit_menu.addAction(self.layout_editor.undo_action)
        edit_menu.addAction(self.layout_editor.redo_action)
        self.gonio_plan_action = QAction("&Gonio plan…", self)
        edit_menu.addAction(self.gonio_plan_action)
        dev_menu = self.menuBar().addMenu("&Devices")
        self.connect_sim_action = QAction("Connect the &simulated bench", self)
        self.all_off_action = QAction(
            "&All LEDs off", self, shortcut=QKeySequence("Ctrl+0")
        )
        dev_menu.addAction(self.connect_sim_action)
        dev_menu.addAction(self.all_off_action)
        view_menu = self.menuBar().addMenu("&View")
        view_menu.addAction(self.device_dock.toggleViewAction())
        view_menu.addAction(self.live_dock.toggleViewAction())
        view_menu.addAction(self.log_dock.toggleViewAction())
        help_menu = self.menuBar().addMenu("&Help")
        about = QAction("&About TuneSpec", self)
        help_menu.addAction(about)
        self.new_action.triggered.connect(self._on_new_action_triggered)
        self.open_action.triggered.connect(self._on_open_action_triggered)
        self.quit_action.triggered.connect(self.close)
        self.open_image_action.triggered.connect(self._on_open_image_action_triggered)
        self.estimate_image_action.triggered.connect(
            self._on_estimate_image_action_triggered
        )
        self.image_view.scheduler_edit.editingFinished.connect(
            self._on_scheduler_edit_editing_finished
        )
        self.connect_sim_action.triggered.connect(self._on_connect_sim_action_triggered)
        self.all_off_action.triggered.connect(self._on_all_off_action_triggered)
        about.triggered.connect(self._on_about_action_triggered)
        self.gonio_plan_action.triggered.connect(self._on_gonio_plan_action_triggered)
        self.record_action.triggered.connect(self._on_record_action_triggered)

    # -- settings ---------------------------------------------------------------------
    def _restore_settings(self) -> None:
        s = self.settings
        geometry, state = s.get("ui/geometry"), s.get("ui/state")
        if geometry:
            self.restoreGeometry(geometry)
        if state:
            self.restoreState(state)
        self.tabs.setCurrentIndex(min(max(0, s.get("ui/tab")), self.tabs.count() - 1))

    def save_settings(self) -> None:
        """Store window and device choices."""
        s = self.settings
        s.set("ui/geometry", self.saveGeometry())
        s.set("ui/state", self.saveState())
        s.set("ui/tab", self.tabs.currentIndex())
        s.set("devices/light_spec", self.device_panel.light_spec_combo.currentText())
        s.set("devices/camera_spec", self.device_panel.camera_spec_combo.currentText())
        s.set("image/scheduler", self.image_view.scheduler_edit.text().strip())
        self.measurement.save_settings()
        self.measurement.save()
        s.sync()

    # -- spectral images ----------------------------------------------------------------
    def open_image(self, folder: str | Path) -> bool:
        """Show the image folder ``folder`` in the image tab; False (and why, in the
        status bar) if it is not one."""
        try:
            self.image_view.open_folder(folder)
        except Exception as exc:
            text = f"Not a spectral image folder: {format_error(exc)}"
            self.image_view.status.setText(text)
            self.statusBar().showMessage(text, 15000)
            return False
        self.tabs.setCurrentIndex(TAB_IMAGE)
        return True

    def estimate_image(self) -> Any:
        """Estimate the per-pixel images of the measurement's sample session (the
        chart's if there is none) with its calibration, into ``images/<session>``
        (on the scheduler of the image tab); returns the worker, or None and says why
        in the status bar."""
        m = self.measurement
        why = None
        sens = m.folder / CALIBRATION_DIR / "sensitivity.csv" if m.folder else None
        which = next(
            (w for w in ("sample", "chart") if m.phase_complete(w, None)), None
        )
        if self.image_view.worker is not None:
            why = "a spectral image is being estimated"
        elif m.folder is None or which is None:
            why = "capture the chart or the sample of a measurement first"
        elif sens is None or not sens.is_file():
            why = "calibrate the measurement first (step 5)"
        if why is not None:
            self.statusBar().showMessage(f"Cannot estimate the image: {why}.", 15000)
            return None
        session = m.folder / (SAMPLE_DIR if which == "sample" else CHART_DIR)
        self.tabs.setCurrentIndex(TAB_IMAGE)
        return self.image_view.estimate(session, sens, m.folder / IMAGES_DIR / which)

    # -- slots: menus -----------------------------------------------------------------
    @Slot()
    def _on_open_image_action_triggered(self) -> None:
        m = self.measurement
        images = m.folder / IMAGES_DIR if m.folder is not None else None
        start = images if images is not None and images.is_dir() else None
        folder = QFileDialog.getExistingDirectory(
            self,
            "Open a spectral image folder",
            str(start or self.settings.measurements_dir()),
        )
        if folder:
            self.open_image(folder)

    @Slot()
    def _on_estimate_image_action_triggered(self) -> None:
        self.estimate_image()

    @Slot()
    def _on_scheduler_edit_editing_finished(self) -> None:
        self.settings.set(
            "image/scheduler", self.image_view.scheduler_edit.text().strip()
        )

    @Slot()
    def _on_new_action_triggered(self) -> None:
        if self.wizard_panel.ask_new_measurement():
            self.tabs.setCurrentIndex(TAB_MEASUREMENT)

    @Slot()
    def _on_open_action_triggered(self) -> None:
        if self.wizard_panel.ask_open_measurement():
            self.tabs.setCurrentIndex(TAB_MEASUREMENT)

    @Slot()
    def _on_connect_sim_action_triggered(self) -> None:
        if not self.device_panel.connected:
            self.device_panel.light_spec_combo.setCurrentText("sim")
            self.device_panel.camera_spec_combo.setCurrentText("sim")
            self.device_panel.connect_devices()

    @Slot(bool)
    def _on_device_panel_realtime_changed(self, on: bool) -> None:
        self.settings.set("sim/realtime", bool(on))
        self.measurement.sim_options["realtime"] = bool(on)

    @Slot()
    def _on_all_off_action_triggered(self) -> None:
        self.wizard_panel.abort()
        self.controller.all_off()

    @Slot()
    def _on_gonio_plan_action_triggered(self) -> None:
        """The gonio plan editor (issue 15), a non-modal dialog kept by the window."""
        from tunespec.app.gui.editors.gonio_plan_editor import GonioPlanEditor

        if getattr(self, "gonio_plan_editor", None) is None:
            self.gonio_plan_editor = GonioPlanEditor(parent=self)
        self.gonio_plan_editor.show()
        self.gonio_plan_editor.raise_()

    @Slot()
    def _on_record_action_triggered(self) -> None:
        """The open measurement's record (operator, sample ID, instruments)."""
        from tunespec.app.gui.panels.provenance import MeasurementRecordDialog

        MeasurementRecordDialog(self.measurement.folder, parent=self).exec()

    @Slot()
    def _on_about_action_triggered(self) -> None:
        QMessageBox.about(
            self,
            "About TuneSpec",
            "TuneSpec: spectral reflectance from an RGB camera and a spectrally "
            "tunable LED light source (Image Engineering CAL1, Canon EOS 5D Mark III).",
        )

    # -- slots: devices and measurement ----------------------------------------------
    @Slot(object)
    def _on_controller_devices_opened(self, info: BenchInfo) -> None:
        self.spd_plot.set_channel_names([c.name for c in info.channels])
        self._truth = dict(info.extra.get("truth", {}))
        self.statusBar().showMessage("Devices connected", 5000)

    @Slot()
    def _on_controller_devices_closed(self) -> None:
        self.spd_plot.set_connected(False)
        self.statusBar().showMessage("Devices closed", 5000)

    @Slot(object, object)
    def _on_controller_spd_measured(self, spd: Any, levels: Any) -> None:
        self._spd_throttle(spd, levels)

    @Slot(object)
    def _on_controller_frame_acquired(self, preview: Any) -> None:
        self._last_preview[self.measurement.current_target] = preview
        self._frame_throttle(preview)

    @Slot(object)
    def _on_controller_errored(self, exc: Any) -> None:
        self.statusBar().showMessage(f"Device error: {format_error(exc)}", 15000)

    @Slot(object)
    def _on_measurement_layout_needed(self, target_layout: Any) -> None:
        # the editor shows the last frame taken of that target, not of the other one
        preview = self._last_preview.get(self.measurement.current_target)
        if preview is not None:
            self.layout_editor.show_preview(preview)
        self.layout_editor.set_session_root(self._current_session_root())
        self.layout_editor.set_target_layout(target_layout)

    @Slot(object)
    def _on_measurement_folder_changed(self, _folder: Any) -> None:
        self.layout_editor.set_session_root(self._current_session_root())

    def _current_session_root(self) -> Any:
        """The session folder of the target the editor edits (None: no folder)."""
        m = self.measurement
        if m.folder is None:
            return None
        return m.folder / (CHART_DIR if m.current_target == "chart" else SAMPLE_DIR)

    @Slot(object)
    def _on_layout_editor_layout_changed(self, target_layout: Any) -> None:
        self.measurement.set_current_layout(target_layout)

    @Slot(str)
    def _on_layout_editor_layout_loaded(self, path: str) -> None:
        # the next measurement starts from the layout file the operator chose
        self.settings.set(f"layout/{self.measurement.current_target}_path", path)

    @Slot(object)
    def _on_measurement_calibrated(self, result: Any) -> None:
        show_table1(self.table1_panel, result)
        self._show_corners_used("Calibrate", "chart", result.chart)
        reference = self._truth.get("sensitivity")
        label = "true (simulator)"
        if reference is None:
            reference, label = _reference_sensitivity(), "database"
        self.sensitivity_plot.show_sensitivity(
            result.sensitivity,
            reference,
            label=f"estimated ({result.method})",
            reference_label=label,
            std=getattr(getattr(result.calibration, "estimate", None), "std", None),
        )

    @Slot(object)
    def _on_measurement_estimated(self, result: Any) -> None:
        show_table2(self.table2_panel, result)
        self._show_corners_used("Estimate", "sample", result.sample)
        per_patch = {}
        t = result.table2
        if t is not None:
            per_patch = {
                n: f"CIEDE2000 {d:.2f}, spectral RMS {r:.4f}"
                for n, d, r in zip(t.names, t.delta_e00, t.spectral_rms, strict=True)
            }
        unc = getattr(result.estimation, "uncertainty", None)
        self.reflectance_plot.set_data(
            result.reflectance,
            result.reference,
            per_patch,
            std=None if unc is None else unc.reflectance_std,
        )

    def _show_corners_used(self, step: str, target: str, processed: Any) -> None:
        """Tell the editor's operator that its corners are the ones ``step`` used."""
        if processed is None or self.measurement.current_target != target:
            return
        how = {
            "auto": "found in the images",
            "layout": "set in this editor",
            "given": "given",
        }.get(processed.corners_source, processed.corners_source)
        residual = processed.corner_residual_px
        fit = f", fit residual {residual:.2f} px" if math.isfinite(residual) else ""
        self.layout_editor.show_status(
            f"The corners shown are the ones {step} used ({how}{fit})."
        )

    @Slot(str)
    def _on_measurement_result_cleared(self, which: str) -> None:
        # what another measurement or a retaken step made invalid is not shown
        if which == "calibration":
            self.table1_panel.clear_table("Not calibrated yet.")
            self.sensitivity_plot.clear_data()
        elif which == "estimate":
            self.table2_panel.clear_table("Not estimated yet.")
            self.reflectance_plot.clear_data()
            self.layout_editor.select_patch(None)

    @Slot()
    def _on_preload_finished(self) -> None:
        self.preloaded = True

    # -- closing ----------------------------------------------------------------------
    def closeEvent(self, event: QCloseEvent) -> None:
        """Abort what runs, switch the light off, close the devices, save settings."""
        try:
            self.save_settings()
        except Exception as exc:
            # e.g. the measurement folder is gone: the devices must still be closed
            log.error("cannot save the settings or the measurement: %s", exc)
        finally:
            if self.image_view.worker is not None:
                self.image_view.worker.abort()
            if self.gonio_panel.worker is not None:
                self.gonio_panel.worker.abort()
            self.wizard_panel.shutdown()
            self.controller.shutdown()
            self.log_panel.detach()
        super().closeEvent(event)


#: Whether the start-up objects were moved out of the collector's reach.
_GC_FROZEN = False

#: Modules the measurement steps need, imported in the background at start-up.
PIPELINE_MODULES = (
    "tunespec.app.pipeline.run",
    "tunespec.devices.sim.camera",
    "tunespec.devices.sim.light",
    "tunespec.devices.dng",
    "tunespec.core.io.raw",
    "tunespec.core.homography",
    "tunespec.core.sensitivity",
    "tunespec.core.stats",
    "tunespec.core.wiener",
    "tunespec.core.colorimetry",
    "tunespec.core.io.export",
    # imported lazily by colorimetry and the export: a big module imported by a
    # step holds the GIL for tens of ms at a time (unmarshalling its code)
    "colour",
    "tunespec.app.report.report",
    "tunespec.app.gui.plots.frame_plot",
    "cv2",
    "rawpy",
    "scipy.ndimage",
)


def _preload_pipeline() -> None:
    """Import :data:`PIPELINE_MODULES` (pool thread); one that is not installed
    (``rawpy`` is optional) is imported when needed, with its error then.

    The modules' objects (hundreds of thousands, with colour-science and
    matplotlib) live as long as the program, and a full collection walking them
    holds the GIL for 120-190 ms, wherever it is triggered, while the GUI waits.
    So the collector is off while they are imported, and then they are frozen: it
    leaves them out from then on (``gc.freeze``). Once per process (a second window
    would freeze the first for good).
    """
    import importlib

    global _GC_FROZEN
    freeze = not _GC_FROZEN
    _GC_FROZEN = True
    # gc_paused, not gc.enable() after: this is a pool thread, and the collector
    # must stay with the GUI thread while ours run (workers._GuiThreadCollector)
    with gc_paused() if freeze else contextlib.nullcontext():
        for name in PIPELINE_MODULES:
            try:
                importlib.import_module(name)
            except ImportError as exc:
                log.debug("not preloaded: %s", exc)
        if freeze:
            gc.freeze()
    limit_blas_threads()  # again: scipy brings its own OpenBLAS
    start_process_server()  # the numerics' processes (it imports on its own)


def _reference_sensitivity() -> Any:
    """The database curves of the bench's camera model (the simulator's truth)."""
    from tunespec.core.datasets import DEFAULT_CAMERA, load_camera

    try:
        return load_camera(DEFAULT_CAMERA)
    except Exception as exc:
        log.debug("no reference sensitivity: %s", exc)
        return None


def _spec_choices(role: str, remembered: str) -> list[str]:
    """Spec strings offered for ``role`` (``"light"`` or ``"camera"``).

    The remembered spec comes first, then the simulated bench, then the usual
    hardware specs as examples to edit. (The registry has no hardware discovery yet,
    so ``sim`` stays the default until the operator picks hardware.)
    """
    hardware = (
        ["cal1:///dev/ttyUSB0", "cal1+socket://127.0.0.1:5025"]
        if role == "light"
        else ["gphoto2"]
    )
    choices = [remembered] if remembered else []
    for spec in ("sim", *hardware):
        if spec not in choices:
            choices.append(spec)
    return choices
