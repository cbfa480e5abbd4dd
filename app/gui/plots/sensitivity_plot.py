"""Estimated camera spectral sensitivities (paper Fig. 4)."""

from __future__ import annotations

from typing import Any

import numpy as np
from PySide6.QtWidgets import QWidget

from tunespec.app.gui.plots.spectra_plot import CHANNEL_COLOURS, SpectraPlot
from tunespec.core.intervals import COVERAGE_FACTOR_95

__all__ = ["SensitivityPlot"]


class SensitivityPlot(SpectraPlot):
    """R, G, B sensitivities, optionally with a reference set dashed.

    Both sets are scaled to a peak of 1 for display: the estimate is on the absolute
    scale of the responses, a database curve on its own.
    """

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("Camera sensitivities", "relative sensitivity", None, parent)
        self.set_message("Calibrate to see the estimated sensitivities.")
        self.sensitivity: Any = None

    def clear_data(self) -> None:
        """Forget the shown sensitivities."""
        self.sensitivity = None
        self.clear()
        self.set_message("Calibrate to see the estimated sensitivities.")

    def show_sensitivity(
        self,
        sensitivity: Any,
        reference: Any = None,
        *,
        label: str = "estimated",
        reference_label: str = "reference",
        std: Any = None,
    ) -> None:
        """Plot ``sensitivity`` (``Spectra`` R, G, B) and a dashed ``reference``.

        ``std`` (3, n_wl), the standard uncertainty of ``sensitivity``, is drawn as
        a 95 % band around each channel.
        """
        self.sensitivity = sensitivity
        self.clear()
        if std is not None:
            values = np.asarray(sensitivity.values, dtype=float)
            peak = float(np.max(values)) or 1.0
            u = COVERAGE_FACTOR_95 * np.asarray(std, dtype=float) / peak
            for name, row, uk in zip(sensitivity.names, values / peak, u, strict=True):
                self.set_band(
                    f"{name} 95 %",
                    sensitivity.wavelength_nm,
                    row - uk,
                    row + uk,
                    colour=CHANNEL_COLOURS.get(name, (0, 0, 0)),
                )
            self.set_title("Camera sensitivities (95 % bands)")
        for spectra, dashed, tag in (
            (sensitivity, False, "estimated"),
            (reference, True, reference_label),
        ):
            if spectra is None:
                continue
            values = np.asarray(spectra.values, dtype=float)
            peak = float(np.max(values)) or 1.0
            for name, row in zip(spectra.names, values, strict=True):
                self.add_curve(
                    f"{name} {tag}",
                    spectra.wavelength_nm,
                    row / peak,
                    colour=CHANNEL_COLOURS.get(name, (0, 0, 0)),
                    dashed=dashed,
                    width=1.5 if dashed else 2.0,
                )
        text = label
        if reference is not None:
            text += f"; dashed: {reference_label}"
        self.set_message(text + " (each set scaled to a peak of 1)")
