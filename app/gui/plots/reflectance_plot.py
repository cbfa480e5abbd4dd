"""Estimated reflectance of one patch, with its reference when known (paper Fig. 6)."""

from __future__ import annotations

from typing import Any

import numpy as np
from PySide6.QtCore import Signal, Slot
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QWidget

from tunespec.app.gui.plots.spectra_plot import SpectraPlot
from tunespec.core.intervals import COVERAGE_FACTOR_95

__all__ = ["ReflectancePlot"]


class ReflectancePlot(SpectraPlot):
    """Pick a patch, see its estimated reflectance and the reference.

    Call :meth:`set_data` after an estimate; :meth:`select_patch` (or the combo box)
    chooses the patch. ``patch_selected(name)`` is emitted when the choice changes.
    """

    patch_selected = Signal(str)

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__("Reflectance", "reflectance", None, parent)
        self.plot_item.setYRange(0.0, 1.0, padding=0.02)
        self.patch_combo = QComboBox()
        self.patch_combo.setMinimumContentsLength(10)
        row = QHBoxLayout()
        row.addWidget(QLabel("Patch"))
        row.addWidget(self.patch_combo, 1)
        self.layout().insertLayout(1, row)
        self.estimated: Any = None
        self.reference: Any = None
        self.per_patch_text: dict[str, str] = {}
        self.set_message("Estimate reflectances to see them here.")
        self.patch_combo.currentTextChanged.connect(self._on_patch_combo_changed)

    def set_data(
        self,
        estimated: Any,
        reference: Any = None,
        per_patch_text: dict[str, str] | None = None,
        std: Any = None,
    ) -> None:
        """New estimate (``Spectra`` named by patch) and optional reference ``Spectra``.

        ``per_patch_text`` maps a patch to a line shown under the plot (e.g. its
        CIEDE2000 and spectral RMS from Table 2); ``std`` (n_patches, n_wl), the
        standard uncertainty of the estimate, is drawn as a 95 % band.
        """
        self.estimated, self.reference = estimated, reference
        self.std = None if std is None else np.asarray(std, dtype=float)
        self.per_patch_text = dict(per_patch_text or {})
        current = self.patch_combo.currentText()
        self.patch_combo.blockSignals(True)
        self.patch_combo.clear()
        self.patch_combo.addItems(list(estimated.names))
        self.patch_combo.blockSignals(False)
        self.select_patch(current if current in estimated.names else estimated.names[0])

    def clear_data(self) -> None:
        """Forget the estimate (another measurement, or a retaken step)."""
        self.estimated = self.reference = None
        self.std = None
        self.per_patch_text = {}
        self.patch_combo.blockSignals(True)
        self.patch_combo.clear()
        self.patch_combo.blockSignals(False)
        self.clear()
        self.set_title("Reflectance")
        self.set_message("Estimate reflectances to see them here.")

    def select_patch(self, name: str) -> None:
        """Show patch ``name``."""
        if self.estimated is None or name not in self.estimated.names:
            return
        if self.patch_combo.currentText() != name:
            self.patch_combo.setCurrentText(name)  # re-enters through the slot
            return
        self._draw(name)

    def _draw(self, name: str) -> None:
        est = self.estimated
        self.add_curve("estimated", est.wavelength_nm, est[name], colour=(31, 119, 180))
        if self.std is not None:
            u = COVERAGE_FACTOR_95 * self.std[est.names.index(name)]
            self.set_band(
                "95 %",
                est.wavelength_nm,
                est[name] - u,
                est[name] + u,
                colour=(31, 119, 180),
            )
        else:
            self.remove_band("95 %")
        has_ref = self.reference is not None and name in self.reference.names
        if has_ref:
            ref = self.reference
            self.add_curve(
                "reference", ref.wavelength_nm, ref[name], colour=(0, 0, 0), dashed=True
            )
        else:
            self.remove_curve("reference")
        top = max(1.0, float(np.max(est[name])) * 1.05)
        self.plot_item.setYRange(0.0, top, padding=0.02)
        band = " (95 % band)" if self.std is not None else ""
        self.set_title(f"Reflectance of {name}{band}")
        text = self.per_patch_text.get(name, "")
        if not has_ref:
            text = (text + "; " if text else "") + "no reference for this patch"
        self.set_message(text)

    @Slot(str)
    def _on_patch_combo_changed(self, name: str) -> None:
        if name:
            self._draw(name)
            self.patch_selected.emit(name)
