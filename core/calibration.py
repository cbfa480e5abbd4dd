"""A camera calibration as one object: sensitivities with everything they belong to.

A calibration (``tunespec calibrate``, :func:`~tunespec.core.sensitivity.estimate_camera_sensitivity`)
is more than its three curves. The sensitivities belong to the illuminant spectra
*corrected* for the metering errors the fit found (a common wavelength shift of the
spectroradiometer, or per-LED gains and shifts of a ``"bayes"`` calibration); with
the reported spectra they give visibly worse reflectances (0.07 -> 0.37 CIEDE2000 on
the demo). A ``"bayes"`` calibration also carries the joint covariance of the
curves and the corrections, and every calibration the responses' excess variance
(:class:`~tunespec.core.excess.ExcessVariance`). :class:`Calibration` holds them
together, with the grid and where they came from, and reads and writes them together:

- a sensitivities CSV (or CGATS, or a rawtoaces JSON written by TuneSpec) with its
  side file ``NAME.meta.json`` (:func:`~tunespec.core.io.export.write_sensitivities_csv`,
  as ``calibrate`` writes them), or
- one calibration JSON holding both (:data:`CALIBRATION_FORMAT`).

Reading sensitivities without their side file is an explicit choice
(``without_side_file=True``) that warns (:class:`MissingCorrectionsWarning`); else
:meth:`Calibration.load` refuses with an :class:`~tunespec.core.errors.InputError`
naming the missing file. Sensitivities on another grid than their side file's
covariance (an older export's 5 nm rawtoaces JSON, a CSV resampled by hand) are
refused as the command line refuses them
(:func:`~tunespec.core.plausibility.check_calibration_grid`), unless the ``checks``
accept them.

The metering corrections themselves are here too, one rule each:
:func:`correct_spd_shift` (the common shift), :func:`undo_metering` (per-LED ones
where there are, else the shift) and :func:`correct_illuminants_from_meta` (the same
from a side file's dict).
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError, shown_names
from tunespec.core.excess import ExcessVariance
from tunespec.core.io.export import NOTE_KEYS
from tunespec.core.metering import suppress_meter_floor
from tunespec.core.plausibility import Checks, check_calibration_grid
from tunespec.core.spectra import Grid, Spectra, resampling_matrix

if TYPE_CHECKING:
    from tunespec.core.led_correction import LedCorrection
    from tunespec.core.readings import ReadingReplicates
    from tunespec.core.responses import Responses

__all__ = [
    "CALIBRATION_FORMAT",
    "Calibration",
    "MissingCorrectionsWarning",
    "absolute_sensitivities",
    "calibrated_sensitivities",
    "calibration_curves",
    "correct_illuminants_from_meta",
    "correct_spd_shift",
    "excess_from_meta",
    "linearise_from_meta",
    "predict_responses",
    "undo_metering",
]

#: The ``"format"`` of a calibration JSON (curves and side file in one document).
CALIBRATION_FORMAT = "tunespec-calibration"
_FORMAT_VERSION = 1
#: Keys of ``Spectra.meta`` that carry a calibration's corrections.
_CORRECTION_KEYS = (
    "spd_shift_nm",
    "led_correction",
    "excess_variance",
    "reading_replicates",
    "white_background",
    *NOTE_KEYS,
)


class MissingCorrectionsWarning(UserWarning):
    """Sensitivities loaded without the side file of their calibration: no metering
    corrections, no covariance, worse reflectances."""


@dataclass(frozen=True, eq=False)
class Calibration:
    """A camera calibration: sensitivities, metering corrections, uncertainty.

    The result of :func:`~tunespec.core.sensitivity.estimate_camera_sensitivity`
    (there also called ``SensitivityEstimate``) and of :meth:`load`.

    Parameters
    ----------
    sensitivity : Spectra, (3, n_wl)
        Sensitivities, names ``R, G, B``, on the absolute scale that makes
        :func:`~tunespec.core.forward_model.render_rgb` with the *corrected*
        illuminants (:meth:`correct_illuminants`) predict the responses (response per
        power unit and nm). Their grid (:attr:`grid`) is the one Eq. 1 is integrated
        on when estimating (:func:`~tunespec.core.wiener.on_integration_grid`).
    method
        The estimator, a key of :data:`~tunespec.core.sensitivity.SENSITIVITY_METHODS`
        (``"unknown"`` for sensitivities read without their estimator's name).
    params
        JSON-friendly details of the fit (components, weights, database size, ...).
    excluded_patches
        Patches left out because some of their responses were saturated.
    spd_shift_nm
        Wavelength-scale error of the spectroradiometer found by the fit (0 when
        no shift was fitted, see ``params["spd_shift_fitted"]``): the reported
        spectra are the true ones moved by this much towards longer wavelengths.
    led_correction
        Per-LED gains and shifts of a ``"bayes"`` calibration (they replace the
        common shift), else ``None``.
    covariance : ndarray or None
        Joint covariance of the sensitivities (``s_R, s_G, s_B`` at their
        wavelengths) and then the log gain and shift of each LED in
        ``led_correction`` order (``"bayes"`` only).
    excess
        The responses' systematic errors beyond the known noise that the chart's
        residuals show (:func:`~tunespec.core.excess.fit_excess_variance`).
    provenance
        Where the calibration came from (files read, the estimator's label, plausibility
        checks overridden), JSON-friendly strings.
    readings
        The calibration fitted again with the light's readings' noise drawn anew
        (``"bayes"`` with noisy readings, :mod:`~tunespec.core.readings`): the
        errors-in-variables term of the estimate's uncertainty.
    white_background
        The chart session's white background by Eq. 1 under each light (light ->
        reflectance, :func:`white_from_meta`): what an estimate's scale check
        compares its own session's with; ``None`` without white levels.
    """

    sensitivity: Spectra
    method: str
    params: dict[str, Any] = field(default_factory=dict)
    excluded_patches: tuple[str, ...] = ()
    spd_shift_nm: float = 0.0
    led_correction: LedCorrection | None = None
    covariance: NDArray[np.float64] | None = None
    excess: ExcessVariance | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    readings: ReadingReplicates | None = None
    white_background: dict[str, float] | None = None

    @property
    def std(self) -> NDArray[np.float64] | None:
        """Standard uncertainty of each sensitivity sample, (3, n_wl), if known: the
        covariance's (from the chart's responses) and the spread of the replicates
        fitted with the light's readings drawn anew (:attr:`readings`), added."""
        if self.covariance is None:
            return None
        wl = self.sensitivity.wavelength_nm
        var = np.maximum(np.diag(self.covariance)[: 3 * wl.size], 0.0).reshape(3, -1)
        if self.readings is not None:
            T = resampling_matrix(self.readings.wavelength_nm, wl)
            var = var + np.mean((self.readings.sensitivity_delta @ T.T) ** 2, axis=0)
        return np.sqrt(var)

    @property
    def grid(self) -> Grid:
        """The sensitivities' grid: Eq. 1 is integrated on it."""
        return self.sensitivity.grid

    def correct_illuminants(self, illuminants: Spectra) -> Spectra:
        """The illuminant spectra with the fitted metering errors undone.

        First the spectroradiometer's noise floor goes
        (:func:`~tunespec.core.metering.suppress_meter_floor`, as the calibration saw
        the spectra), then :func:`undo_metering`: each LED the per-LED correction
        knows by its own gain and offset and any other spectrum by the common
        offset, else the fitted common shift. Returns ``illuminants`` itself when
        nothing changes.
        """
        return undo_metering(
            suppress_meter_floor(illuminants), self.led_correction, self.spd_shift_nm
        )

    def corrections_for(
        self, names: Sequence[str]
    ) -> tuple[NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]:
        """Per spectrum of ``names``: its row in the LED correction (-1: not
        fitted), its gain and its wavelength shift, as :func:`undo_metering`
        applies them (without per-LED corrections: gain 1, the common shift)."""
        if self.led_correction is not None:
            return self.led_correction.lookup(names)
        n = len(names)
        return np.full(n, -1), np.ones(n), np.full(n, float(self.spd_shift_nm))

    def linearise(self, responses: Responses) -> Responses:
        """``responses`` as the calibration took its own: its sensor's non-linearity
        undone (:meth:`ExcessVariance.linearise`; as they are without one)."""
        return responses if self.excess is None else self.excess.linearise(responses)

    def side_meta(self) -> dict[str, Any]:
        """The calibration as :func:`correct_illuminants_from_meta` and the side-file
        writer read it from ``Spectra.meta`` (JSON strings)."""
        meta: dict[str, Any] = {
            "source": self.provenance.get("estimated_by", f"estimated ({self.method})"),
            "spd_shift_nm": repr(float(self.spd_shift_nm)),
        }
        if self.led_correction is not None:
            meta["led_correction"] = json.dumps(self.led_correction.as_dict())
        if self.excess is not None:
            meta["excess_variance"] = json.dumps(self.excess.as_dict())
        if self.readings is not None:
            meta["reading_replicates"] = json.dumps(self.readings.as_dict())
        if self.white_background is not None:
            meta["white_background"] = json.dumps(self.white_background)
        for key in NOTE_KEYS:
            if key in self.provenance:
                meta[key] = json.dumps(list(self.provenance[key]))
        return meta

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the calibration; returns ``path``.

        ``*.json``: one calibration JSON (:data:`CALIBRATION_FORMAT`: the curves at
        full precision and the side file's keys). Any other name: the sensitivities
        CSV and its ``.meta.json`` side file, as ``tunespec calibrate`` writes them
        (:func:`~tunespec.core.io.export.write_sensitivities_csv`).
        """
        from tunespec.core.atomic import atomic_write_text
        from tunespec.core.io.export import (
            sensitivity_meta_document,
            write_sensitivities_csv,
        )
        from tunespec.core.limits import dumps_json

        path = Path(path)
        sens = self.sensitivity
        sens = Spectra(sens.wavelength_nm, sens.values, sens.names, self.side_meta())
        if path.suffix.lower() != ".json":
            return write_sensitivities_csv(path, sens, self.covariance)
        doc: dict[str, Any] = {
            "format": CALIBRATION_FORMAT,
            "version": _FORMAT_VERSION,
            "method": self.method,
            **sensitivity_meta_document(sens, self.covariance, curves=True),
        }
        if self.excluded_patches:
            doc["excluded_patches"] = list(self.excluded_patches)
        atomic_write_text(path, dumps_json(doc, indent=1))
        return path

    @classmethod
    def load(
        cls,
        path: str | os.PathLike[str],
        *,
        without_side_file: bool = False,
        checks: Checks | None = None,
    ) -> Calibration:
        """Read a calibration written by :meth:`save` or ``tunespec calibrate``.

        Parameters
        ----------
        path
            A calibration JSON, or sensitivities (CSV, CGATS, a rawtoaces JSON
            written by TuneSpec) with their side file ``NAME.meta.json`` beside them.
        without_side_file
            Accept sensitivities whose side file is missing: no metering corrections
            and no covariance (a :class:`MissingCorrectionsWarning` says so; the
            CLI's ``--no-corrections``).
        checks
            The plausibility checks (default: refuse, no override): sensitivities
            off their side file's covariance grid
            (:func:`~tunespec.core.plausibility.check_calibration_grid`), which an
            override accepts with the covariance resampled after them.

        Raises
        ------
        InputError
            The side file is missing (and ``without_side_file`` not set), either
            file is malformed, or the sensitivities are in relative units.
        Implausible
            The sensitivities are off their covariance's grid (and ``checks`` does
            not accept it).
        """
        from tunespec.core.io.export import (
            parse_sensitivity_meta,
            sensitivity_meta_path,
        )
        from tunespec.core.limits import read_json

        path = Path(path)
        if path.suffix.lower() == ".json" and path.is_file():
            doc = read_json(path)
            if isinstance(doc, dict) and doc.get("format") == CALIBRATION_FORMAT:
                return cls._from_document(doc, path)
        sens = absolute_sensitivities(path)
        side = sensitivity_meta_path(path)
        provenance: dict[str, Any] = {"sensitivities": str(path)}
        if not side.is_file():
            if not without_side_file:
                raise InputError(
                    f"no calibration side file {side.name} next to {path.name}: "
                    "without its LED corrections results are worse (0.07 -> 0.37 "
                    "dE00 on the demo) and carry no uncertainties; copy the side "
                    "file along, or load without it (the CLI's --no-corrections)",
                    path=side,
                )
            warnings.warn(
                f"{path}: loaded without its side file {side.name}: no LED "
                "corrections, no covariance",
                MissingCorrectionsWarning,
                stacklevel=2,
            )
            return cls(sens, "unknown", provenance=provenance)
        raw = read_json(side)
        meta = parse_sensitivity_meta(raw, side)
        provenance["side_file"] = str(side)
        sens = calibration_curves(sens, meta)
        (checks or Checks())(check_calibration_grid, sens.wavelength_nm, meta)
        return cls.from_meta(sens, {**meta, **_labels(raw)}, provenance=provenance)

    @classmethod
    def _from_document(cls, doc: dict[str, Any], path: Path) -> Calibration:
        from tunespec.core.io.export import document_curves, parse_sensitivity_meta

        meta = parse_sensitivity_meta(doc, path)
        # its curves, which a calibration JSON must hold (document_curves says what
        # is missing)
        sens = meta.pop("curves", None)
        if sens is None:
            sens = document_curves(doc, path)
        provenance = {"calibration": str(path)}
        cal = cls.from_meta(sens, {**meta, **_labels(doc)}, provenance=provenance)
        excluded = doc.get("excluded_patches", [])
        if not isinstance(excluded, list):
            raise InputError("excluded_patches: expected a list of names", path=path)
        method = doc["method"] if isinstance(doc.get("method"), str) else cal.method
        return replace(cal, method=method, excluded_patches=tuple(map(str, excluded)))

    @classmethod
    def from_meta(
        cls,
        sensitivity: Spectra,
        meta: Mapping[str, Any],
        *,
        provenance: Mapping[str, Any] | None = None,
    ) -> Calibration:
        """A calibration from its sensitivities (as read, on their own grid) and the
        side file's dict (:func:`~tunespec.core.io.export.read_sensitivity_meta`).

        The sensitivities stay on their own grid, the covariance follows them there;
        their ``meta`` gets the corrections (as :meth:`side_meta`).

        Raises
        ------
        InputError
            The covariance does not fit the sensitivities and LED corrections.
        """
        from tunespec.core.led_correction import LedCorrection

        source = meta.get("meta_path")
        corr = None
        if "led_correction" in meta:
            doc = meta["led_correction"]
            corr = LedCorrection.from_dict(
                json.loads(doc) if isinstance(doc, str) else doc, path=source
            )
        cov = meta.get("covariance")
        if cov is not None:
            n_led = len(corr.names) if corr is not None else 0
            wl = np.asarray(
                meta.get("covariance_wavelength_nm", sensitivity.wavelength_nm)
            )
            expected = 3 * wl.size + 2 * n_led
            if cov.shape != (expected, expected):
                raise InputError(
                    f"covariance is {cov.shape[0]} x {cov.shape[1]}; {wl.size} "
                    f"samples per channel and {n_led} LED corrections need "
                    f"{expected} x {expected}",
                    path=source,
                )
            if wl.shape != sensitivity.wavelength_nm.shape or not np.allclose(
                wl, sensitivity.wavelength_nm
            ):
                # sensitivities on another grid, accepted with an override of
                # check_calibration_grid: the covariance follows the same linear
                # resampling, T Sigma T'
                T1 = resampling_matrix(wl, sensitivity.wavelength_nm)
                T = np.zeros((3 * T1.shape[0] + 2 * n_led, expected))
                for k in range(3):
                    T[
                        k * T1.shape[0] : (k + 1) * T1.shape[0],
                        k * wl.size : (k + 1) * wl.size,
                    ] = T1
                T[3 * T1.shape[0] :, 3 * wl.size :] = np.eye(2 * n_led)
                cov = T @ cov @ T.T
        excess = excess_from_meta(meta)
        readings = None
        if "reading_replicates" in meta:
            from tunespec.core.readings import ReadingReplicates

            doc = meta["reading_replicates"]
            readings = ReadingReplicates.from_dict(
                json.loads(doc) if isinstance(doc, str) else doc, path=source
            )
        prov = dict(provenance or {})
        label = meta.get("estimated_by")
        if isinstance(label, str) and label:
            prov["estimated_by"] = label
        for key in NOTE_KEYS:
            if isinstance(meta.get(key), list):
                prov[key] = [str(x) for x in meta[key]]
        method = "bayes" if corr is not None else "unknown"
        if (
            isinstance(label, str)
            and label.startswith("estimated (")
            and label.endswith(")")
        ):
            method = label[len("estimated (") : -1]
        cal = cls(
            sensitivity,
            method,
            spd_shift_nm=float(meta.get("spd_shift_nm", 0.0)),
            led_correction=corr,
            covariance=cov,
            excess=excess,
            provenance=prov,
            readings=readings,
            white_background=white_from_meta(meta),
        )
        return cal.synced()

    def synced(self) -> Calibration:
        """This calibration with its sensitivities' meta saying what its fields
        say (:meth:`side_meta`; the pipeline's estimate and the side-file writer
        read the corrections from there), its other keys kept."""
        s = self.sensitivity
        merged = {k: v for k, v in s.meta.items() if k not in _CORRECTION_KEYS}
        merged.update((k, v) for k, v in self.side_meta().items() if k != "source")
        sens = Spectra(s.wavelength_nm, s.values, s.names, merged)
        return replace(self, sensitivity=sens)


def _labels(doc: Any) -> dict[str, Any]:
    """The side file's estimator label (``estimated_by``; its findings,
    :data:`NOTE_KEYS`, ``parse_sensitivity_meta`` reads)."""
    if not isinstance(doc, dict):
        return {}
    return {k: doc[k] for k in ("estimated_by",) if k in doc}


def predict_responses(
    sensitivity: Spectra,
    illuminants: Spectra,
    reflectances: Spectra,
    patches: Sequence[str] | None = None,
    illuminant_names: Sequence[str] | None = None,
) -> Responses:
    """Responses that Eq. 1 predicts for known stimuli.

    Parameters
    ----------
    sensitivity : Spectra, (3, n_wl)
        Camera sensitivities R, G, B (e.g. ``Calibration.sensitivity``).
    illuminants : Spectra, (n_i, n_wl)
        Illuminant spectra on the same grid.
    reflectances : Spectra, (n_p, n_wl)
        Patch reflectances on the same grid.
    patches, illuminant_names
        Which patches and illuminants, in that order (default: all).

    Returns
    -------
    Responses
        Noise-free ``rgb`` (n_p, n_i, 3); no ``rgb_std`` etc.

    Raises
    ------
    InputError
        Unknown names (naming the spectra's source file), different grids.

    Examples
    --------
    >>> import numpy as np
    >>> from tunespec.core.spectra import Spectra
    >>> wl = np.array([500.0, 510.0])
    >>> S = Spectra(wl, np.ones((3, 2)), ("R", "G", "B"))
    >>> i = Spectra(wl, [[0.01, 0.01]], ("LED",))
    >>> r = Spectra(wl, [[0.5, 0.5]], ("white",))
    >>> predict_responses(S, i, r).rgb
    array([[[0.1, 0.1, 0.1]]])
    """
    from tunespec.core.forward_model import render_rgb
    from tunespec.core.responses import Responses
    from tunespec.core.simulate import check_rgb_sensitivity, check_same_grid

    check_same_grid(reflectances, illuminants, sensitivity)
    check_rgb_sensitivity(sensitivity)
    refl = select_named(reflectances, patches, "patch(es)")
    illum = select_named(illuminants, illuminant_names, "illuminant(s)")
    rgb = render_rgb(
        refl.values, illum.values, sensitivity.values, reflectances.step_nm
    )
    return Responses(refl.names, illum.names, rgb)


def select_named(spectra: Spectra, names: Sequence[str] | None, what: str) -> Spectra:
    """``spectra`` with only ``names`` in that order (all when ``None``); an
    InputError naming the missing ones and the spectra's file."""
    if names is None:
        return spectra
    missing = [n for n in names if n not in spectra.names]
    if missing:
        shown = shown_names(missing, 8)
        raise InputError(
            f"{len(missing)} {what} not found in the spectra: {shown}",
            path=spectra.meta.get("source"),
        )
    return spectra.select(names)


def absolute_sensitivities(path: str | os.PathLike[str]) -> Spectra:
    """Sensitivities for Eq. 1: any format, refused in relative units without a scale.

    Raises
    ------
    InputError
        The file is unreadable, or its sensitivities are normalised (no absolute
        scale: Eq. 1 needs the calibration's).
    """
    from tunespec.core.datasets import read_sensitivities

    sensitivity = read_sensitivities(path)
    if sensitivity.meta.get("relative"):
        raise InputError(
            "sensitivities in relative units (normalised, no absolute scale): Eq. 1 "
            "needs the calibration's scale; give the sensitivities CSV that "
            "'tunespec calibrate' wrote, or a rawtoaces JSON written by TuneSpec",
            path=path,
        )
    return sensitivity


def calibrated_sensitivities(
    path: str | os.PathLike[str],
) -> tuple[Spectra, dict[str, Any]]:
    """:func:`absolute_sensitivities` and their side file
    (:func:`~tunespec.core.io.export.read_sensitivity_meta`, ``{}`` without one),
    read once, the curves as :func:`calibration_curves` gives them."""
    from tunespec.core.io.export import read_sensitivity_meta

    sensitivity = absolute_sensitivities(path)
    meta = read_sensitivity_meta(path)
    return calibration_curves(sensitivity, meta), meta


#: How far (of each channel's peak) a file's sensitivities may lie from their side
#: file's curves resampled onto the file's wavelengths: a rawtoaces JSON stores
#: them normalised, its absolute scale with 10 significant digits.
CURVES_TOLERANCE = 1e-6


def calibration_curves(sensitivity: Spectra, meta: Mapping[str, Any]) -> Spectra:
    """The calibration's own curves where the file holds them resampled.

    ``export-rawtoaces`` and the export folder write rawtoaces' 5 nm samples of a
    calibration on 2 nm, with the curves themselves in the side file
    (:func:`~tunespec.core.io.export.sensitivity_meta_document`; ``meta["curves"]``
    as :func:`~tunespec.core.io.export.parse_sensitivity_meta` reads it). The 5 nm
    samples lose what the estimate needs: from them, the demo's Table 2 was 0.090
    instead of 0.048 mean CIEDE2000 and its 95 % intervals covered 0.83 of the
    reflectance samples instead of 0.97. The file must still hold those curves
    (its samples within :data:`CURVES_TOLERANCE` of their linear interpolation,
    zero where they end), so that an edited file is refused rather than
    overridden.
    """
    from tunespec.core.io.export import onto_grid

    own = meta.get("curves")
    if own is None:
        return sensitivity
    wl = sensitivity.wavelength_nm
    values = sensitivity.select(["R", "G", "B"]).values
    expected, _ = onto_grid(own.wavelength_nm, own.values, wl)
    peak = np.maximum(np.abs(own.values).max(axis=1, keepdims=True), 1e-300)
    off = np.abs(values - expected) / peak
    if off.max() > CURVES_TOLERANCE:
        k, i = np.unravel_index(int(np.argmax(off)), off.shape)
        raise InputError(
            f"the sensitivities are not those of the side file "
            f"{Path(meta['meta_path']).name} (channel {'RGB'[k]} at {wl[i]:g} nm: "
            f"{values[k, i]:.6g} against {expected[k, i]:.6g}); was one of them "
            "edited? Use the calibration's own files, or export them again",
            path=sensitivity.meta.get("source"),
        )
    return Spectra(own.wavelength_nm, own.values, own.names, sensitivity.meta)


def shift_values(
    wavelength_nm: NDArray[np.float64], values: NDArray[np.float64], shift_nm: float
) -> NDArray[np.float64]:
    """``values`` (n, n_wl) evaluated at ``wavelength_nm + shift_nm``, >= 0.

    A cubic spline, not linear interpolation: on a 5 nm grid a narrowband LED spans a
    few samples, and linear interpolation would blur it by more than the shift.
    Outside the grid the end values are held. The common-shift case of
    :func:`~tunespec.core.led_correction.apply_led_corrections`.
    """
    if shift_nm == 0.0:
        return np.asarray(values, dtype=np.float64)
    from tunespec.core.led_correction import apply_led_corrections

    n = np.atleast_2d(values).shape[0]
    return apply_led_corrections(
        wavelength_nm, np.atleast_2d(values), np.ones(n), np.full(n, float(shift_nm))
    )


def correct_spd_shift(illuminants: Spectra, spd_shift_nm: float) -> Spectra:
    """Undo a spectroradiometer's wavelength shift: ``i(l) = reported(l + shift)``.

    Parameters
    ----------
    illuminants : Spectra, (n_i, n_wl)
        Spectra as reported, on an equidistant grid.
    spd_shift_nm
        The instrument's shift (reported peaks lie this much too long), e.g.
        ``Calibration.spd_shift_nm``.

    Returns
    -------
    Spectra
        Same names and grid; cubic-spline interpolation, clipped at 0.

    Raises
    ------
    InputError
        If ``spd_shift_nm`` is not finite.

    References
    ----------
    The paper, Eq. 1 (the reported SPD enters the forward model); the shift model
    is a wavelength-scale error of the spectroradiometer (CIE 250:2022,
    spectroradiometric measurement of optical radiation sources).

    Examples
    --------
    >>> import numpy as np
    >>> from tunespec.core.spectra import Spectra
    >>> wl = np.arange(400.0, 501.0, 5.0)
    >>> led = Spectra(wl, [np.exp(-0.5 * ((wl - 451.0) / 10.0) ** 2)], ("LED",))
    >>> fixed = correct_spd_shift(led, 1.0)
    >>> float(wl[np.argmax(fixed.values[0])])
    450.0
    """
    if not np.isfinite(spd_shift_nm):
        raise InputError(
            f"spectroradiometer wavelength shift {spd_shift_nm} nm is not finite"
        )
    values = shift_values(illuminants.wavelength_nm, illuminants.values, spd_shift_nm)
    return illuminants.with_values(values)


def undo_metering(
    illuminants: Spectra, correction: LedCorrection | None, shift_nm: float
) -> Spectra:
    """The one rule that undoes a calibration's metering corrections: the per-LED
    ones where there are, else the common wavelength shift; ``illuminants`` itself
    when there is nothing to undo."""
    if correction is not None:
        return correction.apply(illuminants)
    if not shift_nm:
        return illuminants
    return correct_spd_shift(illuminants, shift_nm)


def excess_from_meta(meta: Mapping[str, Any]) -> ExcessVariance | None:
    """The side file's ``excess_variance`` (None without one); its non-linearity
    is undone in a capture's responses before any estimate (:meth:`Calibration.linearise`)."""
    if "excess_variance" not in meta:
        return None
    doc = meta["excess_variance"]
    return ExcessVariance.from_dict(
        json.loads(doc) if isinstance(doc, str) else doc, path=meta.get("meta_path")
    )


def white_from_meta(meta: Mapping[str, Any]) -> dict[str, float] | None:
    """The side file's ``white_background`` (light -> the chart session's white
    background reflectance by Eq. 1, ``core.plausibility.white_reflectance``);
    None without one."""
    if "white_background" not in meta:
        return None
    doc = meta["white_background"]
    try:
        doc = json.loads(doc) if isinstance(doc, str) else doc
        white = {str(k): float(v) for k, v in doc.items()}
    except (AttributeError, TypeError, ValueError):
        white = {}
    if not white or not all(0.0 < v < np.inf for v in white.values()):
        raise InputError(
            "white_background: expected an object of light name -> reflectance "
            "(positive numbers), as 'tunespec calibrate' writes it",
            path=meta.get("meta_path") or meta.get("source"),
        )
    return white


def linearise_from_meta(responses: Responses, meta: Mapping[str, Any]) -> Responses:
    """``responses`` with the non-linearity of the calibration whose side file is
    ``meta`` undone, as :meth:`Calibration.linearise`."""
    excess = excess_from_meta(meta)
    return responses if excess is None else excess.linearise(responses)


def correct_illuminants_from_meta(
    illuminants: Spectra, meta: Mapping[str, Any], spd_shift_nm: float | None = None
) -> Spectra:
    """Undo the light source's metering errors that a calibration found.

    The noise floor first (:func:`~tunespec.core.metering.suppress_meter_floor`, as
    the calibration saw the spectra), then the per-LED corrections of a ``"bayes"``
    calibration (``meta["led_correction"]``, a ``LedCorrection`` as JSON or a
    dict) or else the common wavelength shift (``spd_shift_nm`` if given, else
    ``meta["spd_shift_nm"]``). ``meta`` is a sensitivity's ``Spectra.meta`` or the
    ``.meta.json`` beside a sensitivities CSV.

    Raises
    ------
    InputError
        A malformed correction or shift (naming ``meta["source"]``).
    """
    source = meta.get("meta_path") or meta.get("source")
    illuminants = suppress_meter_floor(illuminants)
    doc = meta.get("led_correction")
    if doc is not None and spd_shift_nm is None:
        from tunespec.core.led_correction import LedCorrection

        if isinstance(doc, str):
            try:
                doc = json.loads(doc)
            except json.JSONDecodeError:
                raise InputError(
                    "led_correction is not valid JSON", path=source
                ) from None
        correction = LedCorrection.from_dict(doc, path=source)
        return undo_metering(illuminants, correction, 0.0)
    if spd_shift_nm is None:
        try:
            spd_shift_nm = float(meta.get("spd_shift_nm", 0.0))
        except (TypeError, ValueError):
            raise InputError("spd_shift_nm is not a number", path=source) from None
    return undo_metering(illuminants, None, spd_shift_nm)
