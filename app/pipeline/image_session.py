"""From a captured session to per-pixel reflectance images, in stages that stream.

The stages (each a plain function of picklable arguments, so that
:mod:`tunespec.app.pipeline.image` can run them as a Dask graph, in threads or on a
``dask.distributed`` cluster):

1. :func:`prepare_darks` - per (exposure, ISO) the mean dark planes;
2. :func:`prepare_channel` - per LED: white and target frames read once
   (:func:`tunespec.core.io.raw.load_raw`, 2 x 2 Bayer superpixels, no
   demosaicing), dark subtracted, exposure brackets merged, flat-fielded with Eq. 2
   and written as three planes of the response stack ``responses.f16`` (half
   precision, :data:`STACK_DTYPE`)
   (``3 n_i`` planes, illuminant-major as Eq. 5's ``c``); clipped cells become NaN.
   The white board ``A_B`` is smoothed (block means, interpolated back
   bilinearly; :func:`tunespec.core.image_planes.flat_block_px`): the light field is smooth at that scale,
   and dividing by the raw white pixels would add the white frame's noise to every
   pixel. Blocks of :data:`PTC_BLOCK_PX` also give photon-transfer points (noise
   variance vs. level);
3. :func:`setup_estimation` - the noise model (photon-transfer fit of the white
   frames, or the camera's), the illuminants (measured SPD x exposure, with the
   calibration's per-LED corrections applied exactly as ``tunespec estimate`` does),
   the lighting matrix and the bank of Wiener matrices
   (:func:`tunespec.core.image.build_wiener_bank`); the per-pixel flat-field factor
   ``phi`` is written as ``phi.f32``;
   :func:`~tunespec.app.pipeline.image_systematic.systematic_table` then takes what a
   pixel's own noise does not cover (the
   calibration's covariance, a target unlike the prior) from
   :func:`tunespec.core.uncertainty.reflectance_uncertainty` on sampled regions,
   tabulated by CIELAB cell;
4. :func:`estimate_block` - per block of rows: the responses are read from disk,
   each pixel gets Eq. 5 from its bin (:func:`tunespec.core.image.estimate_pixels`),
   and the cube, XYZ, L*a*b* and uncertainty rows are written
   (:class:`tunespec.core.io.image_formats.ImageOutputs`). With a rectification
   (:class:`tunespec.core.image_planes.Rectification`) the block's rows are those of the target plane and the
   responses are resampled through the target's homography first (bilinear; Eq. 5
   is linear, so this equals resampling the unclipped estimates).

The numerics without file I/O (dark smoothing, rectification, the systematic
table) are :mod:`tunespec.core.image_planes`.

Memory is that of one frame (stage 2) or one block (stage 4), whatever the image
size: the response stack lives on disk (``3 n_i x 4`` bytes per pixel, 1.5 GB for
a 22-LED 5760 x 3840 session) and is read and written with positioned I/O, never
mapped, so the page cache holds it and not the process.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing", Eq. 1, 2, 5 and 6.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.app.pipeline.lighting import estimation_lighting, sample_scale_record
from tunespec.core.errors import InputError
from tunespec.core.excess import linearised
from tunespec.core.image import (
    DEFAULT_LEVEL_BINS,
    DEFAULT_PHI_BINS,
    NoiseModel,
    SensorFigures,
    WienerBank,
    block_noise_stats,
    build_wiener_bank,
    estimate_pixels,
    photon_transfer_fit,
    srgb8_from_xyz_d50,
)
from tunespec.core.image_planes import (
    DARK_MODES,
    DARK_SMOOTH_PX,
    Rectification,
    SystematicTable,
    flat_block_px,
    smooth_dark,
)
from tunespec.core.io.image_formats import ImageOutputs, pwrite_all, write_array
from tunespec.core.io.raw import load_raw
from tunespec.core.io.session import Session, find_darks, frames_by_channel
from tunespec.core.processing import (
    BRACKET_CLIP_LEVEL,
    exposure_groups,
    frame_settings_problem,
)
from tunespec.core.scratch import SCRATCH_ALIGN, scratch
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "PTC_BLOCK_PX",
    "BlockResult",
    "ChannelResult",
    "ImageJob",
    "block_rows_for",
    "estimate_block",
    "finish_uncertainty",
    "illuminants_of",
    "lighting_for",
    "plan_image_job",
    "prepare_channel",
    "prepare_darks",
    "read_response_rows",
    "release_buffers",
    "setup_estimation",
    "warm_up",
]

#: Side of the photon-transfer blocks, plane pixels.
PTC_BLOCK_PX = 16
#: Side of the centre window whose mean normalises Eq. 2 (as processing's).
FLAT_WINDOW_PX = 100
#: A channel needs its smoothed white board to this relative precision, else it
#: borrows the flat field of the LED's strongest channel (as processing does).
FLAT_MIN_PRECISION = 0.002
#: Pixels per block of rows in stage 4 (bounds its memory: about 1 kB per pixel).
BLOCK_PIXELS = 1 << 18
RESPONSES = "responses.f16"
#: The response stack's type on disk. Half precision rounds a response by at most
#: 2^-11 of itself (RMS 1.4e-4 relative), 20x below the photon noise of a superpixel
#: at the full well (1 / sqrt(67000) = 3.9e-3 relative, and more at lower levels):
#: it adds 0.1 % to the noise variance and halves the bytes written and read.
STACK_DTYPE = np.dtype("<f2")
PHI = "phi.f32"


@dataclass(frozen=True)
class _Frame:
    path: str
    exposure_s: float
    iso: int


@dataclass(frozen=True)
class ImageJob:
    """What the stages need of a session (picklable: travels to Dask workers).

    Build it with :func:`plan_image_job`.
    """

    session_root: str
    fingerprint: str
    channels: tuple[str, ...]
    whites: tuple[tuple[_Frame, ...], ...]
    targets: tuple[tuple[_Frame, ...], ...]
    darks: tuple[tuple[_Frame, ...], ...]
    dark_keys: tuple[tuple[float, int], ...]
    plane_shape: tuple[int, int]
    work: str
    spd_files: tuple[str, ...]
    spd_exposures_s: tuple[float, ...]
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def n_responses(self) -> int:
        return 3 * len(self.channels)

    def dark_index(self, frame: _Frame) -> int:
        for i, (t, iso) in enumerate(self.dark_keys):
            if iso == frame.iso and math.isclose(t, frame.exposure_s, rel_tol=1e-6):
                return i
        raise InputError(f"no dark frame at {frame.exposure_s:g} s, ISO {frame.iso}")

    def work_path(self, name: str) -> Path:
        return Path(self.work) / name


def plan_image_job(
    session: Session,
    work: str | PathLike[str],
    *,
    channels: Sequence[str] | None = None,
    dark: str = "pixel",
) -> ImageJob:
    """Check that a session is complete and list what the stages read.

    Creates ``work`` and the (sparse) response stack in it. ``dark``: ``"pixel"``
    subtracts the mean dark frame pixel by pixel, ``"smooth"`` its
    :func:`smooth_dark` version.

    Raises
    ------
    InputError
        A channel without its white, target or dark frames, or frames of
        different sizes.
    """
    import rawpy

    if dark not in DARK_MODES:
        raise InputError(f"dark: expected one of {', '.join(DARK_MODES)}, got {dark!r}")
    frames = session.frames
    whites = frames_by_channel(frames, "white")
    targets = frames_by_channel(frames, "target")
    wanted = list(channels) if channels is not None else list(session.settings.channels)
    missing = {s.channel for s in session.missing(verify=False) if s.channel}
    keys: list[tuple[float, int]] = []
    dark_frames: list[tuple[_Frame, ...]] = []
    w_out, t_out, spd_files, spd_t = [], [], [], []
    for c in wanted:
        if c not in whites or c not in targets or c in missing:
            raise InputError(
                f"channel {c}: frames missing or marked bad; resume the capture "
                "(tunespec capture ... --resume)",
                path=session.manifest_path,
            )
        for rec in (*whites[c], *targets[c]):
            key = (rec.exposure_s, rec.iso)
            if not any(k[1] == key[1] and math.isclose(k[0], key[0], rel_tol=1e-6)
                       for k in keys):  # fmt: skip
                darks = find_darks(frames, rec.exposure_s, rec.iso)
                if not darks:
                    raise InputError(
                        f"no dark frame at {rec.exposure_s:g} s, ISO {rec.iso} for "
                        f"frame {rec.id}; resume the capture",
                        path=session.manifest_path,
                    )
                keys.append(key)
                dark_frames.append(tuple(_frame(session, d) for d in darks))
        w_out.append(tuple(_frame(session, r) for r in whites[c]))
        t_out.append(tuple(_frame(session, r) for r in targets[c]))
        ref = targets[c][0]
        if ref.spd_file is None:
            raise InputError(f"frame {ref.id} has no measured SPD", path=session.root)
        spd_files.append(str(session.root / ref.spd_file))
        spd_t.append(ref.exposure_s)
    if not wanted:
        raise InputError("no channel to estimate", path=session.manifest_path)
    raw = rawpy.RawPy()
    first = w_out[0][0].path
    try:
        raw.open_file(first)
        h, w = raw.sizes.height, raw.sizes.width
    except rawpy.LibRawError as exc:
        raise InputError(f"cannot read as a raw file: {exc}", path=first) from None
    finally:
        raw.close()
    shape = (h // 2, w // 2)
    work = Path(work)
    work.mkdir(parents=True, exist_ok=True)
    job = ImageJob(
        str(session.root), session.fingerprint(), tuple(wanted), tuple(w_out),
        tuple(t_out), tuple(dark_frames), tuple(keys), shape, str(work),
        tuple(spd_files), tuple(spd_t),
        {
            "n_darks": max(len(d) for d in dark_frames),
            # frames averaged at the reference exposure (the fewest of any channel)
            "n_repeats": min(
                len(exposure_groups([f.exposure_s for f in t])[0]) for t in t_out
            ),
            "dark": dark,
        },
    )  # fmt: skip
    _allocate(
        job.work_path(RESPONSES),
        job.n_responses * shape[0] * shape[1] * STACK_DTYPE.itemsize,
    )
    return job


def _frame(session: Session, rec: Any) -> _Frame:
    return _Frame(str(session.path_of(rec)), float(rec.exposure_s), int(rec.iso))


def _allocate(path: Path, n_bytes: int) -> None:
    with open(path, "wb") as fh:
        fh.truncate(n_bytes)


def _planes(
    job: ImageJob,
    frame: _Frame,
    slot: str = "",
    dark: NDArray[np.float32] | None = None,
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """A frame's planes (less ``dark``, in the same passes:
    :meth:`~tunespec.core.io.raw.RawFrame.planes_minus`) and clipped cells; with a
    ``slot``, the planes are this thread's :func:`~tunespec.core.scratch.scratch`
    buffer of that name (a frame is 66 MB at full resolution: fresh pages for
    every frame cost as much as the conversion)."""
    raw = load_raw(frame.path)
    h, w = job.plane_shape
    if raw.shape != job.plane_shape:
        raise InputError(
            f"a {raw.shape[1] * 2}x{raw.shape[0] * 2} frame in a session of "
            f"{w * 2}x{h * 2} frames",
            path=frame.path,
        )
    # its own EXIF against its record, as processing checks it (no aperture here:
    # the stages read frames apart, on workers)
    if why := frame_settings_problem(raw, frame.exposure_s, frame.iso, None):
        raise InputError(why, path=frame.path)
    out = scratch(f"planes_{slot}", (3, h, w)) if slot else None
    if dark is not None:
        return raw.planes_minus(dark, out=out), raw.saturated
    return raw.planes_in(0, h, 0, w, out=out), raw.saturated


def prepare_darks(job: ImageJob, index: int) -> str:
    """Stage 1: the mean dark planes of ``job.dark_keys[index]`` (smoothed by
    :func:`smooth_dark` when ``job.meta["dark"]`` is ``"smooth"``); returns the
    file."""
    acc: NDArray[np.float32] | None = None
    frames = job.darks[index]
    for f in frames:
        planes, _ = _planes(job, f)
        acc = planes if acc is None else acc + planes
    assert acc is not None
    acc *= np.float32(1.0 / len(frames))
    if job.meta.get("dark") == "smooth":
        for k in range(3):
            acc[k] = smooth_dark(acc[k])
    path = job.work_path(f"dark_{index}.f32")
    write_array(path, acc)
    return str(path)


#: Mean dark planes kept in memory per process (a session has one or a few
#: exposures; read once, not once per frame).
_DARK_CACHE: dict[tuple[str, int], NDArray[np.float32]] = {}
_DARK_CACHE_SIZE = 2
_DARK_LOCK = threading.Lock()


def release_buffers() -> int:
    """Drop the cached dark planes and every thread's scratch buffers (call when
    the images are done); returns the bytes released."""
    from tunespec.core.scratch import release_scratch

    with _DARK_LOCK:
        n = sum(d.nbytes for d in _DARK_CACHE.values())
        _DARK_CACHE.clear()
    return n + release_scratch()


def _dark(job: ImageJob, frame: _Frame) -> NDArray[np.float32]:
    """The mean dark planes of ``frame``'s (exposure, ISO), read-only, cached."""
    path = job.work_path(f"dark_{job.dark_index(frame)}.f32")
    key = (str(path), path.stat().st_mtime_ns)
    with _DARK_LOCK:
        dark = _DARK_CACHE.get(key)
    if dark is None:
        dark = np.fromfile(path, dtype=np.float32).reshape(3, *job.plane_shape)
        dark.flags.writeable = False
        with _DARK_LOCK:
            while len(_DARK_CACHE) >= _DARK_CACHE_SIZE:
                _DARK_CACHE.pop(next(iter(_DARK_CACHE)))
            _DARK_CACHE[key] = dark
    return dark


def _group_mean(
    job: ImageJob, frames: Sequence[_Frame], group: range, slot: str, shorter: bool
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Mean of the dark-subtracted planes of ``frames[group]`` (one exposure) in this
    thread's scratch buffer ``planes_<slot>``, and the cells clipped in any of them
    (with ``shorter`` brackets to take over, also those above
    :data:`BRACKET_CLIP_LEVEL`)."""
    values: NDArray[np.float32] | None = None
    clipped = np.zeros(job.plane_shape, dtype=bool)
    for i in group:
        into = slot if values is None else "repeat"
        dark = _dark(job, frames[i])
        if shorter:  # the clipping level applies to the planes before the dark
            planes, sat = _planes(job, frames[i], into)
            clipped |= planes.max(axis=0) > BRACKET_CLIP_LEVEL
            planes -= dark
        else:
            planes, sat = _planes(job, frames[i], into, dark)
        clipped |= sat
        if values is None:
            values = planes
        else:
            values += planes
    assert values is not None  # a group has at least one frame
    if len(group) > 1:
        values *= np.float32(1.0 / len(group))
    return values, clipped


def _merged(
    job: ImageJob, frames: Sequence[_Frame]
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Dark-subtracted planes of a bracket series (longest first), merged as
    processing merges them: repeated frames of one exposure averaged
    (:func:`~tunespec.core.processing.exposure_groups`), a clipped cell takes the
    next shorter exposure, scaled.

    The planes are this thread's scratch buffer ``planes_merged`` (valid until the
    next call on this thread)."""
    groups = exposure_groups([f.exposure_s for f in frames])
    shorter = len(groups) > 1
    values, clipped = _group_mean(job, frames, groups[0], "merged", shorter)
    for group in groups[1:]:
        if not clipped.any():
            break
        planes, sat = _group_mean(job, frames, group, "bracket", shorter)
        use = clipped & ~sat
        values[:, use] = planes[:, use] * np.float32(
            frames[0].exposure_s / frames[group[0]].exposure_s
        )
        clipped &= ~use
    return values, clipped


@dataclass(frozen=True)
class ChannelResult:
    """What :func:`prepare_channel` returns (small: travels back from workers).

    Parameters
    ----------
    white_mean : (3,)
        Eq. 2's normaliser: the white board's mean over the centre window.
    ptc_level, ptc_var : (3, n_blocks)
        Photon-transfer points of the white frame.
    flat_grid : (hb, wb) float32
        The G flat-field factor ``mean(A_B) / A_B`` on the smoothing blocks.
    borrowed : tuple of int
        Channels (0-2) that used the strongest channel's flat field.
    n_saturated : int
        Pixels with a clipped target or white cell.
    """

    white_mean: NDArray[np.float64]
    ptc_level: NDArray[np.float64]
    ptc_var: NDArray[np.float64]
    flat_grid: NDArray[np.float32]
    borrowed: tuple[int, ...]
    n_saturated: int


def prepare_channel(job: ImageJob, j: int) -> ChannelResult:
    """Stage 2: channel ``j``'s responses, flat-fielded (Eq. 2), into the stack.

    Raises
    ------
    InputError
        A clipped centre window of the white frame, unreadable frames.
    """
    import cv2

    h, w = job.plane_shape
    white, w_sat = _merged(job, job.whites[j])
    r0, r1, c0, c1 = _window((h, w))
    ok = ~w_sat[r0:r1, c0:c1]
    if ok.sum() < 0.5 * ok.size:
        raise InputError(
            f"channel {job.channels[j]}: the white frame's centre window is clipped; "
            "lower the exposure",
            path=job.whites[j][0].path,
        )
    mean_b = white[:, r0:r1, c0:c1][:, ok].astype(np.float64).mean(axis=1)
    level, var = block_noise_stats(white, w_sat, PTC_BLOCK_PX)
    block = flat_block_px(w)
    hb, wb = max(1, round(h / block)), max(1, round(w / block))
    grids = np.stack(
        [cv2.resize(white[k], (wb, hb), interpolation=cv2.INTER_AREA) for k in range(3)]
    )
    # relative standard error of a block mean of the white board, per channel
    n_block = block**2
    rel_se = np.sqrt(np.median(var, axis=1) / n_block) / np.maximum(mean_b, 1e-30)
    usable = (mean_b > 0) & (grids.min(axis=(1, 2)) > 0)
    if not usable.any():
        raise InputError(
            f"channel {job.channels[j]}: the white frame has no usable signal",
            path=job.whites[j][0].path,
        )
    best = int(np.argmin(np.where(usable, rel_se, np.inf)))
    own = usable & (rel_se < FLAT_MIN_PRECISION)
    own[best] = True
    factor_grid = np.empty_like(grids)
    for k in range(3):
        src = k if own[k] else best
        factor_grid[k] = np.float32(mean_b[src]) / grids[src]
    del white
    target, t_sat = _merged(job, job.targets[j])
    sat = t_sat | w_sat
    n_sat = int(np.count_nonzero(sat))
    factor = scratch("flat_factor", (h, w))
    stored = scratch("stack_planes", target.shape, STACK_DTYPE)
    for k in range(3):
        cv2.resize(factor_grid[k], (w, h), dst=factor, interpolation=cv2.INTER_LINEAR)
        # Eq. 2, A' = mean(A_B) A / A_B, and the cast to half precision in one
        # OpenCV pass (F16C): the same bits as the float32 product cast by numpy
        # (round to nearest even), at a third of the time of the two passes
        cv2.multiply(target[k], factor, dst=stored[k], dtype=cv2.CV_16F)
        if n_sat:
            stored[k][sat] = np.nan
    offset = 3 * j * h * w * STACK_DTYPE.itemsize
    target = stored
    pwrite_all(job.work_path(RESPONSES), offset, target)
    return ChannelResult(
        mean_b, level, var, factor_grid[1].astype(np.float32),
        tuple(int(k) for k in np.flatnonzero(~own)), n_sat,
    )  # fmt: skip


def _window(shape: tuple[int, int]) -> tuple[int, int, int, int]:
    from tunespec.core.processing import flat_window

    return flat_window(shape, FLAT_WINDOW_PX)


def read_response_rows(
    job: ImageJob, row0: int, row1: int, col0: int = 0, col1: int | None = None
) -> NDArray[np.float32]:
    """Responses of plane rows ``row0:row1`` (and columns), (m, rows, cols) float32."""
    w = job.plane_shape[1]
    col1 = w if col1 is None else col1
    out = _read_stack_rows(job, row0, row1).astype(np.float32)
    return out[:, :, col0:col1] if (col0, col1) != (0, w) else out


def _read_stack_rows(job: ImageJob, row0: int, row1: int) -> NDArray[Any]:
    """Rows ``row0:row1`` of every plane of the stack as stored, (m, rows, w), in
    this thread's scratch buffer ``stack_rows`` (positioned reads)."""
    h, w = job.plane_shape
    m = job.n_responses
    stored = scratch("stack_rows", (m, row1 - row0, w), STACK_DTYPE)
    size = STACK_DTYPE.itemsize
    path = job.work_path(RESPONSES)
    fd = os.open(path, os.O_RDONLY)
    try:
        for k in range(m):
            view = memoryview(stored[k]).cast("B")
            done = 0
            while done < view.nbytes:
                got = os.preadv(fd, [view[done:]], ((k * h + row0) * w) * size + done)
                if got <= 0:
                    raise InputError("the response stack is truncated", path=path)
                done += got
    finally:
        os.close(fd)
    return stored


def _read_phi(job: ImageJob, row0: int, row1: int) -> NDArray[np.float32]:
    w = job.plane_shape[1]
    return np.fromfile(
        job.work_path(PHI),
        dtype=np.float32,
        count=(row1 - row0) * w,
        offset=row0 * w * 4,
    ).reshape(row1 - row0, w)


#: The sessions' illuminants read in this process (the warm-up, the setup and the
#: systematic table each need them: 22 SPD files a session, read once).
_ILLUMINANTS: dict[tuple[Any, ...], Spectra] = {}
_ILLUMINANTS_SIZE = 4
_ILLUMINANTS_LOCK = threading.Lock()


def illuminants_of(job: ImageJob) -> Spectra:
    """Each channel's measured SPD x its target exposure and gain, as processing's
    (:func:`tunespec.core.processing.illuminants_from_spds`); read once per
    process while the files are unchanged."""
    from tunespec.core.io.spectral import read_spectra_csv
    from tunespec.core.processing import illuminants_from_spds

    stamps = []
    for path in job.spd_files:
        try:
            st = os.stat(path)
            stamps.append((st.st_mtime_ns, st.st_size))
        except OSError:
            stamps.append(None)  # read_spectra_csv names the missing file
    isos = tuple(t[0].iso for t in job.targets)
    key = (job.spd_files, job.spd_exposures_s, isos, job.channels, job.session_root,
           tuple(stamps))  # fmt: skip
    with _ILLUMINANTS_LOCK:
        found = _ILLUMINANTS.get(key)
    if found is not None:
        return found
    found = illuminants_from_spds(
        [read_spectra_csv(path) for path in job.spd_files],
        job.spd_exposures_s,
        job.channels,
        isos=isos,
        source=job.session_root,
    )
    with _ILLUMINANTS_LOCK:
        while len(_ILLUMINANTS) >= _ILLUMINANTS_SIZE:
            _ILLUMINANTS.pop(next(iter(_ILLUMINANTS)))
        _ILLUMINANTS[key] = found
    return found


def setup_estimation(
    job: ImageJob,
    results: Sequence[ChannelResult],
    sensitivity: Spectra,
    meta: dict[str, Any],
    prior: Spectra,
    grid: Grid,
    *,
    noise: NoiseModel | SensorFigures | None = None,
    n_levels: int = DEFAULT_LEVEL_BINS,
    n_phi: int = DEFAULT_PHI_BINS,
    force: bool = False,
) -> WienerBank:
    """Stage 3: the session's scale against the chart's, noise model, corrected
    illuminants, lighting matrix, Wiener bank.

    Parameters
    ----------
    results
        :func:`prepare_channel`'s, in ``job.channels`` order.
    sensitivity : Spectra (R, G, B)
        The calibration's sensitivities on their own grid.
    meta
        The calibration's side file (:func:`tunespec.core.io.export.read_sensitivity_meta`):
        its per-LED corrections (or common shift) are applied to the measured SPDs
        as ``tunespec estimate`` does (:func:`lighting_for`).
    prior
        Prior reflectances, on ``grid`` or reaching beyond it: Eq. 5 is solved on
        :func:`tunespec.core.wiener.support_grid`'s samples, as ``tunespec
        estimate`` solves a patch, and the pixels reported on ``grid``.
    noise
        The sensor's noise model, or its figures (the session's averaged darks
        complete the model); default: fitted to the white frames
        (:func:`tunespec.core.image.photon_transfer_fit`).
    force
        Accept a session on another scale than the calibration's chart
        (:func:`tunespec.app.pipeline.lighting.sample_scale_record`).

    Returns
    -------
    WienerBank
        Its ``params`` also hold the noise model's source and the session's scale
        against the chart's (``white_scale``, ``forced``).
    """
    import cv2

    from tunespec.core.calibration import Calibration
    from tunespec.core.excess import flat_field_residual

    # the LEDs are done: their frame buffers (about 0.3 GB a thread at full
    # resolution) and the dark planes go back to the heap, where the blocks' buffers
    # find them, instead of fresh pages beside them
    release_buffers()
    if isinstance(noise, SensorFigures):
        n_darks = int(job.meta.get("n_darks", 1))
        if job.meta.get("dark") == "smooth":  # the box mean's noise is negligible
            n_darks *= DARK_SMOOTH_PX**2
        noise = noise.model(n_darks, int(job.meta.get("n_repeats", 1)))
    elif noise is None:
        noise = photon_transfer_fit(
            np.concatenate([r.ptc_level for r in results], axis=1),
            np.concatenate([r.ptc_var for r in results], axis=1),
        )
    # Eq. 5 solved wherever Eq. 1 integrates, the pixels reported on ``grid``
    F, prior = lighting_for(job, sensitivity, meta, grid, prior)
    white = np.concatenate([r.white_mean for r in results])
    # phi: the flat-field factor of the brightest LED's G plane
    brightest = int(np.argmax([r.white_mean[1] for r in results]))
    h, w = job.plane_shape
    phi = cv2.resize(
        results[brightest].flat_grid, (w, h), interpolation=cv2.INTER_LINEAR
    ).astype(np.float32)
    write_array(job.work_path(PHI), phi)
    # the flat field's residual as the calibration's chart showed it (its K_e, as
    # the patches' estimate and uncertainty use it)
    excess = Calibration.from_meta(sensitivity, meta).excess
    gamma = 0.0 if excess is None else excess.linearity_gamma
    scale = sample_scale_record(
        linearised(white.reshape(-1, 3), gamma), job.channels, illuminants_of(job),
        sensitivity, meta, force=force,
    )  # fmt: skip
    bank = build_wiener_bank(
        F, prior.values, white, noise, prior.wavelength_nm,
        phi_range=(float(phi.min()), float(phi.max())),
        n_levels=n_levels, n_phi=n_phi,
        flat_residual=flat_field_residual(excess), report_nm=grid.wavelength_nm,
    )  # fmt: skip
    bank.params["noise_source"] = noise.source
    # the sensor's non-linearity, undone in every pixel as in the chart's responses
    bank.params["linearity_gamma"] = gamma
    bank.params.update(scale)
    return bank


def warm_up(wavelength_nm: NDArray[np.float64], job: ImageJob | None = None) -> None:
    """Import what :func:`setup_estimation` and ``image_systematic`` use and
    compute the D50 weights of the grid (cached per process): run as a task beside
    the LEDs' (:func:`prepare_channel`), so that the two serial stages between the
    LEDs and the blocks do not wait for it (2 s of colour-science and SciPy imports
    and weight probing at first use), and the writers' libraries (0.3 s of Zarr,
    tifffile and spectral's ENVI imports, which the outputs' creation between the
    setup and the blocks would wait for). With ``job``, its illuminants are read
    too (:func:`illuminants_of`, cached: the setup's serial path then only finds
    them)."""
    import spectral.io.envi  # noqa: F401
    import tifffile  # noqa: F401
    import zarr  # noqa: F401

    from tunespec.core import sensitivity, uncertainty, wiener  # noqa: F401
    from tunespec.core.colorimetry import astm_e308_weights_d50

    astm_e308_weights_d50(np.asarray(wavelength_nm, dtype=np.float64))
    if job is not None:
        illuminants_of(job)


def lighting_for(
    job: ImageJob,
    sensitivity: Spectra,
    meta: dict[str, Any],
    grid: Grid,
    prior: Spectra,
) -> tuple[NDArray[np.float64], Spectra]:
    """``F`` of Eq. 5 for the session, exactly as ``tunespec estimate`` builds it:
    the calibration's corrections applied to the measured SPDs, Eq. 1 integrated on
    the finer of the calibration's and the estimation grid, the reflectance on the
    samples Eq. 5 solves for to report on ``grid``
    (:func:`tunespec.core.wiener.support_grid`,
    :func:`tunespec.core.wiener.integrated_lighting_matrix`); and ``prior`` on them."""
    from tunespec.core.wiener import integrated_lighting_matrix, prior_on_support

    # corrected as ``tunespec estimate`` corrects them, on the integration grid
    L, S, fine = estimation_lighting(illuminants_of(job), sensitivity, meta, grid)
    prior = prior_on_support(prior, grid, fine.wavelength_nm)
    F = integrated_lighting_matrix(
        L.select(job.channels).values,
        S.select(("R", "G", "B")).values,
        fine.wavelength_nm,
        prior.wavelength_nm,
    )
    return F, prior


@dataclass(frozen=True)
class BlockResult:
    """What :func:`estimate_block` returns with ``keep_uncertainty``: the block's
    sRGB preview (rows, cols, 3) uint8, its pixels' own uncertainty (rows, cols, 2:
    u(L*), RMS u) float32 and their CIELAB cells (rows, cols) uint16
    (:meth:`SystematicTable.cells`), for :func:`finish_uncertainty`."""

    srgb: NDArray[np.uint8]
    uncertainty: NDArray[np.float32]
    cells: NDArray[np.uint16]


def estimate_block(
    job: ImageJob,
    bank: WienerBank,
    outputs: ImageOutputs,
    row0: int,
    row1: int,
    *,
    clip: bool = True,
    rectification: Rectification | None = None,
    systematic: SystematicTable | None = None,
    keep_uncertainty: bool = False,
) -> Any:
    """Stage 4: output rows ``row0:row1`` estimated and written.

    ``keep_uncertainty``: the uncertainty TIFF's rows are not written but
    returned, without the systematic part, which :func:`finish_uncertainty` adds
    once ``image_systematic.systematic_table`` is done (so the blocks need not wait
    for it).

    Returns
    -------
    (rows, cols, 3) uint8, or BlockResult with ``keep_uncertainty``
        The sRGB preview of the block.
    """

    if rectification is None:
        planes = _read_stack_rows(job, row0, row1)
        if planes.dtype == np.float16:  # transposed as the bits they are
            planes = planes.view(np.uint16)
        phi = _read_phi(job, row0, row1)
    else:
        planes, phi = _rectified(job, rectification, row0, row1)
    m, r, cols = planes.shape
    c = _pixels_as_rows(planes.reshape(m, r * cols))
    del planes
    gamma = float(bank.params.get("linearity_gamma", 0.0))
    if gamma:
        c = linearised(c, gamma)
    # placed as the cube's rows fall in its files: written there without a copy
    est = estimate_pixels(
        bank, c, phi.reshape(-1), clip=clip,
        out=scratch("block_reflectance", (r * cols, bank.wavelength_nm.size),
                    phase=outputs.cube_offset(row0) % SCRATCH_ALIGN),
    )  # fmt: skip
    del c
    unc = np.stack([est.u_lab_l, est.u_rms], axis=1)
    if systematic is not None:
        unc = systematic.add_to(unc, systematic.cells(est.lab.T))
    unc = unc.reshape(r, cols, 2)
    outputs.write_rows(
        row0,
        est.reflectance.reshape(r, cols, -1),
        est.xyz.reshape(r, cols, 3),
        est.lab.reshape(r, cols, 3),
        None if keep_uncertainty else unc,
    )
    srgb = srgb8_from_xyz_d50(est.xyz.T).reshape(r, cols, 3)
    if keep_uncertainty:
        cells = SystematicTable.cells(est.lab.T).reshape(r, cols)
        return BlockResult(srgb, unc, cells)
    return srgb


#: Pixels transposed at a time by :func:`_pixels_as_rows` (their half floats stay
#: in the L2 cache until converted).
TRANSPOSE_PX = 4096


def _pixels_as_rows(planes: NDArray[Any]) -> NDArray[np.float32]:
    """``planes`` (m, n) as pixels in rows (n, m) float32 (band-interleaved by
    pixel, as the outputs), in this thread's buffers (no fresh pages per block).

    OpenCV's blocked transpose (of the half floats' bits as stored), then its
    half-precision conversion (F16C) as ``x - 0`` (the same bits as numpy's cast,
    NaN and -0 kept; 1.5x its ``x * 1``), :data:`TRANSPOSE_PX` pixels at a time
    while they are cached (a 5760x3840 block: 24 -> 15 ms against transposing the
    whole block, then converting it)."""
    import cv2

    m, n = planes.shape
    c = scratch("block_pixels", (n, m), np.float32)
    if planes.dtype == np.float32:
        cv2.transpose(planes, dst=c)
        return c
    t = scratch("block_pixels_t", (min(TRANSPOSE_PX, n), m), planes.dtype)
    for lo in range(0, n, TRANSPOSE_PX):
        hi = min(lo + TRANSPOSE_PX, n)
        cv2.transpose(planes[:, lo:hi], dst=t[: hi - lo])
        cv2.subtract(t[: hi - lo].view(STACK_DTYPE), 0.0, dst=c[lo:hi],
                     dtype=cv2.CV_32F)  # fmt: skip
    return c


def finish_uncertainty(
    outputs: ImageOutputs,
    blocks: Sequence[BlockResult],
    systematic: SystematicTable | None,
) -> None:
    """The uncertainty TIFF from the blocks' own uncertainty and the systematic
    table (the same sums :func:`estimate_block` makes with ``systematic``)."""
    # block by block: the sums' float64 temporaries stay in the cache and the
    # whole image is never concatenated (this is the last, serial task)
    row0 = 0
    for b in blocks:
        unc = b.uncertainty
        if systematic is not None:
            unc = systematic.add_to(unc.reshape(-1, 2), b.cells.reshape(-1))
            unc = unc.reshape(b.uncertainty.shape)
        outputs.write_uncertainty(row0, unc)
        row0 += unc.shape[0]


def _rectified(
    job: ImageJob, rect: Rectification, row0: int, row1: int
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Responses and phi at the output rows, resampled bilinearly from the planes."""
    import cv2

    h, _w = job.plane_shape
    s0, s1 = rect.source_rows(row0, row1, h)
    u, v = rect.maps(row0, row1)
    v = v - np.float32(s0)
    src = read_response_rows(job, s0, s1)
    out = np.empty((src.shape[0], *u.shape), dtype=np.float32)
    for k in range(src.shape[0]):
        out[k] = cv2.remap(
            src[k], u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
            borderValue=float("nan"),
        )  # fmt: skip
    phi_src = _read_phi(job, s0, s1)
    phi = cv2.remap(phi_src, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out, phi


def block_rows_for(cols: int) -> int:
    """Rows per block so that a block holds about :data:`BLOCK_PIXELS` pixels."""
    return max(1, BLOCK_PIXELS // max(cols, 1))
