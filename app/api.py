"""TuneSpec's Python API: the command line's steps as functions, with its answers.

Each function runs the code the command line and ``tunespec run`` run (the pipeline's
steps in :mod:`tunespec.app.pipeline`, not a chain of its own), checks its inputs as
they do (readers with file and line, :mod:`tunespec.core.limits`, the plausibility
checks) and returns a documented object:

=====================  ===============================  ==========================
function               what it runs                     returns
=====================  ===============================  ==========================
:func:`calibrate`      ``calibrate`` (the pipeline's)   :class:`CalibrationResult`
:func:`estimate`       ``estimate`` (corrections,       :class:`EstimateResult`
                       integration grid, Wiener)
:func:`evaluate`       ``evaluate`` (Table 2)           ``ReflectanceStats``
:func:`extract`        ``extract``                      ``Extraction``
:func:`estimate_images`  ``estimate-image``             :class:`ImagesResult`
=====================  ===============================  ==========================

A calibration is one object, :class:`~tunespec.core.calibration.Calibration`
(:func:`load_calibration`): its sensitivities come with the light source's metering
corrections and the integration grid they belong to, so :func:`estimate` gives the
command line's reflectances (0.07 CIEDE2000 on the demo, where the bare Wiener
estimate with the reported spectra gives 0.37).

Spectral inputs are files (any format the command line reads), :class:`Spectra`, or
colour-science ``SpectralDistribution`` / ``MultiSpectralDistributions``
(:func:`from_colour`); :func:`to_colour` converts results back.

Examples
--------
See ``docs/api-example.ipynb``::

    from tunespec.app import api
    cal = api.load_calibration("export/sensitivities.csv")
    est = api.estimate("export/responses.csv", "export/illuminants.csv", cal,
                       reference="export/reference_reflectances.csv")
    print(est.table2.format_table())
"""

from __future__ import annotations

import tempfile
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tunespec.core.calibration import Calibration
from tunespec.core.errors import InputError, check_names
from tunespec.core.responses import Responses
from tunespec.core.spectra import CALIBRATION_GRID, Grid, Spectra

if TYPE_CHECKING:
    from tunespec.app.pipeline.extract import Extraction
    from tunespec.app.pipeline.image import ImageSettings
    from tunespec.core.colorimetry import ReflectanceStats
    from tunespec.core.layout import TargetLayout
    from tunespec.core.stats import PredictionStats
    from tunespec.core.uncertainty import ReflectanceUncertainty

__all__ = [
    "Calibration",
    "CalibrationResult",
    "EstimateResult",
    "ImagesResult",
    "Stimuli",
    "calibrate",
    "estimate",
    "estimate_images",
    "evaluate",
    "extract",
    "from_colour",
    "load_calibration",
    "read_stimuli",
    "to_colour",
]

#: How a plausibility refusal tells an API caller to accept (``Checks.force_hint``).
_FORCE_HINT = "force=True"

SpectralInput = (
    Any  # a path, Spectra, or a colour-science (Multi)SpectralDistribution(s)
)


# -- documented results --------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Stimuli:
    """Responses of a target and the illuminant spectra they were captured under.

    What ``tunespec process`` writes (``responses.csv``, ``illuminants.csv``) and
    what the pipeline's calibrate and estimate steps read of a processed session.

    Parameters
    ----------
    responses
        Mean RGB (full scale) of each patch under each illuminant, with their noise.
    illuminants
        The reported spectrum of each illuminant (x exposure), named as the
        responses' illuminants.
    """

    responses: Responses
    illuminants: Spectra


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """What :func:`calibrate` returns.

    Parameters
    ----------
    calibration
        Sensitivities with their metering corrections, covariance and excess
        variance (:meth:`~tunespec.core.calibration.Calibration.save` writes what
        ``tunespec calibrate`` writes).
    table1
        The paper's Table 1: how well the sensitivities predict the chart's RGB.
    patch_rgb_error
        Table 1's RGB error per fitted patch.
    self_check
        The calibration's self-check (``check=True``), else ``None``.
    forced
        Plausibility checks accepted with ``force=True``, one line each.
    """

    calibration: Calibration
    table1: PredictionStats
    patch_rgb_error: Mapping[str, float] = field(default_factory=dict)
    self_check: Any = None
    forced: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class EstimateResult:
    """What :func:`estimate` returns.

    Parameters
    ----------
    reflectance
        Estimated reflectance factors (0-1) of each patch on ``grid``.
    grid
        The estimation grid.
    table2
        The paper's Table 2 against ``reference`` (CIEDE2000 D50, spectral RMS),
        ``None`` without a reference.
    uncertainty
        Standard uncertainties of the reflectances and of their XYZ and CIELAB
        (a ``"bayes"`` calibration with its covariance), else ``None``.
    clipped
        Patches whose estimate was clipped to [0, 1].
    forced
        Plausibility checks accepted with ``force=True``, one line each.
    """

    reflectance: Spectra
    grid: Grid
    table2: ReflectanceStats | None = None
    uncertainty: ReflectanceUncertainty | None = None
    clipped: tuple[str, ...] = ()
    forced: tuple[str, ...] = ()


@dataclass(frozen=True)
class ImagesResult:
    """What :func:`estimate_images` returns.

    Parameters
    ----------
    out_dir
        The folder with the per-pixel images (reflectance, XYZ, L*a*b*, their
        uncertainties; see ``docs/user-guide.md``).
    provenance
        What ``provenance.json`` there says (inputs, settings, files, shape).
    """

    out_dir: Path
    provenance: dict[str, Any]


# -- colour-science at the boundary ----------------------------------------------------
def to_colour(spectra: Spectra) -> Any:
    """``spectra`` as a colour-science ``MultiSpectralDistributions`` (labels the
    names; one spectrum: ``to_colour(s).to_sds()[0]`` is its ``SpectralDistribution``).
    """
    from colour import MultiSpectralDistributions

    return MultiSpectralDistributions(
        spectra.values.T.copy(),
        spectra.wavelength_nm.copy(),
        labels=list(spectra.names),
        name=str(spectra.meta.get("source", "TuneSpec")),
    )


def from_colour(obj: Any, *, kind: str = "spectra", what: str = "spectra") -> Spectra:
    """A colour-science ``SpectralDistribution`` or ``MultiSpectralDistributions``
    (or a list of ``SpectralDistribution`` on one domain) as :class:`Spectra`,
    checked as a file of ``kind`` is (finite, non-negative, wavelengths rising; a
    reflectance in percent is converted, an illuminant's meter floor removed).

    Raises
    ------
    InputError
        Not a colour-science spectral object, or values a file could not hold
        (naming ``what``).
    """
    from colour import MultiSpectralDistributions, SpectralDistribution

    if isinstance(obj, (list, tuple)) and all(
        isinstance(s, SpectralDistribution) for s in obj
    ):
        if not obj:
            raise InputError(f"{what}: no spectral distributions given")
        obj = MultiSpectralDistributions(obj)
    if isinstance(obj, MultiSpectralDistributions):
        names = tuple(str(n) for n in obj.labels)
        values = np.asarray(obj.values, dtype=np.float64).T
    elif isinstance(obj, SpectralDistribution):
        names = (str(obj.name),)
        values = np.asarray(obj.values, dtype=np.float64)[None, :]
    else:
        raise InputError(
            f"{what}: expected a file, Spectra or a colour-science "
            f"SpectralDistribution/MultiSpectralDistributions, got {type(obj).__name__}"
        )
    wl = np.asarray(obj.wavelengths, dtype=np.float64)
    return _checked(Spectra(wl, values, names, {"source": what}), kind, what)


def _checked(spectra: Spectra, kind: str, what: str) -> Spectra:
    """The value checks and unit conversions of :func:`~tunespec.core.io.spectral.
    read_spectral` for spectra that come from memory."""
    from tunespec.core.io.spectral import MAX_VALUE, to_reflectance_factor
    from tunespec.core.metering import suppress_meter_floor

    v, wl = spectra.values, spectra.wavelength_nm
    if wl.size < 2 or not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
        raise InputError(f"{what}: wavelengths must be finite and rising")
    if not np.all(np.isfinite(v)):
        raise InputError(f"{what}: NaN or infinite values")
    if np.any(v < 0) or np.any(v > MAX_VALUE):
        raise InputError(f"{what}: values must lie in [0, {MAX_VALUE:g}]")
    if kind == "reflectance":
        return to_reflectance_factor(spectra, source=what)
    if kind == "illuminant":
        return suppress_meter_floor(spectra)
    return spectra


def _spectra(value: SpectralInput, kind: str, what: str) -> Spectra:
    """A spectral input (file, Spectra, colour-science object) read and checked."""
    if isinstance(value, (str, PathLike)):
        from tunespec.core.io.spectral import read_spectral

        return read_spectral(value, kind=kind)
    if isinstance(value, Spectra):
        return _checked(value, kind, what)
    return from_colour(value, kind=kind, what=what)


def _grid(value: Grid | str | None, default: Grid) -> Grid:
    if value is None:
        return default
    return value if isinstance(value, Grid) else Grid.parse(str(value))


# -- inputs ----------------------------------------------------------------------------
def load_calibration(
    path: str | PathLike[str],
    *,
    without_side_file: bool = False,
    force: bool = False,
) -> Calibration:
    """:meth:`Calibration.load <tunespec.core.calibration.Calibration.load>`: the
    sensitivities CSV with its ``.meta.json`` side file, or a calibration JSON.
    ``force`` accepts sensitivities off their covariance's grid (with a warning),
    as ``estimate --force`` does."""
    from tunespec.core import plausibility as pl

    checks = pl.Checks(
        force=force,
        force_hint=_FORCE_HINT,
        warn=lambda line: warnings.warn(line, stacklevel=3),
    )
    return Calibration.load(path, without_side_file=without_side_file, checks=checks)


def read_stimuli(
    responses: str | PathLike[str] | Responses,
    illuminants: SpectralInput,
) -> Stimuli:
    """Responses and their illuminants, read and checked as ``estimate`` and
    ``calibrate`` read them; every illuminant of the responses must be there.

    Raises
    ------
    InputError
        A file unreadable or malformed (file and line), an illuminant missing.
    """
    from tunespec.core.io.responses_csv import read_responses_csv

    resp = (
        responses if isinstance(responses, Responses) else read_responses_csv(responses)
    )
    illum = _spectra(illuminants, "illuminant", "illuminants")
    check_names(
        resp.illuminants,
        illum.names,
        "{n} illuminant name(s) of the responses are not in the illuminants: {names}",
        path=illum.meta.get("source"),
        limit=6,
    )
    return Stimuli(resp, illum)


# -- the steps ---------------------------------------------------------------------------
def calibrate(
    responses: str | PathLike[str] | Responses,
    illuminants: SpectralInput,
    reflectances: SpectralInput = None,
    *,
    method: str | None = None,
    grid: Grid | str | None = None,
    check: bool = False,
    force: bool = False,
) -> CalibrationResult:
    """Camera sensitivities from a chart's responses (``tunespec calibrate``).

    Parameters
    ----------
    responses, illuminants
        The chart's responses and the illuminants' reported spectra
        (:func:`read_stimuli`).
    reflectances
        The chart's reference reflectances (default the shipped ColorChecker SG).
    method
        A sensitivity method (``tunespec calibrate --method``; default ``bayes``).
    grid
        Working grid (``"380:730:2"`` or a :class:`Grid`; default the pipeline's
        calibration grid).
    check
        Run the calibration's self-check too (``--check``).
    force
        Accept a fit the plausibility checks refuse (``--force``; a chart whose
        responses bend more than a raw sensor's).
    """
    from tunespec.app.pipeline import steps
    from tunespec.core import plausibility as pl
    from tunespec.core.sensitivity import SENSITIVITY_METHODS

    if method is not None and method not in SENSITIVITY_METHODS:
        raise InputError(
            f"unknown method {method!r}; expected one of {', '.join(SENSITIVITY_METHODS)}"
        )
    chart = read_stimuli(responses, illuminants)
    refl = (
        None
        if reflectances is None
        else _spectra(reflectances, "reflectance", "reflectances")
    )
    checks = pl.Checks(force=force, force_hint=_FORCE_HINT)
    done = steps.calibrate(
        chart,
        refl,
        method=method,
        grid=_grid(grid, CALIBRATION_GRID),
        check=check,
        checks=checks,
    )
    return CalibrationResult(
        done.estimate,
        done.table1,
        dict(done.patch_rgb_error or {}),
        done.self_check,
        tuple(checks.overridden),
    )


def _where(cal: Calibration) -> str | None:
    """The file a calibration was read from (None: made in memory)."""
    return cal.provenance.get("sensitivities") or cal.provenance.get("calibration")


def _warn_of(cal: Calibration) -> None:
    """What the calibration found about itself (its warnings, the checks accepted
    with ``force``) as Python warnings: its estimates inherit them, as the
    commands repeat them."""
    from tunespec.core.plausibility import calibration_notes

    for line in calibration_notes(cal.provenance, _where(cal)):
        warnings.warn(line, stacklevel=3)


def estimate(
    responses: str | PathLike[str] | Responses,
    illuminants: SpectralInput,
    calibration: Calibration | str | PathLike[str],
    *,
    prior: SpectralInput = None,
    reference: SpectralInput = None,
    grid: Grid | str | None = None,
    force: bool = False,
) -> EstimateResult:
    """Reflectances from a target's responses (``tunespec estimate``; with a
    reference, Table 2 as ``evaluate`` gives it).

    The calibration's metering corrections are applied to the reported
    illuminants, Eq. 1 is integrated on the sensitivities' grid and the Wiener
    estimate computed on ``grid``: the pipeline's estimate step, the one
    ``tunespec run`` and ``demo`` run.

    Parameters
    ----------
    responses, illuminants
        The target's responses and its illuminants' reported spectra.
    calibration
        A :class:`Calibration` or the path :func:`load_calibration` reads (the
        side file is required).
    prior
        Training reflectances of the Wiener prior (default the ColorChecker SG).
    reference
        Reference reflectances of the patches, for Table 2.
    grid
        Estimation grid (default ``400:700:5``, the pipeline's).
    force
        Accept inputs the plausibility checks refuse (``--force``).

    Raises
    ------
    InputError
        Unreadable or implausible inputs (as the command line refuses them).
    """
    from tunespec.app.pipeline import steps
    from tunespec.app.pipeline.plan import ESTIMATION_GRID
    from tunespec.core import plausibility as pl

    checks = pl.Checks(force=force, force_hint=_FORCE_HINT)
    cal = (
        calibration
        if isinstance(calibration, Calibration)
        else Calibration.load(calibration, checks=checks)
    )
    _warn_of(cal)
    sample = read_stimuli(responses, illuminants)
    work = _grid(grid, ESTIMATION_GRID)
    where = _where(cal)
    checks(pl.check_absolute_sensitivities, cal.sensitivity.values, where)
    prior_spectra = None
    if prior is not None:
        prior_spectra = _spectra(prior, "reflectance", "prior")
        checks(pl.check_prior_size, len(prior_spectra.names), "prior")
    ref = None if reference is None else _spectra(reference, "reflectance", "reference")
    inputs = [
        ("illuminants", sample.illuminants.wavelength_nm),
        ("sensitivities", cal.sensitivity.wavelength_nm),
    ]
    if prior_spectra is not None:
        inputs.append(("prior", prior_spectra.wavelength_nm))
    checks(pl.check_coverage, inputs, "estimate", grid_nm=work.wavelength_nm)
    done = steps.estimate(
        sample,  # type: ignore[arg-type]  # the step reads .responses and .illuminants
        cal.sensitivity,
        prior=prior_spectra,
        reference=ref,
        grid=work,
        calibration=cal,
        checks=checks,
    )
    for line in done.warnings:
        warnings.warn(line, stacklevel=2)
    wiener = done.wiener
    return EstimateResult(
        wiener.reflectance,
        work,
        done.table2,
        done.uncertainty,
        tuple(wiener.clipped),
        done.forced,
    )


def evaluate(
    estimated: SpectralInput,
    reference: SpectralInput,
    *,
    grid: Grid | str | None = None,
) -> ReflectanceStats:
    """Table 2: estimated against reference reflectances (``tunespec evaluate``).

    ``grid`` as ``--grid`` (default: from the data, as the command line finds it);
    ``.format_table()`` prints it, ``.as_dict()`` is the ``--stats`` JSON.
    """
    from tunespec.app.pipeline import steps
    from tunespec.core.spectra import grid_from_data

    est = _spectra(estimated, "reflectance", "estimated")
    ref = _spectra(reference, "reflectance", "reference")
    work = _grid(grid, None) if grid is not None else grid_from_data([est, ref])
    return steps.evaluate(
        est.resample(work, source=est.meta.get("source")),
        ref.resample(work, source=ref.meta.get("source")),
    )


def extract(
    image: str | PathLike[str],
    layout: str | PathLike[str] | TargetLayout,
    *,
    corners_px: Any = None,
    reflectances: SpectralInput = None,
    illuminant: str | None = None,
    force: bool = False,
    preview: str | PathLike[str] | None = None,
) -> Extraction:
    """Patch responses of a chart in one photograph (``tunespec extract``).

    ``layout`` a layout file, a shipped layout's name or a
    :class:`~tunespec.core.layout.TargetLayout`; ``corners_px`` (4, 2) its corners
    TL, TR, BR, BL in pixels (default found); ``reflectances`` the chart's reference
    for the check (default the layout's own, as the command's); ``force`` keeps an
    extraction that fails its check. ``Extraction.responses`` are the responses;
    :func:`tunespec.app.pipeline.extract.write_extraction` writes them.
    """
    from tunespec.app.pipeline.extract import extract_chart, layout_reference
    from tunespec.core.layout import TargetLayout

    lay = layout if isinstance(layout, TargetLayout) else TargetLayout.load(layout)
    if reflectances is None:
        where = None if isinstance(layout, TargetLayout) else layout
        refl = layout_reference(lay, None, where)
    else:
        refl = _spectra(reflectances, "reflectance", "reflectances")
    if corners_px is not None:
        corners_px = np.asarray(corners_px, dtype=np.float64)
        if corners_px.shape != (4, 2) or not np.all(np.isfinite(corners_px)):
            raise InputError("corners_px: expected 4 finite (x, y) pixel positions")
    return extract_chart(
        image, lay, corners_px=corners_px, reflectances=refl,
        illuminant=illuminant, force=force, preview=preview,
    )  # fmt: skip


def estimate_images(
    session_dir: str | PathLike[str],
    calibration: Calibration | str | PathLike[str],
    out_dir: str | PathLike[str],
    *,
    settings: ImageSettings | None = None,
    scheduler: Any = "sync",
) -> ImagesResult:
    """Per-pixel reflectance images of a captured session (``tunespec
    estimate-image``): the pipeline's image job.

    ``calibration`` a path (its side file is required, as :func:`load_calibration`
    checks) or a :class:`Calibration` (written to a temporary folder for the job
    unless it was loaded from a file that is still there). ``settings``: grid,
    rectification, noise model (:class:`tunespec.app.pipeline.image.ImageSettings`);
    ``scheduler`` as ``--scheduler`` (default: this process, no threads).
    """
    from tunespec.app.pipeline.image import ImageSettings
    from tunespec.app.pipeline.image import estimate_images as job

    session = Path(session_dir)
    if not (session / "manifest.json").is_file():
        raise InputError("not a session folder (no manifest.json)", path=session)
    settings = settings if settings is not None else ImageSettings()
    if isinstance(calibration, Calibration):
        _warn_of(calibration)
        path = calibration.provenance.get("sensitivities")
        if path and Path(path).is_file():
            Calibration.load(path)  # its side file still there
            prov = job(session, path, out_dir, settings=settings, scheduler=scheduler)
            return ImagesResult(Path(out_dir), prov)
        with tempfile.TemporaryDirectory() as tmp:
            saved = calibration.save(Path(tmp) / "sensitivities.csv")
            prov = job(session, saved, out_dir, settings=settings, scheduler=scheduler)
            return ImagesResult(Path(out_dir), prov)
    _warn_of(load_calibration(calibration))  # refuses a missing side file
    prov = job(session, calibration, out_dir, settings=settings, scheduler=scheduler)
    return ImagesResult(Path(out_dir), prov)
