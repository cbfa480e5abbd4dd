"""Processing a gonio session: per-geometry responses, spectra, single-shot XYZ, fusion.

For each geometry of a captured session (:mod:`tunespec.app.pipeline.gonio`):

1. dark subtraction; the target's corners are found again in the mix frame (its
   projection changes with the viewing angle, :func:`tunespec.core.homography.
   locate_target`); the ROIs follow from the layout;
2. the calibration's non-linearity is undone in every frame (``core.excess.
   linearised``), then each illuminant's brackets are merged per ROI pixel
   (:func:`tunespec.core.hdr.merge_brackets`) into responses whose noise and
   saturation flags go into Eq. 6; the brackets must scale with their exposures
   (:func:`tunespec.core.hdr.fit_bracket_bend`), or the geometry is warned of;
3. the illuminants of Eq. 1 are the measured SPDs times the base exposure times
   ``cos theta_i`` read back from the goniometer (responses are reflectance factors
   against a perfect diffuser at that geometry);

then spectra by Wiener estimation (Eq. 5-6) where the 22 LEDs were captured,
single-shot XYZ (D50) everywhere and fused spectra at the other geometries.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.app.pipeline.gonio import DARK, HDR_EXPOSURES, MIX, GonioPlan
from tunespec.core.calibration import excess_from_meta
from tunespec.core.colorimetry import astm_e308_weights_d50, xyz_d50, xyz_to_lab_d50
from tunespec.core.errors import InputError
from tunespec.core.excess import linearised
from tunespec.core.fusion import fuse_patch, fused_covariance, material_prior
from tunespec.core.hdr import (
    HdrImage,
    fit_bracket_bend,
    hdr_patch_responses,
    merge_brackets,
)
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import read_json
from tunespec.core.metering import suppress_meter_floor
from tunespec.core.plausibility import NO_BRACKETS_WARNING
from tunespec.core.processing import illuminants_from_spds
from tunespec.core.progress import (
    ProgressFn,
    StopFn,
    check_stop,
    report,
    sub_progress,
)
from tunespec.core.responses import Responses
from tunespec.core.single_shot import apply_xyz_transform, xyz_transform
from tunespec.core.spectra import DEFAULT_GRID, Spectra
from tunespec.core.wiener import wiener_reflectance

__all__ = [
    "Correction",
    "GeometryData",
    "GonioResult",
    "calibration_correction",
    "geometry_label",
    "process_gonio",
]

#: Undoes metering errors on the illuminants of one geometry (names: mix, LEDs).
Correction = Callable[[Spectra], Spectra]

#: Flat (specular) offsets added to the prior's spectra: a glossy sample's reflectance
#: factor near the specular peak is its body colour plus a flat surface reflection.
SPECULAR_OFFSETS = (0.1, 0.3, 1.0, 3.0)
#: The single-shot transform of a session: a few materials' families of spectra are
#: fitted closer by the degree-3 root-polynomial (measured on the simulated bench,
#: seeds 1 and 2: fused D50 colorimetry 0.48 -> 0.39-0.40 mean dE00), with relative
#: row weights (the near-black patch).
SESSION_KIND = "root-polynomial-3"
#: Offsets of the single-shot prior built from the session's spectral estimates.
SESSION_OFFSETS = (0.03, 0.1, 0.3, 0.6, 1.0, 1.5, 3.0)


@dataclass(frozen=True, eq=False)
class GeometryData:
    """One geometry's responses (mix first, then LEDs) and Eq. 1 illuminants."""

    index: int
    position: dict[str, float]
    responses: Responses
    illuminants: Spectra
    corners_px: NDArray[np.float64]
    #: What the geometry's frames say against their use (``core.plausibility``).
    warnings: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class GonioResult:
    """Spectra and colorimetry of every patch at every geometry.

    ``reflectance`` (n_p, n_g, n_wl); ``u_reflectance`` its standard uncertainty:
    the Wiener posterior std at spectral geometries, at fused ones the single
    shot's XYZ covariance and the prior spectrum's propagated through the fusion
    (:func:`tunespec.core.fusion.fused_covariance`); ``xyz``, ``u_xyz`` (n_p, n_g,
    3) the single-shot XYZ (D50) and its standard uncertainty; ``lab`` of the final
    spectra (which reproduce ``xyz`` at fused geometries) and ``u_lab`` its standard
    uncertainty (from the spectra's, first order); ``spectral`` (n_g,) bool.
    """

    patches: tuple[str, ...]
    plan: GonioPlan
    positions: list[dict[str, float]]
    wavelength_nm: NDArray[np.float64]
    reflectance: NDArray[np.float64]
    u_reflectance: NDArray[np.float64]
    xyz: NDArray[np.float64]
    u_xyz: NDArray[np.float64]
    lab: NDArray[np.float64]
    spectral: NDArray[np.bool_]
    u_lab: NDArray[np.float64]
    #: The geometries' warnings, each naming its geometry.
    warnings: tuple[str, ...] = ()


def _roi_pixels(
    layout: TargetLayout, corners: NDArray[np.float64], shape: tuple[int, int]
) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    import cv2

    out = []
    for quad in layout.with_corners(corners).roi_quads_px():
        mask = np.zeros(shape, np.uint8)
        cv2.fillPoly(mask, [np.round(quad * 16).astype(np.int32)], 1, shift=4)
        yy, xx = np.nonzero(mask)
        if yy.size < 4:
            raise InputError("a patch ROI has fewer than 4 pixels at this geometry")
        out.append((yy, xx))
    return out


#: The extraction check's uniformity limit at a gonio geometry (see _check_geometry).
GONIO_MAX_EXCESS_SPREAD = 0.35


def geometry_label(index: int, position: Any) -> str:
    """How a message names geometry ``index`` (0-based): ``geometry 3 (theta_i 45,
    theta_r 30)``, its angles as read back (``position.json``) where known."""
    where = ", ".join(
        f"{k} {position[k]:g}"
        for k in ("theta_i", "theta_r")
        if isinstance(position, dict) and isinstance(position.get(k), int | float)
    )
    return f"geometry {index + 1}" + (f" ({where})" if where else "")


def _check_geometry(
    frame: NDArray[np.float64],
    layout: TargetLayout,
    corners: NDArray[np.float64],
    index: int,
    position: Any,
) -> None:
    """The extraction check (ROI uniformity) of one geometry's mix frame; an
    InputError naming the geometry when the ROIs do not sit on the patches."""
    from tunespec.core.extraction import check_extraction, patch_statistics

    stats = patch_statistics(frame, layout.with_corners(corners).roi_quads_px())
    # near the specular direction a glossy patch has a gradient across it (12 % on
    # the demo's 45/50 geometry); an ROI across a patch edge spreads far more
    check = check_extraction(
        layout.patch_names, stats, max_excess_spread=GONIO_MAX_EXCESS_SPREAD
    )
    if not check.ok:
        raise InputError(
            f"{geometry_label(index, position)}: patch extraction refused: "
            f"{check.summary()}"
        )


def _load(gdir: Path, name: str, k: int) -> NDArray[np.float64]:
    path = gdir / f"{name}_e{k}.npy"
    if not path.exists():
        raise InputError(f"missing frame {path}: resume the capture first")
    arr = np.load(path, allow_pickle=False)
    if arr.ndim != 3 or arr.shape[0] != 3 or not np.all(np.isfinite(arr)):
        raise InputError(f"{path}: expected a finite 3 x H x W frame")
    return arr.astype(np.float64)


def _process_geometry(gdir: Path, index: int, plan: GonioPlan, layout: TargetLayout,
                      leds: list[str], correct: Correction | None,
                      gamma: float) -> GeometryData:  # fmt: skip
    """One geometry's responses and illuminants, from frames of a sensor whose
    response is ``x^(1 + gamma)`` (the calibration's); an InputError names the
    geometry (its number and read-back angles) and its folder."""
    pos_path = gdir / "position.json"
    position = read_json(pos_path) if pos_path.exists() else None
    where = f"{geometry_label(index, position)}, {gdir.name}"
    try:
        data = _geometry_data(gdir, index, plan, layout, leds, correct, position, gamma)
    except InputError as exc:
        if str(exc).startswith(f"geometry {index + 1}"):
            raise
        raise InputError(f"{where}: {exc}") from exc
    return replace(data, warnings=tuple(f"{where}: {w}" for w in data.warnings))


def _geometry_data(gdir: Path, index: int, plan: GonioPlan, layout: TargetLayout,
                   leds: list[str], correct: Correction | None,
                   position: Any, gamma: float) -> GeometryData:  # fmt: skip
    from tunespec.core.homography import locate_target
    from tunespec.core.plausibility import bracket_bend_warning

    step = plan.steps[index]
    rel = HDR_EXPOSURES if step.hdr else (1.0,)
    dark = _load(gdir, DARK, 0)
    # the shortest bracket first (a specular lobe saturates the longer ones), a
    # longer one where the shortest is too dark to follow the target's sides
    for k in range(len(rel) - 1, -1, -1):
        frame = _load(gdir, MIX, k) - dark
        try:
            corners, _ = locate_target(frame[1], layout)
            break
        except InputError:
            if k == 0:
                raise
    if position is None:
        raise InputError(f"missing {gdir / 'position.json'}: resume the capture first")
    _check_geometry(frame, layout, corners, index, position)
    rois = _roi_pixels(layout, corners, frame.shape[1:])
    exposures = read_json(gdir / "exposure.json")
    cos_i = math.cos(math.radians(abs(float(position["theta_i"]))))
    names = [MIX] + (leds if step.spectral else [])
    merged: list[list[HdrImage]] = [[] for _ in rois]
    bracketed = []  # every ROI pixel's brackets, where there are several
    for name in names:
        stack = np.stack([_load(gdir, name, k) - dark for k in range(len(rel))])
        stack = linearised(stack, gamma) if gamma else stack
        for p, (yy, xx) in enumerate(rois):
            roi = stack[:, :, yy, xx]
            merged[p].append(merge_brackets(roi, rel))
            if len(rel) > 1:
                bracketed.append(roi.reshape(len(rel), -1))
    said = (
        bracket_bend_warning(*fit_bracket_bend(np.concatenate(bracketed, 1), rel))
        if bracketed
        else None
    )
    responses = hdr_patch_responses(merged, layout.patch_names, names)
    illum = illuminants_from_spds(
        [read_spectra_csv(gdir / f"spd_{name}.csv") for name in names],
        [float(exposures[name]) for name in names],
        names,
        factor=cos_i,
        grid=DEFAULT_GRID,
    )
    if correct is not None:
        illum = correct(illum)
    return GeometryData(
        index, position, responses, illum, corners, (said,) if said else ()
    )


def _augmented(base: Spectra, offsets: tuple[float, ...]) -> Spectra:
    vals = [base.values] + [base.values + k for k in offsets]
    names = [f"{n}+{k:g}" for k in (0.0, *offsets) for n in base.names]
    return Spectra(base.wavelength_nm, np.vstack(vals), tuple(names))


def process_gonio(
    folder: str | Path,
    sensitivity: Spectra,
    layout: TargetLayout,
    prior: Spectra,
    *,
    correct: Correction | None = None,
    scheduler: str | None = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
) -> GonioResult:
    """Spectra and XYZ (D50) of every patch at every geometry of a captured session.

    Parameters
    ----------
    sensitivity : Spectra
        Calibrated sensitivities on the working grid (``tunespec calibrate``).
    layout
        The sample target's layout.
    prior : Spectra
        Training reflectances (the ColorChecker SG): the Wiener prior, with flat
        specular offsets added. The single-shot transform's prior is the sample's own
        body spectra (its least specular spectral estimate per patch) with flat
        offsets: never the XYZ it then measures.
    scheduler
        ``None``: geometries one after another here. Otherwise the per-geometry
        work (target detection, HDR merge, ROI statistics) runs on the pipeline's
        Dask engine (:mod:`tunespec.app.pipeline.engine`, shared with the spectral
        images):
        ``"threads"`` or ``"processes"`` locally, or a Dask distributed
        scheduler's address (``tcp://host:8786``, needs the ``distributed``
        package).
    """
    root = Path(folder)
    plan = GonioPlan.load(root / "plan.json")
    spectral_idx = [i for i, s in enumerate(plan.steps) if s.spectral]
    if not spectral_idx:
        raise InputError("the plan has no spectral geometry: fusion needs at least one")
    leds = list(plan.leds) or list(_led_names(root / plan.folder(spectral_idx[0])))
    excess = excess_from_meta(sensitivity.meta)
    gamma = 0.0 if excess is None else excess.linearity_gamma
    jobs = [(root / plan.folder(i), i, plan, layout, leds, correct, gamma)
            for i in range(len(plan.steps))]  # fmt: skip
    if scheduler is None:
        data = []
        for job in jobs:
            check_stop(should_stop)
            data.append(_process_geometry(*job))
            report(progress, 0.8 * len(data) / len(jobs))
    else:
        data = _on_dask(jobs, scheduler, sub_progress(progress, 0.0, 0.8), should_stop)
    n_p, n_g, wl = layout.n_patches, len(plan.steps), DEFAULT_GRID.wavelength_nm
    R = np.full((n_p, n_g, wl.size), np.nan)
    uR = np.full_like(R, np.nan)
    wprior = _augmented(prior.resample(DEFAULT_GRID), SPECULAR_OFFSETS)
    # the full posterior covariance per patch and spectral geometry: a spectrum's
    # errors are strongly correlated across wavelengths, which its colour sees
    post: dict[int, NDArray[np.float64]] = {}
    for i in spectral_idx:
        d = data[i]
        resp = d.responses.subset(illuminants=leds)
        est = wiener_reflectance(resp, d.illuminants, sensitivity, wprior, clip=False)
        # reflectance factors may exceed 1 near the specular peak: clip below only
        R[:, i], uR[:, i] = np.maximum(est.reflectance.values, 0.0), est.std
        post[i] = _posterior_covariance(est)
    rho = np.array([material_prior(R[p, spectral_idx])[0] for p in range(n_p)])
    # the single-shot transform's prior: the sample's own body spectra with flat
    # surface reflections added (what the sample can look like at any geometry)
    session = Spectra(wl, rho, tuple(f"rho_{n}" for n in layout.patch_names))
    session = _augmented(session, SESSION_OFFSETS)
    xyz = np.zeros((n_p, n_g, 3))
    u_xyz = np.zeros_like(xyz)
    W = astm_e308_weights_d50(wl)
    # the covariance of the XYZ of the final spectra (W^T cov(R) W)
    xyz_cov_R = np.zeros((n_p, n_g, 3, 3))
    for i in spectral_idx:
        xyz_cov_R[:, i] = W.T @ post[i] @ W
    for i, d in enumerate(data):
        mix = d.illuminants.select([MIX])
        rgb = d.responses.rgb[:, 0, :]
        var = d.responses.rgb_std[:, 0, :] ** 2 / d.responses.n_pixels[:, :1]
        T = xyz_transform(sensitivity, mix, session, kind=SESSION_KIND, relative=True)
        xyz[:, i], cov = apply_xyz_transform(T, rgb, var)
        u_xyz[:, i] = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
        if not plan.steps[i].spectral:
            M = sensitivity.values * mix.values[0] * DEFAULT_GRID.step_nm
            for p in range(n_p):
                spec = R[p, spectral_idx]
                f = fuse_patch(rgb[p], xyz[p, i], spec, M, wl, rgb_var=var[p])
                R[p, i] = f.reflectance
                # the prior R0 = a rho_hat + b: rho_hat's posterior covariance, a^2
                k_rho = post[spectral_idx[int(np.argmin(spec.mean(axis=1)))]][p]
                K = fused_covariance(spec, wl, cov[p], f.coefficients[0] ** 2 * k_rho)
                uR[p, i] = np.sqrt(np.maximum(np.diagonal(K), 0.0))
                xyz_cov_R[p, i] = W.T @ K @ W  # = cov[p]: the single shot's
        report(progress, 0.8 + 0.2 * (i + 1) / n_g)
    lab, u_lab = _lab_with_uncertainty(R, xyz_cov_R, wl)
    said = [w for d in data for w in d.warnings]
    if not any(s.hdr for s in plan.steps):
        said.append(NO_BRACKETS_WARNING)
    return GonioResult(layout.patch_names, plan, [d.position for d in data], wl, R, uR,
                       xyz, u_xyz, lab, np.array([s.spectral for s in plan.steps]),
                       u_lab, tuple(said))  # fmt: skip


def _posterior_covariance(est: Any) -> NDArray[np.float64]:
    """The full Wiener posterior covariance per patch, (n_p, n_wl, n_wl):
    ``K - K F^T (F K F^T + K_e)^-1 F K`` with each patch's own ``K_e`` (the
    estimate's ``variance`` is its diagonal)."""
    F, K = est.lighting, est.prior_covariance
    FK = F @ K
    G = FK @ F.T
    noise = est.noise_variance.reshape(est.noise_variance.shape[0], -1)
    A = np.repeat(G[None], noise.shape[0], axis=0)
    idx = np.arange(G.shape[0])
    A[:, idx, idx] += noise
    sol = np.linalg.solve(A, np.broadcast_to(FK, (noise.shape[0], *FK.shape)))
    out = K[None] - FK.T[None] @ sol
    return 0.5 * (out + out.transpose(0, 2, 1))


def _lab_with_uncertainty(
    R: NDArray[np.float64], xyz_cov: NDArray[np.float64], wl: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """CIELAB (D50) of the spectra and its standard uncertainty, first order from
    the covariance of their XYZ (..., 3, 3)."""
    from tunespec.core.uncertainty import lab_covariance

    xyz = xyz_d50(R, wl)
    lab_cov = lab_covariance(xyz.reshape(-1, 3), xyz_cov.reshape(-1, 3, 3))
    u_lab = np.sqrt(np.maximum(np.diagonal(lab_cov, axis1=-2, axis2=-1), 0.0))
    return xyz_to_lab_d50(xyz), u_lab.reshape(xyz.shape)


def _on_dask(
    jobs: list[tuple[Any, ...]],
    scheduler: str,
    progress: ProgressFn | None,
    should_stop: StopFn | None,
) -> list[GeometryData]:
    """``_process_geometry`` for every job on the pipeline's Dask engine (the one the
    spectral images use: local by default, a ``dask.distributed`` cluster by
    address)."""
    import dask

    from tunespec.app.pipeline.engine import compute, connect

    tasks = [dask.delayed(_process_geometry)(*job) for job in jobs]
    with connect(scheduler) as sched:
        return compute([(t, []) for t in tasks], sched, progress, should_stop)


def calibration_correction(
    led_correction: Any, leds_reported: Spectra, mix_levels: NDArray[np.float64]
) -> Correction:
    """The calibration's per-LED corrections, extended to the D50 mix.

    Each LED spectrum is corrected by its own gain and offset
    (:class:`~tunespec.core.led_correction.LedCorrection`). The mix is a sum of
    LEDs: its measured spectrum is multiplied by the ratio, per wavelength, of the
    corrected to the uncorrected sum of the calibration's LED spectra at the mix
    levels (the mix's own shape is kept, its metering errors are those of its LEDs).
    """
    base = suppress_meter_floor(leds_reported).resample(DEFAULT_GRID, average=True)
    model = mix_levels @ base.values
    fixed = mix_levels @ led_correction.apply(base).values
    factor = np.where(
        model > 1e-6 * model.max(), fixed / np.maximum(model, 1e-300), 1.0
    )

    def correct(illuminants: Spectra) -> Spectra:
        out = led_correction.apply(illuminants).values.copy()
        if MIX in illuminants.names:
            j = illuminants.names.index(MIX)
            out[j] = illuminants.values[j] * factor
        return illuminants.with_values(out)

    return correct


def _led_names(gdir: Path) -> list[str]:
    names = sorted(p.name[4:-4] for p in gdir.glob("spd_*.csv"))
    return [n for n in names if n not in (MIX, DARK)]


def result_summary(result: GonioResult, truth: NDArray[np.float64]) -> dict[str, Any]:
    """Scores against true reflectance factors (n_p, n_g, n_wl): the simulated bench.

    Spectral RMS at the spectral geometries (full captures) and at the fused ones,
    and CIEDE2000 (D50) of the fused geometries' spectra against the truth; the
    single shot's own XYZ scored the same way (everywhere and at the single-shot-only
    geometries).
    """
    from tunespec.core.colorimetry import delta_e_2000, xyz_d50

    wl = result.wavelength_nm
    rms = np.sqrt(np.mean((result.reflectance - truth) ** 2, axis=-1))
    de = delta_e_2000(result.lab, xyz_to_lab_d50(xyz_d50(truth, wl)))
    de_ss = delta_e_2000(xyz_to_lab_d50(result.xyz), xyz_to_lab_d50(xyz_d50(truth, wl)))
    s, f = result.spectral, ~result.spectral
    return {
        "n_geometries": int(s.size),
        "n_spectral": int(s.sum()),
        "spectral_rms_full_captures": float(rms[:, s].mean()),
        "spectral_rms_fused": float(rms[:, f].mean()),
        "rms_ratio_fused_to_full": float(rms[:, f].mean() / rms[:, s].mean()),
        "de00_fused_mean": float(de[:, f].mean()),
        "de00_fused_max": float(de[:, f].max()),
        "de00_single_shot_mean": float(de_ss.mean()),
        "de00_single_shot_fused_mean": float(de_ss[:, f].mean()),
        "de00_single_shot_fused_max": float(de_ss[:, f].max()),
        "de00_full_captures_mean": float(de[:, s].mean()),
    }
