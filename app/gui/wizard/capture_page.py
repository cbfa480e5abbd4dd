"""Wizard steps 2-4: dark frame, white background, chart under all LEDs."""

from __future__ import annotations

from typing import Any

from PySide6.QtCore import Signal
from PySide6.QtWidgets import (
    QComboBox,
    QDoubleSpinBox,
    QFormLayout,
    QHBoxLayout,
    QPushButton,
    QSpinBox,
    QWidget,
)

from tunespec.app.gui.wizard.measurement import (
    CHART_DIR,
    CaptureOptions,
    PhaseResult,
    capture_job,
)
from tunespec.app.gui.wizard.step_page import StepPage, devices_connected
from tunespec.app.gui.workers import DeviceJob

__all__ = ["CapturePage"]

#: What "Retake" takes again, by frame kind.
_RETAKE = {
    "dark": "dark frames",
    "white": "white frames",
    "target": "chart frames",
}
_NOUN = {
    "dark": "dark frame(s)",
    "white": "white-background frames",
    "target": "chart frames",
}


class CapturePage(StepPage):
    """One phase of the chart session's capture sequence.

    A clipped frame (flagged as it is taken) shows "Retake with shorter exposure"
    under the badge: :attr:`shorter_exposure_requested`, which the wizard answers.

    Parameters
    ----------
    measurement
        The shared measurement.
    kind
        ``"dark"``, ``"white"`` or ``"target"`` (a frame kind of ``core.io.session``).
    title, description
        Shown to the operator.
    """

    def __init__(
        self,
        measurement: Any,
        kind: str,
        title: str,
        description: str,
        parent: QWidget | None = None,
    ) -> None:
        super().__init__(
            measurement,
            title,
            description,
            start_text="Take frames",
            retake_text=f"Retake {_RETAKE[kind]}",
        )
        self.kind = kind
        self.key = kind
        self.options_widget: QWidget | None = None
        # under the warning badge, while a frame of the chart's is clipped
        self.shorter_button = QPushButton("Retake with shorter exposure")
        self.shorter_button.setToolTip(
            "Keep these frames aside (renamed) and take the chart session again "
            "from the dark frame: a fixed exposure a quarter as long, a metered "
            "one metered again"
        )
        self.shorter_button.hide()
        layout = self.layout()
        layout.insertWidget(layout.indexOf(self.warning_label) + 1, self.shorter_button)
        self.shorter_button.clicked.connect(self.shorter_exposure_requested)
        self.warnings_changed.connect(self._on_warnings_changed)
        self.state_changed.connect(self._on_warnings_changed)
        if kind == "dark":
            self._build_options()
            measurement.folder_changed.connect(self._on_measurement_folder_changed)
        else:  # no options: the space stays under the description
            self.body.addStretch(1)

    #: The operator asked to take the chart again with a shorter exposure.
    shorter_exposure_requested = Signal()

    def _on_warnings_changed(self, *_args: object) -> None:
        clipped = any("clipped (saturated)" in w for w in self.warnings)
        self.shorter_button.setVisible(clipped and not self.running)

    def _build_options(self) -> None:
        """Exposure, ISO, darks and repeats: set before the first frame of the session."""
        opts = self.measurement.capture_options
        self.exposure_combo = QComboBox()
        self.exposure_combo.addItem("automatic (metered per LED)", "auto")
        self.exposure_combo.addItem("fixed", "fixed")
        self.exposure_spin = QDoubleSpinBox(
            decimals=3, minimum=0.001, maximum=30.0, value=6.0, suffix=" s"
        )
        self.iso_spin = QSpinBox(
            minimum=50, maximum=6400, value=opts.iso, singleStep=100
        )
        self.darks_spin = QSpinBox(minimum=1, maximum=16, value=opts.n_darks)
        self.repeats_spin = QSpinBox(minimum=1, maximum=16, value=opts.repeats)
        self.repeats_spin.setToolTip(
            "Frames per LED, averaged: N frames have 1/N of one frame's noise "
            "variance (for per-pixel images; with as many dark frames)"
        )
        self.exposure_spin.setToolTip("Exposure of every frame (fixed exposure only)")
        # the seconds only count with a fixed exposure: greyed out otherwise
        self.exposure_combo.currentIndexChanged.connect(self._on_exposure_combo_changed)
        self._show_options(opts)
        self._on_exposure_combo_changed()
        row = QHBoxLayout()
        row.addWidget(self.exposure_combo)
        row.addWidget(self.exposure_spin)
        form = QFormLayout()
        form.addRow("Exposure", row)
        form.addRow("ISO", self.iso_spin)
        form.addRow("Dark frames", self.darks_spin)
        form.addRow("Frames per LED", self.repeats_spin)
        self.options_widget = QWidget()
        self.options_widget.setLayout(form)
        self.body.addWidget(self.options_widget)
        self.body.addStretch(1)

    def _show_options(self, opts: CaptureOptions) -> None:
        fixed = opts.exposure != "auto"
        self.exposure_combo.setCurrentIndex(1 if fixed else 0)
        if fixed:
            self.exposure_spin.setValue(float(opts.exposure))
        self.iso_spin.setValue(opts.iso)
        self.darks_spin.setValue(opts.n_darks)
        self.repeats_spin.setValue(opts.repeats)

    def _on_exposure_combo_changed(self, _index: int = 0) -> None:
        self.exposure_spin.setEnabled(self.exposure_combo.currentData() == "fixed")

    def _on_measurement_folder_changed(self, _folder: object) -> None:
        # the options of the measurement opened, not those of the previous one
        self._show_options(self.measurement.capture_options)

    def capture_options(self) -> CaptureOptions:
        """The options as set on the page (or the measurement's)."""
        if self.options_widget is None:
            return self.measurement.capture_options
        fixed = self.exposure_combo.currentData() == "fixed"
        return CaptureOptions(
            self.exposure_spin.value() if fixed else "auto",
            self.iso_spin.value(),
            self.darks_spin.value(),
            self.repeats_spin.value(),
        )

    def refresh(self) -> None:
        """Show the chart in the layout editor; lock options once frames exist."""
        self.measurement.edit_target("chart")
        if self.options_widget is not None:
            started = self.measurement.folder is not None and self.measurement.session(
                "chart"
            )
            self.options_widget.setEnabled(not started)

    def can_start(self) -> str | None:
        """Devices must be connected."""
        return devices_connected(self.measurement)

    def make_job(self) -> DeviceJob:
        """A device job capturing this phase of the chart session."""
        m = self.measurement
        if self.options_widget is not None and m.session("chart") is None:
            m.capture_options = self.capture_options()
        root = m.path(CHART_DIR)
        m.save()
        return DeviceJob(
            capture_job, root, m.chart_layout, m.capture_options, self.kind
        )

    def accept_result(self, result: PhaseResult) -> str:
        """Summary line for the operator; the dark frame step, where the exposures
        are metered, shows every warning of the chart's capture (a retake does not
        meter again, but a weak LED stays weak)."""
        if self.kind == "dark":
            self.add_warnings(self.measurement.capture_warnings("chart"))
        return result.summary(_NOUN[self.kind])

    def restore(self) -> bool:
        """Done if the chart session already holds every frame of this kind."""
        if self.measurement.phase_complete("chart", self.kind):
            # the exposures are metered in the first phase: its warnings show there
            warnings = self.measurement.capture_warnings("chart")
            self.mark_done(
                f"All {_NOUN[self.kind]} are in the session (resumed).",
                warnings=warnings if self.kind == "dark" else (),
            )
            return True
        return False
