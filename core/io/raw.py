"""Camera raw frames: the Bayer mosaic as half-resolution R, G, B planes.

:func:`load_raw` reads any raw file LibRaw understands (a Canon CR2, a CFA DNG such as
the simulator writes) through rawpy and keeps the visible mosaic as it is in the file,
with the black level, white level and CFA pattern read from the file. Nothing is
demosaiced, white-balanced or colour-converted: the paper's processing (dark frame,
flat field Eq. 2, ROI averages) works on intensity-linear camera responses.

Each 2 x 2 CFA cell becomes one pixel of three planes::

    R = (r - black) / (white - black)
    G = mean of the two greens, each (g - black) / (white - black)
    B = (b - black) / (white - black)

so the planes are in units of the usable raw range ("full scale"): 0 is the black
level and 1 the white level. A cell is *saturated* when any of its four photosites
is at or above the white level; its values then say nothing about the scene.

Coordinates
-----------
Full-resolution (mosaic) pixel ``(x, y)`` has its centre at integer ``x, y``.
Plane pixel ``(u, v)`` covers mosaic pixels ``2u, 2u + 1`` and ``2v, 2v + 1``; its
centre is at mosaic ``(2u + 0.5, 2v + 0.5)``, see :func:`full_to_plane_px`.

Memory: a 5760 x 3840 frame keeps its 44 MB uint16 mosaic; ``planes`` (66 MB float32)
is computed on first use. :meth:`RawFrame.roi_stats` and :meth:`RawFrame.planes_in`
compute statistics of small windows without converting the whole frame.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Setup": dark-current correction, flat-fielding (Eq. 2), central 20 % ROIs.
"""

from __future__ import annotations

import contextlib
import os
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tunespec.core.errors import InputError

__all__ = [
    "F_NUMBER_META",
    "F_NUMBER_RANGE",
    "PlaneStats",
    "RawFrame",
    "f_number_text",
    "full_to_plane_px",
    "load_raw",
    "plane_to_full_px",
    "quad_mask",
    "stated_f_number",
]

_CHANNELS = "RGB"
#: The mosaic is LibRaw's own buffer (a view that keeps its ``RawPy`` alive, freed
#: with the frame) rather than a copy: 12 ms a 5760x3840 frame, a tenth of
#: processing's decode. Not on Windows, where the file LibRaw keeps open while the
#: frame lives could not be renamed or deleted.
_KEEP_LIBRAW_BUFFER = os.name == "posix"
#: Bytes of photosites :meth:`RawFrame.planes_minus` copies out per strip of rows
#: (kept in the cache for the arithmetic that follows).
_STRIP_BYTES = 1 << 19

#: The f-numbers a lens has (f/0.95 to f/64 on sale): an EXIF f-number outside is no
#: f-number (LibRaw's 0: the file states none), and a file stating one outside is
#: refused.
F_NUMBER_RANGE = (0.5, 128.0)
#: Where a processed session keeps the f-number its raw files state
#: (:attr:`RawFrame.aperture`): its illuminants' ``Spectra.meta`` (they carry the rest
#: of Eq. 1's scale, exposure and ISO), which their spectral CSV keeps in a
#: ``# f_number: 8`` comment line.
F_NUMBER_META = "f_number"


def stated_f_number(meta: Mapping[str, object]) -> float | None:
    """The f-number a processed session's illuminants keep (``meta``
    :data:`F_NUMBER_META`, checked when their file was read), ``None`` if none."""
    value = meta.get(F_NUMBER_META)
    return None if value is None else float(str(value))


def f_number_text(f_number: float | None) -> str:
    """How an f-number is shown: ``"f/8"``, ``"f/5.6"``; ``"not recorded"`` when the
    raw files state none (a TIFF, the simulator's DNGs): never a guess.

    Examples
    --------
    >>> f_number_text(8.0), f_number_text(5.6), f_number_text(None)
    ('f/8', 'f/5.6', 'not recorded')
    """
    return "not recorded" if f_number is None else f"f/{f_number:g}"


def _planes_out(
    caller: str, shape: tuple[int, int, int], out: NDArray[np.float32] | None
) -> NDArray[np.float32]:
    """``out`` checked to hold planes of ``shape`` (float32), or a new array."""
    if out is None:
        return np.empty(shape, dtype=np.float32)
    if out.shape != shape or out.dtype != np.float32:
        raise ValueError(f"{caller}: out {out.shape} is not {shape} float32")
    return out


@dataclass(frozen=True)
class PlaneStats:
    """Per-ROI statistics of the R, G, B planes.

    Parameters
    ----------
    mean : (n_roi, 3)
        Mean of each plane over the ROI's plane pixels, full-scale units
        (NaN for an empty ROI).
    std : (n_roi, 3)
        Sample standard deviation (``ddof=1``) over the same pixels. The G plane is
        the mean of two photosites, so its pixel-to-pixel noise is about
        ``1/sqrt(2)`` of a single green photosite's.
    n_pixels : (n_roi,)
        Plane pixels in each ROI (all pixels, saturated ones included).
    n_saturated : (n_roi,)
        Of those, cells with a photosite at or above the white level.
    """

    mean: NDArray[np.float64]
    std: NDArray[np.float64]
    n_pixels: NDArray[np.int64]
    n_saturated: NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class RawFrame:
    """One raw frame: the visible Bayer mosaic and how to read it.

    Build it with :func:`load_raw`.

    Parameters
    ----------
    path
        The file it was read from.
    mosaic : (H, W) uint16
        The visible raw photosites as stored (``raw_image_visible``), cropped to even
        height and width.
    cfa_pattern
        The 2 x 2 colour order, row-major from the mosaic's top-left photosite, e.g.
        ``"RGGB"``.
    black_level_cfa : (2, 2)
        Black level of each photosite of the 2 x 2 CFA cell, raw DN.
    white_level
        Raw DN at which the sensor clips.
    make, model
        Camera make and model from the file's TIFF tags ("" when absent).
    exposure_s, iso, aperture
        Exposure time, ISO speed and f-number from the file's EXIF, ``None`` when
        absent (an f-number outside :data:`F_NUMBER_RANGE` too).
    """

    path: Path
    mosaic: NDArray[np.uint16]
    cfa_pattern: str
    black_level_cfa: NDArray[np.float64]
    white_level: float
    make: str = ""
    model: str = ""
    exposure_s: float | None = None
    iso: float | None = None
    meta: dict[str, str] = field(default_factory=dict)
    aperture: float | None = None

    # -- sizes and levels -------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """Plane shape ``(H / 2, W / 2)``."""
        h, w = self.mosaic.shape
        return h // 2, w // 2

    @property
    def black_level(self) -> float:
        """Black level, raw DN (mean over the CFA cell; they are usually equal)."""
        return float(np.mean(self.black_level_cfa))

    @property
    def camera(self) -> str:
        """``"make model"``, without repeating the make."""
        if self.model.lower().startswith(self.make.lower()):
            return self.model
        return f"{self.make} {self.model}".strip()

    # -- planes ----------------------------------------------------------------
    @cached_property
    def planes(self) -> NDArray[np.float32]:
        """R, G (mean of the two greens), B, shape (3, H/2, W/2) float32, full scale."""
        h2, w2 = self.shape
        return self.planes_in(0, h2, 0, w2)

    @cached_property
    def saturated(self) -> NDArray[np.bool_]:
        """(H/2, W/2) bool: a photosite of the cell is at or above the white level."""
        h2, w2 = self.shape
        return self.saturated_in(0, h2, 0, w2)

    def planes_in(
        self,
        row0: int,
        row1: int,
        col0: int,
        col1: int,
        out: NDArray[np.float32] | None = None,
    ) -> NDArray[np.float32]:
        """The planes of the window ``[row0:row1, col0:col1]`` (plane pixels).

        Only the window is converted, so ROI work on a full-size frame needs no
        full float copy.

        Parameters
        ----------
        out : (3, rows, cols) float32, optional
            Where the planes go (a reused buffer), else a new array.

        Returns
        -------
        (3, row1 - row0, col1 - col0) float32
            Full-scale units.
        """
        row0, row1, col0, col1 = self._clip_window(row0, row1, col0, col1)
        out = _planes_out("planes_in", (3, row1 - row0, col1 - col0), out)
        self._convert(row0, row1, col0, col1, out)
        return out

    def planes_minus(
        self, dark: NDArray[np.float32], out: NDArray[np.float32] | None = None
    ) -> NDArray[np.float32]:
        """The whole frame's :attr:`planes` less ``dark``, (3, H/2, W/2) float32.

        The same values as ``planes - dark`` (the same float32 operations), made
        strip by strip while the strip is in the cache, without the planes of the
        whole frame being read back for the subtraction.

        Parameters
        ----------
        dark : (3, H/2, W/2) float32
            The dark planes to subtract (full-scale units).
        out : (3, H/2, W/2) float32, optional
            Where the planes go (a reused buffer), else a new array.
        """
        h2, w2 = self.shape
        shape = (3, h2, w2)
        if dark.shape != shape or dark.dtype != np.float32:
            raise ValueError(f"planes_minus: dark {dark.shape} is not {shape} float32")
        out = _planes_out("planes_minus", shape, out)
        self._convert(0, h2, 0, w2, out, dark)
        return out

    def _convert(
        self,
        row0: int,
        row1: int,
        col0: int,
        col1: int,
        out: NDArray[np.float32],
        dark: NDArray[np.float32] | None = None,
    ) -> None:
        """``out`` = the planes of the window (less ``dark``'s same rows), by strips
        of rows: each strip's four photosites are first copied into contiguous
        planes (OpenCV's ``mixChannels``, one pass per row parity: numpy's
        conversions of the strided sites were 3x slower than of contiguous ones),
        then converted with numpy's float32 operations (``(v - black) * scale``
        accumulated in place, the greens averaged) while the strip is cached."""
        import cv2

        cols = col1 - col0
        step = max(1, _STRIP_BYTES // (8 * cols))
        n = min(step, row1 - row0)
        site = np.empty((4, n, cols), dtype=np.uint16)
        tmp = np.empty((n, cols), dtype=np.float32)
        sites = self._sites()
        levels = []
        for (dy, dx), _ in sites:
            black = float(self.black_level_cfa[dy, dx])
            scale = np.float32(1.0 / (self.white_level - black))
            levels.append((scale, np.float32(black * scale)))
        counts = [0, 0, 0]
        for _, ch in sites:
            counts[ch] += 1
        for r0 in range(row0, row1, step):
            r1 = min(r0 + step, row1)
            k = r1 - r0
            s, t = site[:, :k], tmp[:k]
            for dy in (0, 1):
                pairs = self.mosaic[2 * r0 + dy : 2 * r1 : 2, 2 * col0 : 2 * col1]
                cv2.mixChannels(
                    [pairs.reshape(k, cols, 2)], [s[2 * dy], s[2 * dy + 1]],
                    [0, 0, 1, 1],
                )  # fmt: skip
            o = out[:, r0 - row0 : r1 - row0]
            done = [False, False, False]
            for i, ((dy, dx), ch) in enumerate(sites):
                scale, offset = levels[i]
                # (v - black) * scale accumulated in place: no float copy of the mosaic
                target = t if done[ch] else o[ch]
                np.multiply(s[2 * dy + dx], scale, out=target, dtype=np.float32)
                target -= offset
                if done[ch]:
                    o[ch] += t
                done[ch] = True
            for ch, count in enumerate(counts):
                if count > 1:
                    o[ch] *= np.float32(1.0 / count)
            if dark is not None:
                o -= dark[:, r0:r1, col0:col1]

    def saturated_in(
        self, row0: int, row1: int, col0: int, col1: int
    ) -> NDArray[np.bool_]:
        """Saturation mask of the window ``[row0:row1, col0:col1]`` (plane pixels)."""
        row0, row1, col0, col1 = self._clip_window(row0, row1, col0, col1)
        mask = np.zeros((row1 - row0, col1 - col0), dtype=bool)
        # one contiguous pass (15x faster than the four strided compares) settles
        # the usual frame, which has no clipped photosite
        if (
            self.mosaic[2 * row0 : 2 * row1, 2 * col0 : 2 * col1].max()
            < self.white_level
        ):
            return mask
        tmp = np.empty_like(mask)
        for (dy, dx), _ in self._sites():
            site = self._site_view(dy, dx, row0, row1, col0, col1)
            np.greater_equal(site, self.white_level, out=tmp)
            mask |= tmp
        return mask

    def roi_stats(self, quads_px: ArrayLike) -> PlaneStats:
        """Mean and spread of each plane inside quadrilateral ROIs.

        Parameters
        ----------
        quads_px : (n_roi, 4, 2) or (4, 2)
            ROI corners in **plane** pixel coordinates (x, y); convert mosaic
            coordinates (e.g. ``TargetLayout.roi_quads_px()`` of a layout whose
            corners are in mosaic pixels) with :func:`full_to_plane_px`. A plane
            pixel belongs to the ROI when its centre is inside the quad.

        Returns
        -------
        PlaneStats
            Statistics over all pixels of each ROI (saturated ones included;
            ``n_saturated`` says how many there are).
        """
        q = np.asarray(quads_px, dtype=np.float64)
        if q.ndim == 2:
            q = q[None]
        if q.ndim != 3 or q.shape[1:] != (4, 2) or not np.all(np.isfinite(q)):
            raise InputError(f"ROI quads must be finite (n, 4, 2), got {q.shape}")
        h2, w2 = self.shape
        n = len(q)
        mean = np.full((n, 3), np.nan)
        std = np.full((n, 3), np.nan)
        n_px = np.zeros(n, dtype=np.int64)
        n_sat = np.zeros(n, dtype=np.int64)
        for i, quad in enumerate(q):
            col0 = max(int(np.floor(quad[:, 0].min())), 0)
            col1 = min(int(np.ceil(quad[:, 0].max())) + 1, w2)
            row0 = max(int(np.floor(quad[:, 1].min())), 0)
            row1 = min(int(np.ceil(quad[:, 1].max())) + 1, h2)
            if row1 <= row0 or col1 <= col0:
                continue
            mask = quad_mask(quad, col0, row0, col1 - col0, row1 - row0)
            k = int(mask.sum())
            if k == 0:
                continue
            vals = self.planes_in(row0, row1, col0, col1)[:, mask].astype(np.float64)
            n_px[i] = k
            n_sat[i] = int(self.saturated_in(row0, row1, col0, col1)[mask].sum())
            mean[i] = vals.mean(axis=1)
            if k > 1:
                std[i] = vals.std(axis=1, ddof=1)
        return PlaneStats(mean, std, n_px, n_sat)

    # -- helpers ---------------------------------------------------------------
    def _sites(self) -> list[tuple[tuple[int, int], int]]:
        """((dy, dx), channel index 0/1/2) for the four photosites of a CFA cell."""
        return [
            ((k // 2, k % 2), _CHANNELS.index(c))
            for k, c in enumerate(self.cfa_pattern)
        ]

    def _site_view(
        self, dy: int, dx: int, row0: int, row1: int, col0: int, col1: int
    ) -> NDArray[np.uint16]:
        return self.mosaic[2 * row0 + dy : 2 * row1 : 2, 2 * col0 + dx : 2 * col1 : 2]

    def _clip_window(
        self, row0: int, row1: int, col0: int, col1: int
    ) -> tuple[int, int, int, int]:
        h2, w2 = self.shape
        r0, r1 = max(int(row0), 0), min(int(row1), h2)
        c0, c1 = max(int(col0), 0), min(int(col1), w2)
        if r1 <= r0 or c1 <= c0:
            raise InputError(
                f"empty window rows {row0}:{row1}, cols {col0}:{col1} of planes "
                f"{h2}x{w2}",
                path=self.path,
            )
        return r0, r1, c0, c1


def full_to_plane_px(xy_px: ArrayLike) -> NDArray[np.float64]:
    """Mosaic pixel coordinates (..., 2) to plane pixel coordinates.

    Examples
    --------
    >>> full_to_plane_px([[0.5, 0.5], [2.5, 4.5]])
    array([[0., 0.],
           [1., 2.]])
    """
    return (np.asarray(xy_px, dtype=np.float64) - 0.5) / 2.0


def plane_to_full_px(uv_px: ArrayLike) -> NDArray[np.float64]:
    """Plane pixel coordinates (..., 2) to mosaic pixel coordinates."""
    return np.asarray(uv_px, dtype=np.float64) * 2.0 + 0.5


def quad_mask(
    quad: ArrayLike, x0: int, y0: int, width: int, height: int
) -> NDArray[np.bool_]:
    """Pixels of a window whose centres lie inside a convex quadrilateral.

    Parameters
    ----------
    quad : (4, 2)
        Corners (x, y) in order around the quad (either direction).
    x0, y0, width, height
        The window: pixel centres ``x0 ... x0 + width - 1``, ``y0 ... y0 + height - 1``.

    Returns
    -------
    (height, width) bool

    Examples
    --------
    >>> quad_mask([[0.5, 0.5], [2.5, 0.5], [2.5, 1.5], [0.5, 1.5]], 0, 0, 4, 3).astype(int)
    array([[0, 0, 0, 0],
           [0, 1, 1, 0],
           [0, 0, 0, 0]])
    """
    q = np.asarray(quad, dtype=np.float64).reshape(4, 2)
    xs = np.arange(x0, x0 + width, dtype=np.float64)[None, :]
    ys = np.arange(y0, y0 + height, dtype=np.float64)[:, None]
    # signed area picks the winding so the half-plane tests work either way round
    area = 0.5 * np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
    sign = 1.0 if area >= 0 else -1.0
    mask = np.ones((height, width), dtype=bool)
    for k in range(4):
        ax, ay = q[k]
        bx, by = q[(k + 1) % 4]
        cross = (bx - ax) * (ys - ay) - (by - ay) * (xs - ax)
        mask &= sign * cross >= 0
    return mask


def load_raw(
    path: str | PathLike[str], *, white_level: float | None = None
) -> RawFrame:
    """Read a Bayer raw file (CR2, CFA DNG, ...) without demosaicing it.

    Parameters
    ----------
    path
        The raw file.
    white_level
        Override the file's white level (raw DN), for cameras that clip below what
        their metadata says.

    Returns
    -------
    RawFrame
        The visible mosaic with black level, white level, CFA pattern and the
        camera metadata read from the file.

    Raises
    ------
    InputError
        Naming the file, when it is missing or unreadable, is not a raw file LibRaw
        knows, or is not a Bayer CFA image (a LinearRaw/demosaiced DNG, X-Trans,
        a monochrome sensor).
    """
    import rawpy

    path = Path(path)
    if not path.is_file():
        raise InputError("raw file not found", path=path)
    try:
        with contextlib.ExitStack() as opened:
            raw = rawpy.imread(str(path))
            opened.callback(raw.close)
            visible = raw.raw_image_visible
            pattern = raw.raw_pattern
            desc = raw.color_desc.decode("ascii", "replace")
            if visible.ndim != 2 or pattern is None:
                raise InputError(
                    "not a Bayer CFA raw file (a LinearRaw or already demosaiced "
                    f"image with {visible.shape[-1] if visible.ndim == 3 else 1} "
                    "samples per pixel); TuneSpec needs the camera's own raw file "
                    "(CR2) or a CFA DNG",
                    path=path,
                )
            cfa = _bayer_pattern(np.asarray(pattern), desc, path)
            h, w = visible.shape
            h, w = h - h % 2, w - w % 2
            if h < 2 or w < 2:
                raise InputError("raw image is smaller than one CFA cell", path=path)
            mosaic = visible[:h, :w]
            keep = _KEEP_LIBRAW_BUFFER and mosaic.dtype == np.uint16
            if not keep:
                mosaic = np.array(mosaic, dtype=np.uint16, copy=True)
            black_per_channel = np.asarray(raw.black_level_per_channel, dtype=float)
            black_cfa = black_per_channel[np.asarray(pattern)[:2, :2]]
            white = float(raw.white_level)
            camera_white = raw.camera_white_level_per_channel
            if camera_white is not None and any(v > 0 for v in camera_white):
                white = float(min(v for v in camera_white if v > 0))
            other = raw.other
            shutter = float(other.shutter_speed)
            iso_speed = float(other.iso_speed)
            f_number = float(other.aperture)
            if keep:  # the mosaic's memory: closed when the frame is dropped
                opened.pop_all()
    except InputError:
        raise
    except rawpy.LibRawFileUnsupportedError:
        raise InputError(
            "not a camera raw file LibRaw can read (unsupported format)", path=path
        ) from None
    except (rawpy.LibRawError, OSError) as exc:
        detail = (
            exc.args[0].decode() if exc.args and isinstance(exc.args[0], bytes) else exc
        )
        raise InputError(
            f"cannot read as a camera raw file (truncated or not a raw file?): "
            f"{type(exc).__name__}: {detail}",
            path=path,
        ) from None
    if white_level is not None:
        white = float(white_level)
    if not np.all(white > black_cfa):
        raise InputError(
            f"white level {white:g} is not above the black level {black_cfa.max():g}",
            path=path,
        )
    tags = _tiff_ifd0_strings(path)
    lo, hi = F_NUMBER_RANGE  # outside: no f-number (0: none stated)
    return RawFrame(
        path=path,
        mosaic=mosaic,
        cfa_pattern=cfa,
        black_level_cfa=black_cfa,
        white_level=white,
        make=tags.get(271, ""),
        model=tags.get(272, ""),
        exposure_s=shutter if shutter > 0 else None,
        iso=iso_speed if iso_speed > 0 else None,
        aperture=f_number if lo <= f_number <= hi else None,
        meta={"unique_camera_model": tags.get(50708, "")} if 50708 in tags else {},
    )


def _bayer_pattern(pattern: NDArray[np.generic], desc: str, path: Path) -> str:
    """The 2 x 2 pattern as letters, e.g. ``"RGGB"``; InputError if not Bayer."""
    p = pattern.astype(int)
    if p.shape == (4, 4):
        # LibRaw reports some 2x2 patterns as 4x4: accept if it repeats
        if not (
            np.array_equal(p[:2, :2], p[2:, :2])
            and np.array_equal(p[:2, :2], p[:2, 2:])
        ):
            raise InputError(f"not a 2x2 Bayer CFA (pattern {p.tolist()})", path=path)
        p = p[:2, :2]
    if p.shape != (2, 2) or p.max() >= len(desc):
        raise InputError(
            f"not a Bayer CFA (pattern {p.tolist()}, colours {desc!r})", path=path
        )
    letters = "".join(desc[i] for i in p.ravel())
    if sorted(letters) != ["B", "G", "G", "R"]:
        raise InputError(
            f"not an RGB Bayer CFA (pattern {letters}); TuneSpec needs R, G, G, B",
            path=path,
        )
    return letters


def _tiff_ifd0_strings(path: Path) -> dict[int, str]:
    """ASCII tags Make (271), Model (272), UniqueCameraModel (50708) of IFD0.

    rawpy does not expose make and model, so they are read from the TIFF header that
    CR2 and DNG files share. Anything unexpected gives an empty result.
    """
    wanted = {271, 272, 50708}
    out: dict[int, str] = {}
    try:
        with path.open("rb") as fh:
            head = fh.read(8)
            if head[:2] == b"II":
                e = "<"
            elif head[:2] == b"MM":
                e = ">"
            else:
                return out
            (offset,) = struct.unpack(e + "I", head[4:8])
            fh.seek(offset)
            (n,) = struct.unpack(e + "H", fh.read(2))
            entries = fh.read(12 * min(n, 4096))
            for k in range(len(entries) // 12):
                tag, typ, count, value = struct.unpack(
                    e + "HHI4s", entries[12 * k : 12 * k + 12]
                )
                if tag not in wanted or typ != 2:
                    continue
                if count <= 4:
                    data = value[:count]
                else:
                    fh.seek(struct.unpack(e + "I", value)[0])
                    data = fh.read(min(count, 512))
                out[tag] = data.split(b"\0", 1)[0].decode("ascii", "replace").strip()
    except (OSError, struct.error):
        return {}
    return out
