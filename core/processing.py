"""Patch responses and illuminants from a session's frames: the numerics of processing.

The stage that reads a session's folder and drives these is
:func:`tunespec.app.pipeline.processing.process_session`. For every LED channel ``j``
of a session (:mod:`tunespec.core.io.session`) and every patch:

1. **Dark subtraction.** The dark frame(s) taken at the same exposure and ISO (light
   off) are averaged and subtracted from the white and the target frame.
2. **Repeats and exposure brackets (optional HDR).** Frames repeated at one exposure
   are averaged; with several exposures per channel each pixel takes the longest
   exposure in which it is not saturated, scaled to the reference (longest) exposure;
   this happens in the linear raw domain.
3. **Flat field, Eq. 2.** ``A' = mean(A_B[centre]) * A / A_B``, pixel- and
   channel-wise, where ``A_B`` is the white background and the mean is taken over a
   ``window_px`` x ``window_px`` window at the centre of ``A_B``. Within each ROI
   ``A_B`` is replaced by its least-squares plane: the light field is smooth at that
   scale, and dividing by the raw white pixels would add the white frame's noise to
   every flat-fielded pixel (and divide by noise in a channel the LED barely
   excites; such a channel borrows the flat field of the ROI's strongest channel).
4. **ROI statistics.** The patches' central ``roi_fraction`` (of the patch area) are
   mapped into the image through the homography of the target's four corners (found
   with :mod:`tunespec.core.homography` or given in the layout), rasterised once into
   pixel indices, and per patch and channel the mean, the per-pixel standard
   deviation (Eq. 6), the pixel count and the clipped fraction are taken. Patches with
   clipped pixels are flagged (``Responses.saturated``), so calibration leaves them
   out.

All of it runs on the half-resolution R, G, B planes of the raw mosaic
(:func:`tunespec.core.io.raw.load_raw`, no demosaicing), and only on the ROI pixels and
the flat-field window: a frame is read, its ROI photosites are gathered as float32,
and the frame is dropped before the next is read, so memory does not grow with the
number of frames and processing costs little more than decoding the raw files.

The illuminant of channel ``j`` in Eq. 1 is the SPD the light source measured around
the target exposure times that exposure in seconds, so channels with different
exposures stay consistent with one set of camera sensitivities.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing", Eq. 1, 2 and 6.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError, shown_names
from tunespec.core.extraction import ExtractionCheck, check_responses
from tunespec.core.io.raw import (
    F_NUMBER_META,
    RawFrame,
    f_number_text,
    load_raw,
    plane_to_full_px,
    quad_mask,
    stated_f_number,
)
from tunespec.core.io.session import (
    FrameRecord,
    Session,
    frames_by_channel,
)
from tunespec.core.layout import TargetLayout
from tunespec.core.metering import reading_meta, suppress_meter_floor
from tunespec.core.responses import Responses
from tunespec.core.spectra import Grid, Spectra

__all__ = [
    "BRACKET_CLIP_LEVEL",
    "EXIF_EXPOSURE_RTOL",
    "FLAT_WINDOW_PX",
    "SATURATION_TOLERANCE",
    "CornerDetection",
    "ProcessedSession",
    "RoiSet",
    "exposure_groups",
    "find_session_corners",
    "flat_window",
    "frame_settings_problem",
]

#: Side of the centre window of the white frame whose mean normalises Eq. 2 (plane px).
FLAT_WINDOW_PX = 100
#: A channel needs its white ROI mean to this relative precision to be flat-fielded
#: with its own white frame (see ``_flat_field``).
FLAT_MIN_PRECISION = 0.01
#: Corner detection works on images at most this wide (block-averaged), in pixels.
DETECT_MAX_WIDTH_PX = 1000
#: A patch is flagged when more than this fraction of its ROI pixels is clipped.
SATURATION_TOLERANCE = 0.0
#: ISO speed whose gain Eq. 1's illuminants are counted in. A raw response is
#: proportional to the light, the exposure time and the sensor's gain, and the gain
#: to the ISO speed: a chart calibrated at ISO 100 and a sample shot at ISO 200 (to
#: shorten a dark sample's exposures) gave reflectances twice too high, with no
#: check able to tell them from a brighter sample. The nominal ratio is taken; a
#: camera's real gains differ from it by a few per cent, so calibrating at the ISO
#: that is measured at stays the most accurate.
ISO_REFERENCE = 100
#: Unit of the illuminants written by processing.
ILLUMINANT_UNIT = "W sr^-1 m^-2 nm^-1 s (measured radiance x exposure x ISO / 100)"


def iso_gain(iso: float) -> float:
    """The sensor's gain at ``iso`` relative to :data:`ISO_REFERENCE` (nominal)."""
    return float(iso) / ISO_REFERENCE


def light_scale(exposure_s: float, iso: float | None = None) -> float:
    """What Eq. 1's illuminants multiply a channel's reading by: its exposure and
    its frames' gain (:func:`iso_gain`; 1 without an ISO)."""
    return float(exposure_s) * (1.0 if iso is None else iso_gain(iso))


#: How far a raw file's own exposure time (EXIF) may lie from the one its session
#: records and scales the light's readings by: EXIF keeps the nominal step (1/125 s
#: for 2^-7 s is 2.4 % off), a third of a stop is 26 %.
EXIF_EXPOSURE_RTOL = 0.1


def frame_settings_problem(
    frame: RawFrame, exposure_s: float, iso: float | None, aperture: float | None
) -> str:
    """What a raw file's own EXIF says against its record: its exposure time and ISO
    (:data:`EXIF_EXPOSURE_RTOL`; Eq. 1's illuminants are scaled by the recorded
    ones, :func:`light_scale`) and its f-number against ``aperture`` (the session's
    first frame's: Eq. 2's white and target frames need one); ``""`` when they agree
    or the file does not say."""
    t = frame.exposure_s
    if t is not None and not math.isclose(t, exposure_s, rel_tol=EXIF_EXPOSURE_RTOL):
        return (
            f"its raw file was exposed {t:g} s where the session records "
            f"{exposure_s:g} s"
        )
    if frame.iso is not None and iso and not math.isclose(frame.iso, iso, rel_tol=0.01):
        return f"its raw file is at ISO {frame.iso:g} where the session records {iso:g}"
    if (
        frame.aperture is not None
        and aperture
        and not math.isclose(frame.aperture, aperture, rel_tol=0.01)
    ):
        return (
            f"its raw file was taken at {f_number_text(frame.aperture)} where the "
            f"session's first frame was at {f_number_text(aperture)} (the aperture "
            "changed)"
        )
    return ""


def illuminants_from_spds(
    spds: Sequence[Spectra],
    exposures_s: Sequence[float],
    names: Sequence[str],
    *,
    isos: Sequence[float] | None = None,
    source: str | None = None,
    factor: float = 1.0,
    grid: Grid | None = None,
    f_number: float | None = None,
) -> Spectra:
    """Eq. 1's illuminants from the light's readings: each channel's measured SPD,
    its meter floor suppressed (:func:`tunespec.core.metering.suppress_meter_floor`,
    at the instrument's own sampling), times :func:`light_scale` of its exposure and
    its frames' ISO (``isos``; none: no gain) and ``factor`` (the gonio's cos
    theta_i), on the first SPD's wavelengths -- or on ``grid``, band-averaged.
    ``f_number``: the one the frames' raw files state, kept in ``meta``
    (:data:`~tunespec.core.io.raw.F_NUMBER_META`; none: not kept).

    The one chain processing, the per-pixel images and the gonio sessions use.
    """
    rows: list[NDArray[np.float64]] = []
    wl: NDArray[np.float64] | None = None
    cleaned = [suppress_meter_floor(spd) for spd in spds]
    iso_of = [None] * len(cleaned) if isos is None else list(isos)
    for spd, t, iso in zip(cleaned, exposures_s, iso_of, strict=True):
        if grid is not None:
            spd = spd.resample(grid, average=True)
        if wl is None:
            wl = spd.wavelength_nm
        scale = light_scale(t, iso) * factor
        rows.append(np.interp(wl, spd.wavelength_nm, spd.values[0]) * scale)
    if wl is None:
        raise InputError("no light readings (SPDs) to build the illuminants from")
    meta = {"unit": ILLUMINANT_UNIT, **({"source": source} if source else {})}
    # each reading's noise and step as reported: the calibration draws it again
    meta |= reading_meta(cleaned, names)
    if f_number is not None:
        meta[F_NUMBER_META] = f"{f_number:g}"  # as EXIF states it (LibRaw: float32)
    return Spectra(wl, np.stack(rows), tuple(names), meta)


_FLAT = "__flat_field_window__"


Loader = Callable[[Path], RawFrame]


def flat_window(
    shape: tuple[int, int], window_px: int = FLAT_WINDOW_PX
) -> tuple[int, int, int, int]:
    """The centre window of Eq. 2's normalisation on planes of ``shape``.

    Parameters
    ----------
    shape
        Plane shape ``(rows, cols)``.
    window_px
        Side of the window in plane pixels (paper: 100), cut to the planes' size.

    Returns
    -------
    (row0, row1, col0, col1)
        The window ``[row0:row1, col0:col1]`` in plane pixels.

    References
    ----------
    Trichromatic Reflectance Capture Using a Tunable Light Source (the paper in
    ``shared/reference``), Eq. 2 (the mean of the white
    background over this centre window normalises the flat field).

    Examples
    --------
    >>> flat_window((512, 768))
    (206, 306, 334, 434)
    """
    h, w = shape
    win = min(int(window_px), h, w)
    if win < 1:
        raise InputError(f"flat-field window must be at least 1 px, got {window_px}")
    r0, c0 = (h - win) // 2, (w - win) // 2
    return r0, r0 + win, c0, c0 + win


@dataclass(frozen=True, eq=False)
class RoiSet:
    """Quadrilateral ROIs rasterised once into plane-pixel indices.

    Parameters
    ----------
    names : n names
        One per ROI.
    rows, cols : (n_total,) int
        Plane-pixel row and column of every ROI pixel, ROIs concatenated in order.
    n_pixels : (n,) int
        Pixels per ROI.
    """

    names: tuple[str, ...]
    rows: NDArray[np.int64]
    cols: NDArray[np.int64]
    n_pixels: NDArray[np.int64]

    @classmethod
    def from_quads(
        cls, names: Sequence[str], quads_px: ArrayLike, shape: tuple[int, int]
    ) -> RoiSet:
        """Rasterise quads given in plane pixels (x, y) on planes of ``shape``.

        A pixel belongs to an ROI when its centre lies inside the quad
        (:func:`tunespec.core.io.raw.quad_mask`).

        Raises
        ------
        InputError
            An ROI reaching outside the image or holding no pixel.
        """
        q = np.asarray(quads_px, dtype=np.float64)
        if q.ndim != 3 or q.shape[1:] != (4, 2) or len(q) != len(names):
            raise InputError(f"ROI quads must be (n, 4, 2) for n names, got {q.shape}")
        h, w = shape
        rows, cols, counts = [], [], []
        for name, quad in zip(names, q, strict=True):
            c0, c1 = math.floor(quad[:, 0].min()), math.ceil(quad[:, 0].max()) + 1
            r0, r1 = math.floor(quad[:, 1].min()), math.ceil(quad[:, 1].max()) + 1
            if c0 < 0 or r0 < 0 or c1 > w or r1 > h:
                raise InputError(
                    f"the ROI of patch {name!r} reaches outside the image ({w}x{h} "
                    "plane px): check the target's corners"
                )
            rr, cc = np.nonzero(quad_mask(quad, c0, r0, c1 - c0, r1 - r0))
            if rr.size == 0:
                raise InputError(
                    f"the ROI of patch {name!r} holds no pixel: the target is too "
                    "small in the image or the ROI fraction too small"
                )
            rows.append(rr + r0)
            cols.append(cc + c0)
            counts.append(rr.size)
        return cls(
            tuple(names),
            np.concatenate(rows).astype(np.int64),
            np.concatenate(cols).astype(np.int64),
            np.array(counts, dtype=np.int64),
        )

    def with_window(
        self, name: str, row0: int, row1: int, col0: int, col1: int
    ) -> RoiSet:
        """A copy with an extra rectangular ROI (all pixels of the window)."""
        rr, cc = np.mgrid[row0:row1, col0:col1]
        return RoiSet(
            (*self.names, name),
            np.concatenate([self.rows, rr.ravel()]),
            np.concatenate([self.cols, cc.ravel()]),
            np.append(self.n_pixels, rr.size),
        )

    def centred_coords(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Column and row offset of every ROI pixel from its ROI's centroid.

        Returns
        -------
        u, v : (n_total,)
            Plane pixels, ROIs concatenated in order (as :meth:`gather`).
        """
        starts = np.concatenate([[0], np.cumsum(self.n_pixels)[:-1]])
        n = self.n_pixels
        u = self.cols.astype(np.float64)
        v = self.rows.astype(np.float64)
        u -= np.repeat(np.add.reduceat(u, starts) / n, n)
        v -= np.repeat(np.add.reduceat(v, starts) / n, n)
        return u, v

    def gather(self, frame: RawFrame) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
        """The R, G, B plane values of every ROI pixel of a frame.

        Reads only the ROI photosites of the mosaic, with the same arithmetic as
        :meth:`tunespec.core.io.raw.RawFrame.planes_in` (so the values are identical),
        instead of converting windows or whole planes: on a full-size frame that
        is what keeps processing close to the raw decoder's own speed.

        Returns
        -------
        values : (3, n_total) float32
            R, G, B of every ROI pixel, full-scale units, ROIs concatenated.
        saturated : (n_total,) bool
            Pixels whose CFA cell has a photosite at or above the white level.
        """
        mosaic = frame.mosaic
        width = mosaic.shape[1]
        flat = mosaic.reshape(-1)  # a view: load_raw keeps the mosaic contiguous
        base = 2 * self.rows * width + 2 * self.cols
        out = np.zeros((3, base.size), dtype=np.float32)
        saturated = np.zeros(base.size, dtype=bool)
        counts = [0, 0, 0]
        for k, letter in enumerate(frame.cfa_pattern):
            dy, dx = divmod(k, 2)
            raw = flat[base + (dy * width + dx)]
            saturated |= raw >= frame.white_level
            black = float(frame.black_level_cfa[dy, dx])
            scale = np.float32(1.0 / (frame.white_level - black))
            val = np.multiply(raw, scale, dtype=np.float32)
            val -= np.float32(black * scale)
            ch = "RGB".index(letter)
            out[ch] += val
            counts[ch] += 1
        for ch, n in enumerate(counts):
            if n > 1:
                out[ch] *= np.float32(1.0 / n)
        return out, saturated


@dataclass(frozen=True, eq=False)
class ProcessedSession:
    """What :func:`tunespec.app.pipeline.processing.process_session` returns.

    Parameters
    ----------
    responses : Responses
        (n_patches, n_channels, 3): mean, per-pixel std, pixel count and saturated
        fraction of the dark-corrected, flat-fielded ROI pixels, full-scale units.
    illuminants : Spectra, (n_channels, n_wl)
        Measured SPD x exposure of each channel's target frame, named by channel,
        on the spectroradiometer's wavelengths.
    layout : TargetLayout
        The layout with the corners used (mosaic pixels).
    corners_source : str
        ``"auto"`` (found in the image), ``"layout"`` or ``"given"``.
    flagged : tuple of (patch, channel)
        Patch/channel pairs with clipped pixels, to be left out of calibration.
    warnings : tuple of str
        Operator-readable notes (saturation, incomplete channels).
    corner_residual_px : float
        RMS distance of the detected edge points from the fitted sides, mosaic
        pixels (NaN unless the corners were found automatically).
    check : ExtractionCheck or None
        The extraction check, once run (:meth:`checked`).
    """

    responses: Responses
    illuminants: Spectra
    layout: TargetLayout
    corners_source: str
    flagged: tuple[tuple[str, str], ...] = ()
    warnings: tuple[str, ...] = ()
    corner_residual_px: float = float("nan")
    stats: dict[str, Any] = field(default_factory=dict)
    check: ExtractionCheck | None = None

    @property
    def aperture(self) -> float | None:
        """The f-number the session's raw files state (EXIF; every frame was checked
        against the first one read), ``None`` when they state none (a TIFF, the
        simulator's DNGs). Kept with the illuminants (``meta``
        :data:`~tunespec.core.io.raw.F_NUMBER_META`), whose CSV keeps it in a comment
        line that its reader checks."""
        return stated_f_number(self.illuminants.meta)

    def checked(self, reference_xyz: ArrayLike | None = None) -> ProcessedSession:
        """A copy with :attr:`check`: :func:`tunespec.core.extraction.
        check_responses` of a white LED's channel, with the chart's reference XYZ
        (layout order) if given; a failed check also adds a warning. A session
        without a white LED is not checked (its ``notes`` say so)."""
        white = _white_channel(self.responses.illuminants)
        if white is None:
            # under a narrow LED alone neither the ROI spread (its pixel noise is
            # not known here) nor the colours (XYZ needs a broadband light) tell a
            # wrong extraction from a right one
            note = "no broadband channel in the session: extraction not checked"
            check = ExtractionCheck((), {}, (note,))
            return replace(self, check=check)
        check = check_responses(self.responses, white, reference_xyz=reference_xyz)
        warnings = self.warnings
        if not check.ok:
            warnings = (*warnings, f"patch extraction check failed: {check.summary()}")
        return replace(self, check=check, warnings=warnings)


@dataclass
class _Pixels:
    """ROI pixels of one frame (or dark average), float32."""

    values: NDArray[np.float32]  # (3, n_total)
    saturated: NDArray[np.bool_]  # (n_total,)


#: Bracket merging treats a cell above this fraction of full scale as clipped: the
#: sensor's full well clips the charge before the read noise is added, so a clipped
#: photosite can read a little under the white level without being flagged.
BRACKET_CLIP_LEVEL = 0.95


def exposure_groups(exposures_s: Sequence[float]) -> list[range]:
    """The runs of equal exposure in a bracket series (longest first).

    Frames repeated at one exposure (``--repeats``, or a bracket factor given twice)
    are averaged before the brackets are merged: the mean of ``n`` frames has
    ``1 / n`` of a frame's photon and read-noise variance.

    >>> exposure_groups([2.0, 2.0, 0.25, 0.25])
    [range(0, 2), range(2, 4)]
    """
    starts = [i for i, t in enumerate(exposures_s) if i == 0 or t != exposures_s[i - 1]]
    return [
        range(a, b)
        for a, b in zip(starts, [*starts[1:], len(exposures_s)], strict=True)
    ]


def _bracket_clipped(frame: _Pixels, shorter: bool) -> NDArray[np.bool_]:
    """Clipped pixels of one frame: flagged by the white level or, when there are
    shorter brackets to take over, above :data:`BRACKET_CLIP_LEVEL`."""
    clipped = frame.saturated.copy()
    if shorter:
        clipped |= frame.values.max(axis=0) > BRACKET_CLIP_LEVEL
    return clipped


def _merge_brackets(
    frames: Sequence[_Pixels], darks: Sequence[_Pixels], exposures_s: Sequence[float]
) -> _Pixels:
    """Dark-subtract and merge exposure brackets (longest first) in the linear domain.

    Repeated frames of one exposure are averaged (:func:`exposure_groups`); a pixel
    clipped in any of them counts as clipped at that exposure. Each pixel takes the
    longest exposure in which it is not clipped, scaled to the reference (first)
    exposure; a pixel clipped in every bracket stays flagged. With brackets, a pixel
    above :data:`BRACKET_CLIP_LEVEL` of full scale (before dark subtraction) counts
    as clipped.
    """
    groups = exposure_groups(exposures_s)
    shorter = len(groups) > 1

    def averaged(group: range) -> _Pixels:
        values = frames[group[0]].values - darks[group[0]].values
        clipped = _bracket_clipped(frames[group[0]], shorter)
        for i in group[1:]:
            values += frames[i].values - darks[i].values
            clipped |= _bracket_clipped(frames[i], shorter)
        if len(group) > 1:
            values *= np.float32(1.0 / len(group))
        return _Pixels(values, clipped)

    merged = averaged(groups[0])
    values, clipped = merged.values, merged.saturated
    for group in groups[1:]:
        if not clipped.any():
            break
        other = averaged(group)
        use = clipped & ~other.saturated
        if use.any():
            scale = np.float32(exposures_s[0] / exposures_s[group[0]])
            values[:, use] = other.values[:, use] * scale
            clipped[use] = False
    return _Pixels(values, clipped)


@dataclass(frozen=True, eq=False)
class _RoiGeometry:
    """What the per-ROI fits need of the ROI pixels, computed once per session.

    ``u, v`` are float32 pixel offsets from each ROI's centroid; ``suu, suv, svv``
    their per-ROI sums of products (the plane fit's normal matrix, whose intercept
    row decouples because the offsets sum to zero).
    """

    n: NDArray[np.int64]
    starts: NDArray[np.int64]
    u: NDArray[np.float32]
    v: NDArray[np.float32]
    suu: NDArray[np.float64]
    suv: NDArray[np.float64]
    svv: NDArray[np.float64]

    @classmethod
    def of(cls, rois: RoiSet, n_rois: int) -> _RoiGeometry:
        n = rois.n_pixels[:n_rois]
        total = int(n.sum())
        u64, v64 = rois.centred_coords()
        u64, v64 = u64[:total], v64[:total]
        starts = np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.int64)
        return cls(
            n,
            starts,
            u64.astype(np.float32),
            v64.astype(np.float32),
            np.add.reduceat(u64 * u64, starts),
            np.add.reduceat(u64 * v64, starts),
            np.add.reduceat(v64 * v64, starts),
        )

    @property
    def n_patch_px(self) -> int:
        """ROI pixels of all patches together (they come first in the gathered rows)."""
        return int(self.n.sum())

    def sums(self, x: NDArray[np.float32]) -> NDArray[np.float64]:
        """Per-ROI sums along the last axis, accumulated in float64."""
        return np.add.reduceat(x, self.starts, axis=-1, dtype=np.float64)

    def spread(self, per_roi: NDArray[np.float64]) -> NDArray[np.float32]:
        """Per-ROI values repeated to every pixel, float32."""
        return np.repeat(per_roi.astype(np.float32), self.n, axis=-1)


def _smooth_white(
    white: NDArray[np.float32], geo: _RoiGeometry
) -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """Least-squares plane through the white frame over each ROI, per channel.

    The light field is smooth at the scale of a patch's ROI (the paper's bench varies
    by 10 % over the whole target), so a plane in ``(u, v)`` keeps its gradient while
    averaging away the white frame's shot and read noise, which a per-pixel division
    would otherwise add to every flat-fielded pixel.

    Parameters
    ----------
    white : (3, N)
        Dark-corrected white-frame pixels of the ROIs, concatenated.
    geo
        The ROIs' pixel offsets and sums.

    Returns
    -------
    fitted : (3, N) float32
        The plane at every pixel.
    rel_se : (3, n_roi)
        Standard error of each ROI's mean white level relative to it (``inf`` for a
        non-positive mean).
    """
    n = geo.n
    sw = geo.sums(white)
    suw = geo.sums(white * geo.u)
    svw = geo.sums(white * geo.v)
    sww = geo.sums(white * white)
    mean = sw / n
    det = geo.suu * geo.svv - geo.suv * geo.suv
    ok = det > 1e-9 * np.maximum(geo.suu * geo.svv, 1e-30)  # one row/column: flat
    safe = np.where(ok, det, 1.0)
    b = np.where(ok, (geo.svv * suw - geo.suv * svw) / safe, 0.0)
    c = np.where(ok, (geo.suu * svw - geo.suv * suw) / safe, 0.0)
    # residual sum of squares of a least-squares fit, without a pass over the pixels
    rss = np.maximum(sww - mean * sw - b * suw - c * svw, 0.0)
    se = np.sqrt(rss / np.maximum(n - 3, 1) / n)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel_se = np.where(mean > 0, se / mean, np.inf)
    fitted = geo.spread(mean)
    fitted += geo.spread(b) * geo.u
    fitted += geo.spread(c) * geo.v
    return fitted, rel_se


def _flat_field(
    target: NDArray[np.float32],
    white: NDArray[np.float32],
    mean_b: NDArray[np.float64],
    geo: _RoiGeometry,
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Eq. 2, ``A' = mean(A_B) A / A_B``, pixel- and channel-wise over the ROIs.

    ``A_B`` is the white frame smoothed by :func:`_smooth_white`. A channel whose
    white signal in an ROI is too weak to divide by (relative standard error above
    :data:`FLAT_MIN_PRECISION`, e.g. the blue channel under a deep-red LED) takes the
    flat field of the strongest channel of that ROI instead: the light field's shape
    is the same for the three channels, only the weak one cannot measure it.

    Returns
    -------
    flat : (3, N) float32
        Flat-fielded target pixels.
    borrowed : (3, n_roi) bool
        Where a channel used the strongest channel's flat field.
    """
    fitted, rel_se = _smooth_white(white, geo)
    positive = np.minimum.reduceat(fitted, geo.starts, axis=1) > 0
    positive &= mean_b[:, None] > 0
    own = (rel_se < FLAT_MIN_PRECISION) & positive
    # factor = mean(A_B) / A_B, in place (channels without signal are replaced below)
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(mean_b.astype(np.float32)[:, None], fitted, out=fitted)
    if not own.all():
        best = np.argmin(np.where(positive, rel_se, np.inf), axis=0)
        lent = fitted[np.repeat(best, geo.n), np.arange(fitted.shape[1])]
        lent[~np.isfinite(lent) | (lent <= 0)] = 1.0  # no white signal at all
        fitted = np.where(np.repeat(own, geo.n, axis=1), fitted, lent[None, :])
    fitted *= target
    return fitted, ~own


def _patch_stats(
    values: NDArray[np.float32], clipped: NDArray[np.bool_], geo: _RoiGeometry
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Mean, per-pixel std (ddof=1) and clipped fraction per ROI.

    Returns
    -------
    mean, std : (n_roi, 3)
    clipped_fraction : (n_roi,)
    """
    n = geo.n
    mean = geo.sums(values) / n
    dev = values - geo.spread(mean)
    dev *= dev
    var = geo.sums(dev) / np.maximum(n - 1, 1)
    std = np.where(n > 1, np.sqrt(var), np.nan)
    frac = geo.sums(clipped.astype(np.float32)) / n
    return mean.T, std.T, frac


def _white_channel(channels: Sequence[str]) -> str | None:
    """The first white LED's channel, if there is one."""
    return next((c for c in channels if "WHITE" in c.upper()), None)


def _detection_channel(channels: Sequence[str]) -> str:
    """A broadband channel for finding the target (white LEDs first)."""
    white = _white_channel(channels)
    return white if white is not None else channels[len(channels) // 2]


def _green_plane(frame: RawFrame, step: int) -> NDArray[np.float32]:
    """The G plane (mean of the two green photosites), block-averaged by ``step``.

    Only for finding the target: no black level or scaling, which the ratio to the
    white frame cancels anyway.
    """
    import cv2

    h2, w2 = frame.shape
    h, w = (h2 // step) * step, (w2 // step) * step
    greens = [divmod(k, 2) for k, c in enumerate(frame.cfa_pattern) if c == "G"]
    (y0, x0), (y1, x1) = greens
    img = frame.mosaic[y0 : 2 * h : 2, x0 : 2 * w : 2].astype(np.float32)
    img += frame.mosaic[y1 : 2 * h : 2, x1 : 2 * w : 2]
    if step > 1:  # an integer factor: INTER_AREA is the block mean
        img = cv2.resize(img, (w // step, h // step), interpolation=cv2.INTER_AREA)
    img -= np.float32(2 * frame.black_level)
    return img


def _find_corners(
    white: RawFrame, target: RawFrame, layout: TargetLayout
) -> tuple[NDArray[np.float64], float]:
    """Target corners (mosaic px) from a white-background and a target frame.

    Works on the G plane straight from the mosaic, block-averaged down to at most
    :data:`DETECT_MAX_WIDTH_PX` columns: sub-pixel edges at that scale place the ROIs
    (the central 20 % of each patch) well within a pixel.
    """
    from tunespec.core.homography import locate_target

    step = max(1, math.ceil(target.shape[1] / DETECT_MAX_WIDTH_PX))
    corners, fit = locate_target(
        _green_plane(target, step), layout, background=_green_plane(white, step)
    )
    plane_xy = corners * step + (step - 1) / 2.0  # block centres -> plane pixels
    return plane_to_full_px(plane_xy), 2.0 * step * fit.residual_px


@dataclass(frozen=True)
class CornerDetection:
    """Where the automatic corner finder found a session's target.

    Parameters
    ----------
    corners_px : (4, 2)
        Outer corners TL, TR, BR, BL of the layout, mosaic pixels.
    residual_px
        RMS distance of the detected edge points from the fitted sides, mosaic px.
    channel
        The channel whose frames were used.
    white_id, target_id
        The white-background and target frames compared.
    """

    corners_px: NDArray[np.float64]
    residual_px: float
    channel: str
    white_id: str
    target_id: str


def _detect_in_session(
    whites: dict[str, list[FrameRecord]],
    targets: dict[str, list[FrameRecord]],
    channels: Sequence[str],
    layout: TargetLayout,
    read: Callable[[FrameRecord], RawFrame],
) -> tuple[CornerDetection, RawFrame, RawFrame]:
    """The one corner detection of a session: processing and the GUI's editor.

    The detection channel among ``channels`` (white LEDs first), its first white-
    background and first target frame, and :func:`_find_corners` on the two.
    """
    c = _detection_channel(channels)
    w_rec, t_rec = whites[c][0], targets[c][0]
    w_frame, t_frame = read(w_rec), read(t_rec)
    corners, residual = _find_corners(w_frame, t_frame, layout)
    found = CornerDetection(corners, residual, c, w_rec.id, t_rec.id)
    return found, w_frame, t_frame


def find_session_corners(
    session: Session,
    layout: TargetLayout | None = None,
    *,
    loader: Loader | None = None,
) -> tuple[CornerDetection, RawFrame]:
    """Find the target's corners in a session's frames, as processing does.

    Uses the frames :func:`~tunespec.app.pipeline.processing.process_session` uses
    with ``corners="auto"``: the white-background and target frames of the same
    broadband channel, compared (the ratio
    flattens the light field, which a target frame alone does not show against the
    board). Channels still being captured count as soon as they have both frames, so
    the finder works while the capture runs; on a complete session the result is
    the one processing gets.

    Parameters
    ----------
    session
        A captured (or partly captured) session.
    layout
        The target's geometry (corners not needed); default the session's.
    loader
        Reads a raw file; default :func:`tunespec.core.io.raw.load_raw`.

    Returns
    -------
    detection : CornerDetection
        The corners (mosaic pixels) and the frames they came from.
    target_frame : RawFrame
        The target frame used (for showing the corners on it).

    Raises
    ------
    InputError
        No channel with both a white-background and a target frame yet, no layout,
        or no target found.
    """
    load = loader or load_raw
    layout = layout or session.layout
    if layout is None:
        raise InputError("the session has no target layout", path=session.root)
    frames = session.frames
    whites = frames_by_channel(frames, "white")
    targets = frames_by_channel(frames, "target")
    order = list(session.settings.channels) or list(whites)
    channels = [c for c in order if c in whites and c in targets]
    if not channels:
        raise InputError(
            "corner detection needs a white-background and a target frame under the "
            "same LED; take them first",
            path=session.root,
        )

    def read(rec: FrameRecord) -> RawFrame:
        return load(session.path_of(rec))

    found, _white, target = _detect_in_session(whites, targets, channels, layout, read)
    return found, target


@dataclass
class _ChannelStats:
    """Per-channel results collected into responses and illuminants."""

    layout: TargetLayout
    use: list[str]
    geo: _RoiGeometry
    rgb: NDArray[np.float64]
    std: NDArray[np.float64]
    sat: NDArray[np.float64]
    white: NDArray[np.float64]  # (n_channels, 3): Eq. 2's mean A_B
    spds: dict[str, tuple[Spectra, float, int]] = field(default_factory=dict)
    flagged: list[tuple[str, str]] = field(default_factory=list)
    n_borrowed: int = 0

    @classmethod
    def empty(
        cls, layout: TargetLayout, use: list[str], geo: _RoiGeometry
    ) -> _ChannelStats:
        rgb = np.zeros((layout.n_patches, len(use), 3))
        sat = np.zeros((layout.n_patches, len(use)))
        white = np.zeros((len(use), 3))
        return cls(layout, use, geo, rgb, np.zeros_like(rgb), sat, white)

    def add(self, session: Session, c: str, white: _Pixels, target: _Pixels) -> None:
        """Flat field (Eq. 2) and ROI statistics of channel ``c``."""
        n_patch_px = self.geo.n_patch_px
        flat = white.values[:, n_patch_px:]
        flat_ok = ~white.saturated[n_patch_px:]
        if flat_ok.sum() < 0.5 * flat_ok.size:
            raise InputError(
                f"channel {c}: the white frame's centre window is clipped; lower the "
                "exposure (or re-meter)",
                path=session.manifest_path,
            )
        mean_b = flat[:, flat_ok].astype(np.float64).mean(axis=1)  # Eq. 2's mean A_B
        a_flat, borrowed = _flat_field(  # Eq. 2
            target.values[:, :n_patch_px],
            white.values[:, :n_patch_px],
            mean_b,
            self.geo,
        )
        self.n_borrowed += int(borrowed.sum())
        clipped = target.saturated[:n_patch_px] | white.saturated[:n_patch_px]
        m, s, f = _patch_stats(a_flat, clipped, self.geo)
        j = self.use.index(c)
        self.rgb[:, j], self.std[:, j], self.sat[:, j] = m, s, f
        self.white[j] = mean_b
        for i in np.nonzero(f > SATURATION_TOLERANCE)[0]:
            self.flagged.append((self.layout.patch_names[i], c))

    def add_spd(self, c: str, spd: Spectra, exposure_s: float, iso: int) -> None:
        """Channel ``c``'s measured SPD, its exposure and ISO (:meth:`illuminants`)."""
        self.spds[c] = (spd, exposure_s, iso)

    def warnings(self) -> list[str]:
        if not self.flagged:
            return []
        chans = sorted({c for _, c in self.flagged}, key=self.use.index)
        return [
            f"{len(self.flagged)} patch/channel pair(s) have clipped pixels (channels "
            f"{shown_names(chans, 6)}); they are "
            "flagged saturated and left out of calibration"
        ]

    def responses(self, n_px: NDArray[np.int64]) -> Responses:
        return Responses(
            self.layout.patch_names,
            tuple(self.use),
            self.rgb,
            self.std,
            np.repeat(n_px[:, None], len(self.use), axis=1).astype(np.float64),
            self.sat,
            self.white,
        )

    def illuminants(self, session: Session, f_number: float | None) -> Spectra:
        """Eq. 1's illuminants, in channel order (:func:`illuminants_from_spds`),
        with the frames' ``f_number``."""
        return illuminants_from_spds(
            [self.spds[c][0] for c in self.use],
            [self.spds[c][1] for c in self.use],
            self.use,
            isos=[self.spds[c][2] for c in self.use],
            source=str(session.root),
            f_number=f_number,
        )
