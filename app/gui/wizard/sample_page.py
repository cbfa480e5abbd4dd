"""Wizard step 6: capture the sample target (its own dark, white and target frames)."""

from __future__ import annotations

from typing import Any

from PySide6.QtWidgets import QWidget

from tunespec.app.gui.wizard.measurement import SAMPLE_DIR, PhaseResult, capture_job
from tunespec.app.gui.wizard.step_page import StepPage, devices_connected
from tunespec.app.gui.workers import DeviceJob

__all__ = ["SamplePage"]


class SamplePage(StepPage):
    """Captures the whole sample session (metering, dark, white, sample frames).

    On hardware the operator is asked to swap the white board and the sample when
    the sequence needs it; on the simulated bench the scene changes by itself.
    """

    key = "sample"

    step_title = "Sample target"
    step_description = (
        "Take the chart away. The sample target is captured like the chart: "
        "dark frame, white background and the <b>sample</b> under every LED; "
        "you are asked when to put the white board and the sample in place."
    )
    step_start_text = "Capture sample"
    step_retake_text = "Retake sample frames"

    def __init__(self, measurement: Any, parent: QWidget | None = None) -> None:
        super().__init__(measurement)
        self.body.addStretch(1)

    def refresh(self) -> None:
        """Show the sample's layout in the editor."""
        self.measurement.edit_target("sample")

    def can_start(self) -> str | None:
        """Devices must be connected."""
        return devices_connected(self.measurement)

    def make_job(self) -> DeviceJob:
        """A device job capturing the whole sample session."""
        m = self.measurement
        root = m.path(SAMPLE_DIR)
        m.save()
        # same board, same LEDs: the chart's metered exposures suit the sample too
        exposure = None
        chart = m.session("chart")
        if m.capture_options.exposure == "auto" and chart and chart.settings.resolved:
            exposure = {c: t[0] for c, t in chart.settings.exposures_s.items()}
        return DeviceJob(
            capture_job,
            root,
            m.sample_layout,
            m.capture_options,
            None,
            exposure=exposure,
        )

    def accept_result(self, result: PhaseResult) -> str:
        """Summary line for the operator (and every warning of the sample's capture)."""
        self.add_warnings(self.measurement.capture_warnings("sample"))
        return result.summary("frames", "sample session")

    def restore(self) -> bool:
        """Done if the sample session is complete."""
        if self.measurement.phase_complete("sample", None):
            self.mark_done(
                "The sample session is complete (resumed).",
                warnings=self.measurement.capture_warnings("sample"),
            )
            return True
        return False
