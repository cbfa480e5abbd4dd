"""Spectral and colorimetric images of sessions, as a Dask graph (one machine or many).

:func:`session_graph` turns one session into a graph of the stages of
:mod:`tunespec.app.pipeline.image_session`: a task per dark exposure, one per LED (read,
dark, Eq. 2, into the on-disk response stack), one setup (noise model, corrected
illuminants, Wiener bank), one per block of output rows (Eq. 5 per pixel, written
into the ENVI, Zarr and TIFF files at the block's own offsets) and a last one
(preview PNG, ``provenance.json``, intermediates removed). :func:`estimate_images`
runs it for one session, :func:`batch_images` for a folder of sessions (one graph,
so a cluster works on several sessions at once; a session whose folder holds its
``provenance.json`` is finished and skipped, so a killed batch resumes).

Scheduler: by default Dask's local threaded scheduler (nothing to install or
start; numpy, OpenCV and LibRaw release the GIL in the heavy parts). ``scheduler``
given as an address (``tcp://host:8786``) or a ``distributed.Client`` runs the same
graph on a ``dask.distributed`` cluster; the workers must see the session and
output folders at the same paths (a shared file system).
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path
from typing import Any

from tunespec.app.pipeline.engine import compute, connect, one_blas_thread
from tunespec.app.pipeline.heap import reused_heap
from tunespec.core.errors import InputError
from tunespec.core.progress import ProgressFn, StopFn, report
from tunespec.core.spectra import Grid

__all__ = [
    "ImageSettings",
    "batch_images",
    "estimate_images",
    "find_sessions",
    "session_graph",
]

WORK_DIR = ".work"
#: Most Wiener matrices per level and per flat-field factor (the bank is
#: ``levels x phi`` matrices of ``3 n_i x n_wl``, built once per session).
MAX_LEVEL_BINS = 256
MAX_PHI_BINS = 32


@dataclass(frozen=True)
class ImageSettings:
    """How images are estimated.

    Parameters
    ----------
    grid
        Wavelength grid of the cube (default the pipeline's estimation grid,
        400-700 nm at 5 nm).
    rectify
        Resample to the target's plane through the session's homography (the
        layout's corners, else found in the frames as processing does).
    clip
        Limit reflectances to [0, 1].
    n_levels, n_phi
        Bins of the noise model (:mod:`tunespec.core.image`).
    noise
        A :class:`~tunespec.core.image.NoiseModel` of the sensor or its
        :class:`~tunespec.core.image.SensorFigures`; ``None`` fits one to the
        session's white frames (photon transfer).
    dark
        ``"pixel"``: the mean dark frame subtracted pixel by pixel; ``"smooth"``:
        its smooth level and hot pixels only
        (:func:`tunespec.core.image_planes.smooth_dark`), which removes the dark
        frame's read noise from every pixel.
    formats
        The files written (``--formats``): ``envi`` (cube.hdr/.img), ``zarr``
        (cube.zarr), ``tiff`` (xyz, lab, uncertainty); default all three.
    force
        Accept a session on another scale than the calibration's chart (its white
        board by Eq. 1, ``lighting.sample_scale_record``), listed in the provenance's
        ``forced``.

    Raises
    ------
    InputError
        Bin counts outside 1 to :data:`MAX_LEVEL_BINS` / :data:`MAX_PHI_BINS`, a
        noise model of another type.
    """

    grid: Grid | None = None
    rectify: bool = False
    clip: bool = True
    n_levels: int = 32
    n_phi: int = 4
    noise: Any = None
    dark: str = "pixel"
    formats: tuple[str, ...] = ("envi", "zarr", "tiff")
    force: bool = False

    def __post_init__(self) -> None:
        from tunespec.core.image import NoiseModel, SensorFigures
        from tunespec.core.image_planes import DARK_MODES
        from tunespec.core.io.image_formats import valid_formats

        object.__setattr__(self, "formats", valid_formats(self.formats))

        if self.dark not in DARK_MODES:
            raise InputError(
                f"dark: expected one of {', '.join(DARK_MODES)}, got {self.dark!r}"
            )

        for name, value, top in (
            ("level bins", self.n_levels, MAX_LEVEL_BINS),
            ("phi bins", self.n_phi, MAX_PHI_BINS),
        ):
            if not (isinstance(value, int) and 1 <= value <= top):
                raise InputError(
                    f"{name}: expected an integer from 1 to {top}, got {value!r}"
                )
        if not (
            self.noise is None or isinstance(self.noise, NoiseModel | SensorFigures)
        ):
            raise InputError(
                f"noise model: expected a NoiseModel or SensorFigures, got "
                f"{type(self.noise).__name__}"
            )


@dataclass(frozen=True)
class _Calibration:
    path: str
    sha256: str
    sensitivity: Any
    meta: dict[str, Any]
    prior: Any
    grid: Grid


def _load_calibration(
    sensitivities: str | PathLike[str],
    grid: Grid,
    warn: Callable[[str], None] | None = None,
) -> _Calibration:
    """Sensitivities (on their own grid: Eq. 1 is integrated there, as ``tunespec
    estimate`` does), their side file and the prior (on its own range: Eq. 5 solves
    for the reflectance wherever the light reaches), read once; ``warn`` is told
    :func:`calibration_warnings`."""
    from tunespec.core.calibration import calibrated_sensitivities
    from tunespec.core.datasets import load_colorchecker_sg
    from tunespec.core.io.session import sha256_file
    from tunespec.core.plausibility import check_calibration_grid

    path = Path(sensitivities)
    sens, meta = calibrated_sensitivities(path)
    check_calibration_grid(sens.wavelength_nm, meta)
    if warn is not None:
        for line in calibration_warnings(path, meta):
            warn(line)
    return _Calibration(
        str(path.resolve()), sha256_file(path), sens, meta, load_colorchecker_sg(),
        grid,
    )  # fmt: skip


def calibration_warnings(sensitivities: Path, meta: Mapping[str, Any]) -> list[str]:
    """What to say of a calibration before its images are estimated: that the
    sensitivities come without their side file (the images are then estimated
    without the calibration's LED corrections: never silently), else what the
    calibration found about itself (``meta``, its side file as read)."""
    from tunespec.core.io.export import sensitivity_meta_path
    from tunespec.core.plausibility import calibration_notes

    side = sensitivity_meta_path(sensitivities)
    if not side.exists():
        return [
            f"no LED corrections next to {sensitivities.name} ({side.name}): the "
            "images are estimated without the calibration's per-LED corrections "
            "and come out worse; copy the side file along with the CSV"
        ]
    return calibration_notes(meta, sensitivities)


def _rectification(session: Any) -> Any:
    from tunespec.core.image_planes import rectification_for
    from tunespec.core.processing import find_session_corners

    layout = session.layout
    if layout is None:
        raise InputError(
            "--rectify needs the session's target layout", path=session.manifest_path
        )
    corners = layout.corners_px
    if corners is None:
        corners = find_session_corners(session, layout)[0].corners_px
    return rectification_for(corners, layout.width_mm, layout.height_mm)


def session_graph(
    session_dir: str | PathLike[str],
    calibration: _Calibration,
    out_dir: str | PathLike[str],
    settings: ImageSettings,
) -> Any:
    """The Dask graph of one session: the final task (computing it returns the
    provenance dict) and the blocks of rows (for progress on a cluster).

    The blocks start as soon as the Wiener bank is built: the systematic part of
    the uncertainty (:func:`~tunespec.app.pipeline.image_systematic.systematic_table`,
    only computed for the TIFFs) is added in the final task, while the blocks
    compute beside it."""
    from dask import delayed

    from tunespec.app.pipeline import image_session as st
    from tunespec.app.pipeline.image_systematic import systematic_table
    from tunespec.core.io.session import Session

    session = Session.open(session_dir)
    out = Path(out_dir)
    work = out / WORK_DIR
    if work.exists():
        shutil.rmtree(work)  # left by a killed run: the stack is rebuilt
    job = st.plan_image_job(session, work, dark=settings.dark)
    rect = _rectification(session) if settings.rectify else None
    shape = rect.shape if rect is not None else job.plane_shape
    # the job and the calibration as one literal each in the graph, which the tasks
    # refer to: as arguments, Dask would take the job's dataclasses apart in every
    # task (about 700 objects each) and build them again when the task runs
    job_ref = delayed(job, name=f"job-{job.work}", traverse=False)
    sens, meta, prior = (
        delayed(v, name=f"{k}-{job.work}", traverse=False)
        for k, v in (
            ("sensitivity", calibration.sensitivity),
            ("meta", calibration.meta),
            ("prior", calibration.prior),
        )
    )
    darks = [
        delayed(st.prepare_darks, pure=True)(
            job_ref, i, dask_key_name=f"dark-{i}-{job.work}"
        )
        for i in range(len(job.dark_keys))
    ]
    channels = [
        delayed(_after(st.prepare_channel), pure=True)(
            darks, job_ref, j, dask_key_name=f"led-{j}-{job.work}"
        )
        for j in range(len(job.channels))
    ]
    warm = delayed(st.warm_up, pure=True)(
        calibration.grid.wavelength_nm, job_ref, dask_key_name=f"warm-{job.work}"
    )
    bank = delayed(_after(st.setup_estimation), pure=True)(
        warm, job_ref, channels, sens, meta, prior, calibration.grid, noise=settings.noise,
        n_levels=settings.n_levels, n_phi=settings.n_phi, force=settings.force,
        dask_key_name=f"setup-{job.work}",
    )  # fmt: skip
    systematic = None
    if "tiff" in settings.formats:  # only the uncertainty TIFF holds it
        systematic = delayed(one_blas_thread, pure=True)(
            systematic_table, job_ref, bank, calibration.path, meta, prior,
            calibration.grid, dask_key_name=f"systematic-{job.work}",
        )  # fmt: skip
    rows = st.block_rows_for(shape[1])
    provenance = delayed(
        _provenance(session, job, calibration, settings, rect, shape),
        name=f"provenance-{job.work}", traverse=False,
    )  # fmt: skip
    outputs = delayed(_create_outputs, pure=True)(
        out, shape, bank, rows, provenance, settings.formats,
        dask_key_name=f"outputs-{job.work}",
    )  # fmt: skip
    blocks = [
        delayed(one_blas_thread, pure=True)(
            st.estimate_block,
            job_ref,
            bank,
            outputs,
            r0,
            min(r0 + rows, shape[0]),
            clip=settings.clip,
            rectification=rect,
            keep_uncertainty=True,
            dask_key_name=f"block-{r0}-{job.work}",
        )
        for r0 in range(0, shape[0], rows)
    ]
    # the last, serial part: the uncertainty TIFF (waiting for the systematic
    # table) and the preview PNG side by side, then the provenance
    uncertainty = delayed(_uncertainty_tiff, pure=True)(
        outputs, blocks, systematic, dask_key_name=f"uncertainty-{job.work}"
    )
    preview = delayed(_preview, pure=True)(
        outputs, blocks, dask_key_name=f"preview-{job.work}"
    )
    final = delayed(_provenance_written, pure=True)(
        job_ref, outputs, bank, provenance, uncertainty, preview,
        dask_key_name=f"finish-{job.work}",
    )  # fmt: skip
    return final, blocks


def _after(func: Any) -> Any:
    """``func`` with a first argument that only orders it after other tasks."""

    def run(_deps: Any, *args: Any, **kwargs: Any) -> Any:
        return one_blas_thread(func, *args, **kwargs)

    run.__name__ = func.__name__
    return run


def _create_outputs(
    out: Path,
    shape: tuple[int, int],
    bank: Any,
    rows: int,
    provenance: dict[str, Any],
    formats: tuple[str, ...],
) -> Any:
    from tunespec.core.io.image_formats import ImageOutputs

    prov = {**provenance, "noise_model": _noise_doc(bank)}
    return ImageOutputs.create(
        out, shape, bank.wavelength_nm, block_rows=rows, provenance=prov,
        formats=formats,
    )  # fmt: skip


def _noise_doc(bank: Any) -> dict[str, Any]:
    n = bank.noise
    return {
        "source": n.source,
        "read_var_fs2": n.read_var.tolist(),
        "shot_gain_fs": n.shot_gain.tolist(),
        "fit_rms": n.fit_rms,
        "flat_field_residual": bank.flat_residual,
        "approximation": "Wiener matrices per bin of level rho (uniform in sqrt) "
        "and flat-field factor phi (geometric); see tunespec.core.image",
        "n_level_bins": int(bank.level_edges.size - 1),
        "n_phi_bins": int(bank.phi_edges.size - 1),
        "phi_range": [float(bank.phi_edges[0]), float(bank.phi_edges[-1])],
    }


def _finish(
    job: Any,
    outputs: Any,
    bank: Any,
    blocks: Sequence[Any],
    provenance: dict[str, Any],
    systematic: Any,
) -> dict[str, Any]:
    """The uncertainty TIFF, the preview and the provenance, one after the other
    (the graph runs the first two as tasks of their own, side by side)."""
    _uncertainty_tiff(outputs, blocks, systematic)
    _preview(outputs, blocks)
    return _provenance_written(job, outputs, bank, provenance)


def _uncertainty_tiff(outputs: Any, blocks: Sequence[Any], systematic: Any) -> None:
    from tunespec.app.pipeline.image_session import finish_uncertainty

    finish_uncertainty(outputs, blocks, systematic)


def _preview(outputs: Any, blocks: Sequence[Any]) -> None:
    import numpy as np

    outputs.write_preview(np.concatenate([b.srgb for b in blocks], axis=0))


def _provenance_written(
    job: Any, outputs: Any, bank: Any, provenance: dict[str, Any], *_done: Any
) -> dict[str, Any]:
    """``provenance.json``, last (its presence marks finished images), once
    ``_done``'s tasks have written the other files; the work folder removed."""
    doc = {
        **provenance,
        "noise_model": _noise_doc(bank),
        # the session's white board by Eq. 1 over the calibration's chart session's
        "white_scale": bank.params.get("white_scale", ""),
        "forced": bank.params.get("forced", []),
        # what the session's white board says of its linearity
        "warnings": bank.params.get("warnings", []),
        "finished_utc": _now(),
    }
    shutil.rmtree(job.work, ignore_errors=True)
    outputs.write_provenance(doc)
    return doc


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")


def _provenance(
    session: Any,
    job: Any,
    cal: _Calibration,
    settings: ImageSettings,
    rect: Any,
    shape: tuple[int, int],
) -> dict[str, Any]:
    from tunespec.core.io.export import tunespec_version

    g = cal.grid
    return {
        "format": "tunespec-image",
        "version": 1,
        "session": str(session.root.resolve()),
        "session_fingerprint": job.fingerprint,
        "calibration": cal.path,
        "calibration_sha256": cal.sha256,
        "led_corrections": "per-LED" if "led_correction" in cal.meta else
        f"common shift {float(cal.meta.get('spd_shift_nm', 0.0)):g} nm",
        "prior": "ColorChecker SG (shipped)",
        "grid_nm": [g.start_nm, g.end_nm, g.step_nm],
        "channels": list(job.channels),
        "shape": list(shape),
        "pixel": "2x2 Bayer superpixel (no demosaicing)",
        "rectified": rect is not None,
        "homography_out_to_plane": None if rect is None else
        [list(r) for r in rect.H_out_to_plane],
        "clip": settings.clip,
        "dark": settings.dark,
        "settings": _settings_doc(settings, g),
        "software": f"tunespec {tunespec_version()}",
        "started_utc": _now(),
        "files": _files_doc(settings.formats),
    }  # fmt: skip


def _files_doc(formats: tuple[str, ...]) -> dict[str, str]:
    files = {
        "cube_envi": ("envi", "cube.hdr"),
        "cube_zarr": ("zarr", "cube.zarr (xarray: reflectance (y, x, wavelength))"),
        "xyz": ("tiff", "xyz.tif"),
        "lab": ("tiff", "lab.tif"),
        "uncertainty": ("tiff", "uncertainty.tif (u(L*), RMS u(reflectance); k=1)"),
    }
    doc = {k: name for k, (fmt, name) in files.items() if fmt in formats}
    return {**doc, "preview": "srgb.png"}


def _settings_doc(settings: ImageSettings, grid: Grid) -> dict[str, Any]:
    """What of the settings shapes the images (a batch redoes a session whose
    images were made otherwise)."""
    noise = settings.noise
    if noise is None:
        noise_doc: Any = "photon-transfer"
    elif hasattr(noise, "full_well_e"):
        noise_doc = {
            "full_well_e": noise.full_well_e,
            "read_noise_e": noise.read_noise_e,
            "iso_gain": noise.iso_gain,
        }
    else:
        noise_doc = {
            "read_var": noise.read_var.tolist(),
            "shot_gain": noise.shot_gain.tolist(),
        }
    return {
        "grid_nm": [grid.start_nm, grid.end_nm, grid.step_nm],
        "rectify": settings.rectify,
        "clip": settings.clip,
        "dark": settings.dark,
        "n_levels": settings.n_levels,
        "n_phi": settings.n_phi,
        "noise": noise_doc,
        "formats": list(settings.formats),
    }


def estimate_images(
    session_dir: str | PathLike[str],
    sensitivities: str | PathLike[str],
    out_dir: str | PathLike[str],
    *,
    settings: ImageSettings = ImageSettings(),
    scheduler: Any = None,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    warn: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Per-pixel reflectance, XYZ, L*a*b* and uncertainty images of one session.

    Parameters
    ----------
    session_dir
        A captured session.
    sensitivities
        The calibration (``calibrate``'s CSV; its ``.meta.json`` carries the
        per-LED corrections, applied as ``tunespec estimate`` does).
    out_dir
        The output folder (see :mod:`tunespec.core.io.image_formats`).
    settings
        Grid, rectification, clipping, noise model.
    scheduler
        ``None`` (Dask's local threads), ``"sync"``, a ``dask.distributed`` address
        or ``Client``.
    warn
        Told what the calibration says of itself (:func:`calibration_warnings`),
        then what the session's white board says of its linearity (the
        provenance's ``warnings``: ``lighting.sample_board``).

    Returns
    -------
    dict
        The provenance written to ``provenance.json``.
    """
    grid = settings.grid or _default_grid()
    cal = _load_calibration(sensitivities, grid, warn)
    with (
        connect(scheduler) as sched,
        reused_heap(),
        _scratch_released(),
        _disk_full(out_dir),
    ):
        graph = session_graph(session_dir, cal, out_dir, settings)
        doc = compute([graph], sched, progress, should_stop)[0]
    if warn is not None:
        for line in doc.get("warnings", []):
            warn(line)
    return doc


def _is_disk_full(exc: BaseException) -> bool:
    import errno

    return isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)


@contextlib.contextmanager
def _disk_full(*out_dirs: str | PathLike[str]) -> Iterator[None]:
    """A full disk while images are written: the work folder and the unfinished
    images are removed and one :class:`DiskFullError` names the output folder."""
    from tunespec.core.errors import DiskFullError
    from tunespec.core.io.image_formats import remove_partial_outputs

    try:
        yield
    except (OSError, DiskFullError) as exc:
        if not (isinstance(exc, DiskFullError) or _is_disk_full(exc)):
            raise
        for out in out_dirs:
            shutil.rmtree(Path(out) / WORK_DIR, ignore_errors=True)
            remove_partial_outputs(out)
        failed = Path(
            getattr(exc, "folder", None)
            or getattr(exc, "filename", None)
            or out_dirs[0]
        )
        where = next(
            (Path(o) for o in out_dirs if Path(o) in (failed, *failed.parents)),
            Path(out_dirs[0]),
        )
        raise DiskFullError(where) from None


@contextlib.contextmanager
def _scratch_released() -> Iterator[None]:
    """The local threads' frame and block buffers (about 0.5 GB a thread at full
    resolution) and the cached dark planes are dropped when the work ends, so a
    GUI does not keep them."""
    from tunespec.app.pipeline.image_session import release_buffers

    try:
        yield
    finally:
        release_buffers()


def _default_grid() -> Grid:
    from tunespec.app.pipeline.plan import ESTIMATION_GRID

    return ESTIMATION_GRID


def find_sessions(folder: str | PathLike[str]) -> list[Path]:
    """Session folders (holding ``manifest.json``) in ``folder``, two levels deep
    (a folder of sessions, or of measurement folders with ``chart/`` and
    ``sample/``), sorted."""
    root = Path(folder)
    if not root.is_dir():
        raise InputError("not a folder", path=root)
    found = [p.parent for p in root.glob("*/manifest.json")]
    found += [p.parent for p in root.glob("*/*/manifest.json")]
    return sorted(set(found))


def batch_images(
    folder: str | PathLike[str],
    sensitivities: str | PathLike[str],
    out_root: str | PathLike[str],
    *,
    settings: ImageSettings = ImageSettings(),
    scheduler: Any = None,
    sessions_at_once: int = 2,
    progress: ProgressFn | None = None,
    should_stop: StopFn | None = None,
    warn: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Images of every session in ``folder`` with one calibration, resumable.

    Each session's images go to ``out_root/<its path under folder>``; a session whose
    output holds a ``provenance.json`` for the same session fingerprint,
    calibration and settings is skipped. ``sessions_at_once`` sessions form one Dask graph (their
    LEDs and blocks run in parallel; more would hold more response stacks on disk at
    once), group after group; a killed batch loses only the sessions in progress.
    ``warn`` as :func:`estimate_images` takes it.

    Returns
    -------
    dict
        ``done`` (paths computed now), ``skipped`` (already finished).
    """
    from tunespec.core.io.image_formats import read_provenance
    from tunespec.core.io.session import Session

    root = Path(folder)
    sessions = find_sessions(root)
    if not sessions:
        raise InputError("no session (a folder with manifest.json) found", path=root)
    grid = settings.grid or _default_grid()
    cal = _load_calibration(sensitivities, grid, warn)
    done: list[str] = []
    skipped: list[str] = []
    todo: list[tuple[Path, Path]] = []
    for s in sessions:
        out = Path(out_root) / s.relative_to(root)
        prov = read_provenance(out)
        if (
            prov is not None
            and prov.get("session_fingerprint") == Session.open(s).fingerprint()
            and prov.get("calibration_sha256") == cal.sha256
            and prov.get("settings") == _settings_doc(settings, grid)
        ):
            skipped.append(str(s))
        else:
            todo.append((s, out))
    group = max(1, int(sessions_at_once))
    with (
        connect(scheduler) as sched,
        reused_heap(),
        _scratch_released(),
    ):
        for k in range(0, len(todo), group):
            part = todo[k : k + group]
            base = k / len(todo)

            def sub(f: float, base: float = base, n: int = len(part)) -> None:
                report(progress, base + f * n / len(todo))

            with _disk_full(*(out for _, out in part)):
                graphs = [session_graph(s, cal, out, settings) for s, out in part]
                docs = compute(graphs, sched, sub, should_stop)
            done.extend(str(s) for s, _ in part)
            if warn is not None:
                for (s, _), doc in zip(part, docs, strict=True):
                    for line in doc.get("warnings", []):
                        warn(f"{s}: {line}")
    report(progress, 1.0)
    return {"done": done, "skipped": skipped, "calibration_sha256": cal.sha256}
