"""Wizard step 1: connect the light source and the camera."""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Slot
from PySide6.QtWidgets import QWidget

from tunespec.app.gui.panels.device_panel import format_error
from tunespec.app.gui.wizard.step_page import StepPage, StepState

__all__ = ["ConnectPage"]


class ConnectPage(StepPage):
    """Opens the devices chosen in the device panel (the simulated bench by default).

    Unlike the other steps it runs no job of its own: the device controller opens
    the devices and the page follows its signals.
    """

    key = "connect"

    step_title = "Connect"
    step_description = (
        "Choose the light source and the camera in the <b>Devices</b> panel "
        "(<i>sim</i> is the simulated bench, used when no hardware is present), "
        "then connect. The LEDs warm up while you prepare the bench."
    )
    step_start_text = "Connect"

    def __init__(self, measurement: Any, parent: QWidget | None = None) -> None:
        super().__init__(measurement)
        self.abort_button.hide()
        self.progress_bar.hide()
        # no widgets of its own: the space stays under the description, which
        # would otherwise be spread over the page
        self.body.addStretch(1)
        c = measurement.controller
        c.devices_opened.connect(self._on_controller_devices_opened)
        c.devices_closed.connect(self._on_controller_devices_closed)
        c.errored.connect(self._on_controller_errored)

    def start(self) -> None:
        """Ask the controller to open the devices."""
        if self.running:
            return
        self.result_label.setStyleSheet("")
        self.result_label.setText("Connecting…")
        self._set_state(StepState.RUNNING)
        self.measurement.connector()

    def refresh(self) -> None:
        """Show "done" if the devices are already open."""
        if self.measurement.controller.is_open and self.state != StepState.DONE:
            self.mark_done("Devices connected.")

    def restore(self) -> bool:
        """Connected devices cannot be restored from disk: the step is redone."""
        return self.state == StepState.DONE

    def _update_buttons(self) -> None:
        super()._update_buttons()
        self.start_button.setText("Connect")
        self.start_button.setEnabled(self.state != StepState.RUNNING)

    @Slot(object)
    def _on_controller_devices_opened(self, info: Any) -> None:
        li, ci = info.light_identity, info.camera_identity
        bench = "the simulated bench" if info.simulated else "the bench"
        self.mark_done(
            f"Connected to {bench}: {li.vendor} {li.model} ({len(info.channels)} "
            f"channels) and {ci.vendor} {ci.model}."
        )
        self.step_finished.emit(info)

    @Slot()
    def _on_controller_devices_closed(self) -> None:
        if self.state == StepState.DONE:
            self.reset()

    @Slot(object)
    def _on_controller_errored(self, exc: Any) -> None:
        if self.state == StepState.RUNNING:
            self.result_label.setStyleSheet("color: #c00000")
            self.result_label.setText(f"Cannot connect: {format_error(exc)}")
            self._set_state(StepState.FAILED)
