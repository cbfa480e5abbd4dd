"""The SPD the light source reports for its current setting."""

from __future__ import annotations

from typing import Any

import numpy as np
import pyqtgraph as pg
from PySide6.QtWidgets import QWidget

from tunespec.app.gui.plots.spectra_plot import SpectraPlot

__all__ = ["SpdPlot"]


class SpdPlot(SpectraPlot):
    """Spectral radiance measured by the light source's internal spectroradiometer.

    Fed by ``DeviceController.spd_measured``; the channel names come from the device.
    """

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(
            "Light source SPD (internal spectroradiometer)",
            "spectral radiance",
            "W sr⁻¹ m⁻² nm⁻¹",
            parent,
        )
        self.plot_item.getAxis("left").enableAutoSIPrefix(True)
        self.channel_names: list[str] = []
        self.last_spd: Any = None
        self.set_connected(False)

    def set_connected(self, connected: bool) -> None:
        """Say what to do next: connect, or switch a channel on (connected)."""
        if not connected:
            self.last_spd = None
            self.clear()
            self.set_title("Light source SPD (internal spectroradiometer)")
            self.set_message("Connect the light source to see its SPD.")
        elif self.last_spd is None:
            self.set_message(
                "Connected: switch a channel on in the Devices panel to see its SPD."
            )

    def set_channel_names(self, names: list[str]) -> None:
        """Names of the light source's channels, in device order (it is connected)."""
        self.channel_names = list(names)
        self.set_connected(True)

    def show_spd(self, spd: Any, levels: Any = None) -> None:
        """Plot ``spd`` (a ``Spectra`` with one ``"measured"`` spectrum).

        Parameters
        ----------
        spd
            The reported SPD.
        levels : (n_channels,) or None
            The levels it was measured at; used to name what is on.
        """
        self.last_spd = spd
        values = np.asarray(spd.values, dtype=float)
        self.add_curve("measured", spd.wavelength_nm, values[0], colour=(60, 60, 60))
        self.set_title(f"Light source SPD — {self._describe(levels)}")
        peak = float(np.max(values[0])) if values.size else 0.0
        if peak > 0:
            wl = spd.wavelength_nm[int(np.argmax(values[0]))]
            # the same SI prefix as the axis (µW...), not "0.00076 W"
            radiance = pg.siFormat(peak, precision=3, suffix="W sr⁻¹ m⁻² nm⁻¹")
            self.set_message(f"peak {radiance} at {wl:g} nm")
        else:
            self.set_message("all channels off")

    def _describe(self, levels: Any) -> str:
        if levels is None:
            return "current setting"
        lv = np.asarray(levels, dtype=float)
        on = np.flatnonzero(lv > 0)
        if on.size == 0:
            return "all off"
        names = [
            self.channel_names[i] if i < len(self.channel_names) else f"#{i + 1}"
            for i in on
        ]
        if on.size > 3:
            return f"{on.size} channels on"
        return ", ".join(f"{n} at {lv[i]:.0%}" for n, i in zip(names, on, strict=True))
