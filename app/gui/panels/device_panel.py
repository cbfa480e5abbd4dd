"""Connect the light source and camera; drive channels, exposure and ISO; live view.

The panel talks to the devices only through a
:class:`~tunespec.app.gui.workers.DeviceController` (queued signals to the device thread);
it never calls a device itself, so nothing here can block the event loop.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from PySide6.QtCore import Qt, QTimer, Signal, Slot
from PySide6.QtWidgets import (
    QAbstractItemView,
    QCheckBox,
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QGroupBox,
    QHBoxLayout,
    QHeaderView,
    QLabel,
    QPushButton,
    QSplitter,
    QTableWidget,
    QTableWidgetItem,
    QVBoxLayout,
    QWidget,
)

from tunespec.app.gui.plots.frame_plot import FramePlot, FramePreview
from tunespec.app.gui.workers import BenchInfo, DeviceController

__all__ = ["DevicePanel", "format_error"]

log = logging.getLogger(__name__)

ISO_CHOICES = (100, 200, 400, 800, 1600, 3200, 6400)
#: How often the light source status is polled while connected and idle.
STATUS_PERIOD_MS = 2000
#: Live view: the next frame is asked for this long after the last one arrived.
LIVE_PERIOD_MS = 200


def format_error(exc: BaseException) -> str:
    """One plain line for the operator: the message, prefixed by its kind if useful
    (a message of several lines gives its first; the log has the rest)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    text = lines[0] if lines else type(exc).__name__
    name = type(exc).__name__
    if name in ("DeviceTimeoutError", "TimeoutError"):
        return f"Timeout: {text}"
    if name in ("DeviceConnectionError", "ConnectionError", "FileNotFoundError"):
        return f"Connection: {text}"
    if name in ("InputError", "DeviceError", "DeviceCommandError"):
        return text
    return f"{name}: {text}"


class DevicePanel(QWidget):
    """The devices of the bench: connection, channels, camera and live view.

    Parameters
    ----------
    controller
        The device controller (owns the devices on its thread).
    light_specs, camera_specs
        Choices offered in the spec boxes (editable; the first is the default).
    sim_options
        Keyword options for opening the simulated bench (``realtime``, size, seed...).
    """

    #: The operator changed exposure or ISO: exposure in s, ISO.
    camera_settings_changed = Signal(float, int)
    #: The operator switched the simulated bench's real-time exposures on or off.
    realtime_changed = Signal(bool)
    #: The current channel changed: index, name.
    channel_selected = Signal(int, str)

    def __init__(
        self,
        controller: DeviceController,
        *,
        light_specs: list[str] | None = None,
        camera_specs: list[str] | None = None,
        sim_options: dict[str, Any] | None = None,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(parent)
        self.controller = controller
        self.sim_options = dict(sim_options or {})
        self.info: BenchInfo | None = None
        self.levels = np.zeros(0)
        self.busy = False
        self._updating = False
        self._live_pending = False

        self._build_layout(
            self._build_connection(light_specs or ["sim"], camera_specs or ["sim"]),
            self._build_light(),
            self._build_camera(),
        )
        self.status_timer = QTimer(self)
        self.status_timer.setInterval(STATUS_PERIOD_MS)
        self.live_timer = QTimer(self)
        self.live_timer.setSingleShot(True)
        self.live_timer.setInterval(LIVE_PERIOD_MS)

        self._connect_signals(controller)
        self._update_enabled()

    def _build_connection(
        self, light_specs: list[str], camera_specs: list[str]
    ) -> QGroupBox:
        """Spec boxes, Connect/Disconnect, the state and the devices' names."""
        self.light_spec_combo = QComboBox(editable=True)
        self.light_spec_combo.addItems(light_specs)
        self.camera_spec_combo = QComboBox(editable=True)
        self.camera_spec_combo.addItems(camera_specs)
        self.realtime_check = QCheckBox("Real-time exposures")
        self.realtime_check.setToolTip(
            "Simulated bench: the camera waits out every exposure as a real one "
            "does (a chart takes about 20 minutes). Off: virtual time, the frames "
            "are the same and the whole wizard takes about 2 minutes. Set before "
            "connecting."
        )
        self.realtime_check.setChecked(bool(self.sim_options.get("realtime", False)))
        self.connect_button = QPushButton("Connect")
        self.disconnect_button = QPushButton("Disconnect")
        self.state_label = QLabel("Not connected")
        self.state_label.setObjectName("state_label")
        self.light_label = QLabel("—")
        self.camera_label = QLabel("—")
        self.error_label = QLabel("")
        self.error_label.setWordWrap(True)
        self.error_label.setStyleSheet("color: #c00000")
        self.error_label.setTextInteractionFlags(
            Qt.TextInteractionFlag.TextSelectableByMouse
        )
        conn_form = QFormLayout()
        conn_form.addRow("Light source", self.light_spec_combo)
        conn_form.addRow("Camera", self.camera_spec_combo)
        conn_form.addRow(self.realtime_check)
        conn_buttons = QHBoxLayout()
        conn_buttons.addWidget(self.connect_button)
        conn_buttons.addWidget(self.disconnect_button)
        conn_form.addRow(conn_buttons)
        conn_form.addRow("State", self.state_label)
        conn_form.addRow("Light", self.light_label)
        conn_form.addRow("Camera", self.camera_label)
        conn_form.addRow(self.error_label)
        conn_box = QGroupBox("Devices")
        conn_box.setLayout(conn_form)
        return conn_box

    def _build_light(self) -> QGroupBox:
        """The channel table and the light source's buttons."""
        self.channel_table = QTableWidget(0, 3)
        self.channel_table.setHorizontalHeaderLabels(
            ["Channel", "Peak (nm)", "Level (%)"]
        )
        self.channel_table.verticalHeader().setVisible(False)
        self.channel_table.setSelectionBehavior(
            QAbstractItemView.SelectionBehavior.SelectRows
        )
        self.channel_table.setSelectionMode(
            QAbstractItemView.SelectionMode.SingleSelection
        )
        self.channel_table.horizontalHeader().setSectionResizeMode(
            QHeaderView.ResizeMode.Stretch
        )
        self.channel_table.verticalHeader().setDefaultSectionSize(24)
        self.channel_table.setMinimumHeight(140)
        self.solo_button = QPushButton("Only this channel")
        self.solo_button.setToolTip(
            "Switch the selected channel on at 100 %, all others off"
        )
        self.all_off_button = QPushButton("All off")
        self.all_off_button.setStyleSheet("font-weight: bold")
        self.spd_button = QPushButton("Measure SPD")
        self.status_label = QLabel("—")
        self.status_label.setWordWrap(True)
        light_buttons = QHBoxLayout()
        light_buttons.addWidget(self.solo_button)
        light_buttons.addWidget(self.spd_button)
        light_buttons.addWidget(self.all_off_button)
        light_layout = QVBoxLayout()
        light_layout.addWidget(self.channel_table, 1)
        light_layout.addLayout(light_buttons)
        light_layout.addWidget(self.status_label)
        light_box = QGroupBox("Light source")
        light_box.setLayout(light_layout)
        return light_box

    def _build_camera(self) -> QGroupBox:
        """Exposure, ISO, Take frame and Live."""
        self.exposure_spin = QDoubleSpinBox(
            decimals=4, minimum=0.0001, maximum=60.0, singleStep=0.1, suffix=" s"
        )
        self.exposure_spin.setKeyboardTracking(False)
        self.iso_combo = QComboBox()
        for iso in ISO_CHOICES:
            self.iso_combo.addItem(str(iso), iso)
        self.snap_button = QPushButton("Take frame")
        self.live_check = QCheckBox("Live")
        cam_form = QFormLayout()
        cam_form.addRow("Exposure", self.exposure_spin)
        cam_form.addRow("ISO", self.iso_combo)
        cam_buttons = QHBoxLayout()
        cam_buttons.addWidget(self.snap_button)
        cam_buttons.addWidget(self.live_check)
        cam_form.addRow(cam_buttons)
        cam_box = QGroupBox("Camera")
        cam_box.setLayout(cam_form)
        return cam_box

    def _build_layout(
        self, conn_box: QGroupBox, light_box: QGroupBox, cam_box: QGroupBox
    ) -> None:
        self.frame_plot = FramePlot()
        self.frame_plot.setMinimumHeight(120)
        top = QWidget()
        top_layout = QVBoxLayout(top)
        top_layout.setContentsMargins(0, 0, 0, 0)
        top_layout.addWidget(conn_box)
        top_layout.addWidget(light_box, 1)
        top_layout.addWidget(cam_box)
        splitter = QSplitter(Qt.Orientation.Vertical)
        splitter.addWidget(top)
        splitter.addWidget(self.frame_plot)
        splitter.setStretchFactor(0, 3)
        splitter.setStretchFactor(1, 2)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addWidget(splitter)

    def _connect_signals(self, controller: DeviceController) -> None:
        self.connect_button.clicked.connect(self._on_connect_button_clicked)
        self.disconnect_button.clicked.connect(self._on_disconnect_button_clicked)
        self.solo_button.clicked.connect(self._on_solo_button_clicked)
        self.all_off_button.clicked.connect(self._on_all_off_button_clicked)
        self.spd_button.clicked.connect(self._on_spd_button_clicked)
        self.snap_button.clicked.connect(self._on_snap_button_clicked)
        self.live_check.toggled.connect(self._on_live_check_toggled)
        self.realtime_check.toggled.connect(self._on_realtime_check_toggled)
        self.light_spec_combo.currentTextChanged.connect(self._on_spec_changed)
        self.camera_spec_combo.currentTextChanged.connect(self._on_spec_changed)
        self.exposure_spin.valueChanged.connect(self._on_camera_edited)
        self.iso_combo.currentIndexChanged.connect(self._on_camera_edited)
        self.channel_table.itemSelectionChanged.connect(
            self._on_channel_table_selection_changed
        )
        self.status_timer.timeout.connect(self._on_status_timer_timeout)
        self.live_timer.timeout.connect(self._on_live_timer_timeout)
        controller.devices_opened.connect(self._on_controller_devices_opened)
        controller.devices_closed.connect(self._on_controller_devices_closed)
        controller.levels_changed.connect(self._on_controller_levels_changed)
        controller.camera_changed.connect(self._on_controller_camera_changed)
        controller.status_changed.connect(self._on_controller_status_changed)
        controller.frame_acquired.connect(self._on_controller_frame_acquired)
        controller.errored.connect(self._on_controller_errored)
        controller.busy_changed.connect(self._on_controller_busy_changed)

    # -- public ---------------------------------------------------------------------
    @property
    def connected(self) -> bool:
        """Whether devices are open."""
        return self.info is not None

    def connect_devices(self) -> None:
        """Open the devices named in the spec boxes."""
        light = self.light_spec_combo.currentText().strip()
        camera = self.camera_spec_combo.currentText().strip()
        options = dict(self.sim_options) if light.startswith("sim") else {}
        self.error_label.setText("")
        self.state_label.setText(f"Connecting to {light} and {camera}…")
        self.connect_button.setEnabled(False)
        log.info("connecting light %r and camera %r", light, camera)
        self.controller.open_devices(light, camera, **options)

    def disconnect_devices(self) -> None:
        """Close the devices (their light is switched off)."""
        self.live_check.setChecked(False)
        self.controller.close_devices()

    def current_channel(self) -> int | None:
        """Index of the selected channel row, or None."""
        rows = self.channel_table.selectionModel().selectedRows() if self.info else []
        return rows[0].row() if rows else None

    def show_error(self, text: str) -> None:
        """Show ``text`` in red under the connection state."""
        self.error_label.setText(text)

    # -- helpers ------------------------------------------------------------------
    def _update_enabled(self) -> None:
        on = self.connected
        idle = not self.busy
        self.connect_button.setEnabled(not on and idle)
        self.disconnect_button.setEnabled(on and idle)
        self.light_spec_combo.setEnabled(not on)
        self.camera_spec_combo.setEnabled(not on)
        # a simulated camera only, and fixed once it is open
        self.realtime_check.setEnabled(not on and self._simulated_specs())
        for w in (
            self.channel_table,
            self.solo_button,
            self.spd_button,
            self.exposure_spin,
            self.iso_combo,
            self.snap_button,
            self.live_check,
        ):
            w.setEnabled(on and idle)
        # "All off" stays available during a capture: it also aborts it
        self.all_off_button.setEnabled(on)

    def _simulated_specs(self) -> bool:
        return self.camera_spec_combo.currentText().strip().startswith("sim")

    def _level_spin(self, row: int) -> QDoubleSpinBox:
        return self.channel_table.cellWidget(row, 2)

    # -- slots: widgets ----------------------------------------------------------------
    @Slot()
    def _on_connect_button_clicked(self) -> None:
        self.connect_devices()

    @Slot()
    def _on_disconnect_button_clicked(self) -> None:
        self.disconnect_devices()

    @Slot()
    def _on_solo_button_clicked(self) -> None:
        row = self.current_channel()
        if row is not None:
            levels = np.zeros(len(self.info.channels))
            levels[row] = 1.0
            self.controller.set_levels(levels)
            self.controller.measure_spd()

    @Slot()
    def _on_all_off_button_clicked(self) -> None:
        log.info("all channels off (operator)")
        self.controller.all_off()

    @Slot()
    def _on_spd_button_clicked(self) -> None:
        self.controller.measure_spd()

    @Slot()
    def _on_snap_button_clicked(self) -> None:
        self.controller.snap_preview()

    @Slot(bool)
    def _on_realtime_check_toggled(self, on: bool) -> None:
        self.sim_options["realtime"] = bool(on)
        log.info("simulated bench: %s", "real-time exposures" if on else "virtual time")
        self.realtime_changed.emit(bool(on))

    @Slot(str)
    def _on_spec_changed(self, _text: str) -> None:
        self._update_enabled()

    @Slot(bool)
    def _on_live_check_toggled(self, on: bool) -> None:
        if on and not self._live_pending:
            self._live_pending = True
            self.controller.snap_preview()

    @Slot()
    def _on_live_timer_timeout(self) -> None:
        if self.live_check.isChecked() and self.connected and not self.busy:
            self._live_pending = True
            self.controller.snap_preview()

    @Slot()
    def _on_camera_edited(self) -> None:
        if self._updating or not self.connected:
            return
        exposure_s = self.exposure_spin.value()
        iso = int(self.iso_combo.currentData())
        self.controller.set_camera(exposure_s, iso)
        self.camera_settings_changed.emit(exposure_s, iso)

    def _on_level_edited(self, row: int, percent: float) -> None:
        if self._updating or not self.connected:
            return
        levels = (
            self.levels.copy()
            if self.levels.size
            else np.zeros(len(self.info.channels))
        )
        levels[row] = percent / 100.0
        self.controller.set_levels(levels)
        self.controller.measure_spd()

    @Slot()
    def _on_channel_table_selection_changed(self) -> None:
        row = self.current_channel()
        if row is not None and self.info is not None:
            self.channel_selected.emit(row, self.info.channels[row].name)

    @Slot()
    def _on_status_timer_timeout(self) -> None:
        if self.connected and not self.busy:
            self.controller.refresh_status()

    # -- slots: controller -------------------------------------------------------------
    @Slot(object)
    def _on_controller_devices_opened(self, info: BenchInfo) -> None:
        self.info = info
        li, ci = info.light_identity, info.camera_identity
        self.light_label.setText(f"{li.vendor} {li.model} (s/n {li.serial})")
        self.camera_label.setText(f"{ci.vendor} {ci.model} (s/n {ci.serial})")
        sim = " — simulated bench" if info.simulated else ""
        self.state_label.setText(f"Connected{sim}")
        self.state_label.setStyleSheet("color: #006000; font-weight: bold")
        self._updating = True
        try:
            self.channel_table.setRowCount(len(info.channels))
            for row, ch in enumerate(info.channels):
                name = QTableWidgetItem(ch.name)
                name.setFlags(name.flags() & ~Qt.ItemFlag.ItemIsEditable)
                peak = QTableWidgetItem(
                    f"{ch.peak_nm:.0f}" if ch.kind == "narrowband" else "white"
                )
                peak.setFlags(peak.flags() & ~Qt.ItemFlag.ItemIsEditable)
                self.channel_table.setItem(row, 0, name)
                self.channel_table.setItem(row, 1, peak)
                spin = QDoubleSpinBox(
                    minimum=0.0, maximum=100.0, decimals=1, singleStep=5.0
                )
                spin.setKeyboardTracking(False)
                spin.setFrame(False)
                spin.valueChanged.connect(lambda v, r=row: self._on_level_edited(r, v))
                self.channel_table.setCellWidget(row, 2, spin)
            self.exposure_spin.setValue(info.exposure_s)
            idx = self.iso_combo.findData(info.iso)
            if idx < 0:
                self.iso_combo.addItem(str(info.iso), info.iso)
                idx = self.iso_combo.count() - 1
            self.iso_combo.setCurrentIndex(idx)
        finally:
            self._updating = False
        self.status_timer.start()
        self._update_enabled()

    @Slot()
    def _on_controller_devices_closed(self) -> None:
        self.info = None
        self.levels = np.zeros(0)
        self.status_timer.stop()
        self.live_timer.stop()
        self.live_check.setChecked(False)
        self._live_pending = False
        self.channel_table.setRowCount(0)
        self.light_label.setText("—")
        self.camera_label.setText("—")
        self.status_label.setText("—")
        self.state_label.setText("Not connected")
        self.state_label.setStyleSheet("")
        self._update_enabled()

    @Slot(object)
    def _on_controller_levels_changed(self, levels: Any) -> None:
        self.levels = np.asarray(levels, dtype=float)
        self._updating = True
        try:
            for row in range(min(self.channel_table.rowCount(), self.levels.size)):
                spin = self._level_spin(row)
                if spin is not None:
                    spin.setValue(100.0 * self.levels[row])
        finally:
            self._updating = False

    @Slot(float, int)
    def _on_controller_camera_changed(self, exposure_s: float, iso: int) -> None:
        self._updating = True
        try:
            self.exposure_spin.setValue(exposure_s)
            idx = self.iso_combo.findData(iso)
            if idx >= 0:
                self.iso_combo.setCurrentIndex(idx)
        finally:
            self._updating = False

    @Slot(object)
    def _on_controller_status_changed(self, status: Any) -> None:
        parts = ["ready" if status.ready else "NOT READY"]
        if np.isfinite(status.temperature_c):
            parts.append(f"{status.temperature_c:.1f} °C")
        parts.append(f"on {status.on_time_s:.0f} s")
        if status.message and status.message.lower() not in ("ready", "not ready"):
            parts.append(status.message)
        self.status_label.setText("Status: " + ", ".join(parts))

    @Slot(object)
    def _on_controller_frame_acquired(self, preview: FramePreview) -> None:
        self._live_pending = False
        self.frame_plot.show_preview(preview)
        if self.live_check.isChecked():
            self.live_timer.start()

    @Slot(object)
    def _on_controller_errored(self, exc: Any) -> None:
        self._live_pending = False
        self.live_check.setChecked(False)
        self.show_error(format_error(exc))
        if not self.connected:
            self.state_label.setText("Not connected")
            self.state_label.setStyleSheet("color: #c00000")
        self._update_enabled()

    @Slot(bool)
    def _on_controller_busy_changed(self, busy: bool) -> None:
        self.busy = busy
        self._update_enabled()
        if not busy and self.live_check.isChecked() and not self._live_pending:
            # a live view paused by a capture goes on afterwards
            self.live_timer.start()
