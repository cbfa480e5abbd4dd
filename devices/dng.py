"""Write a Bayer CFA DNG (the simulated camera's raw file), with numpy and struct only.

The file is what LibRaw/rawpy reads back bit for bit: ``raw_image_visible`` equals the
mosaic written, and the black level, white level, CFA pattern, exposure time, ISO,
make and model come back from the tags (checked in ``tests/devices/test_sim_camera.py``
and ``tests/core/test_raw.py``).

A DNG here is a little-endian baseline TIFF: one IFD with the uncompressed mosaic as
one strip (``PhotometricInterpretation`` 32803 = CFA) and the DNG tags, plus an EXIF
sub-IFD, where LibRaw looks for the ISO speed. Written by :func:`_tiff_bytes`, a few
dozen lines, because

- pidng, used before, is built from source on install (no wheels): installing
  TuneSpec needed a C compiler;
- tifffile (wheels) writes the main IFD's tags through ``extratags`` but cannot
  write an EXIF sub-IFD (a tag whose value is the offset of another IFD), so the
  ISO would be lost or need a hand-made IFD patched into its output anyway.

Storage is 16 bits per sample while ``WhiteLevel`` says where the 14-bit sensor
clips (the 5D Mark III's data are 14-bit): 1/7 more disk (44 MB for 5760 x 3840)
than 14-bit packing and no decoding risk.

Tags (TIFF 6.0, TIFF/EP, DNG 1.4.0.0): IFD0 NewSubFileType 254, ImageWidth 256,
ImageLength 257, BitsPerSample 258, Compression 259, PhotometricInterpretation 262,
ImageDescription 270, Make 271, Model 272, StripOffsets 273, Orientation 274,
SamplesPerPixel 277, RowsPerStrip 278, StripByteCounts 279, PlanarConfiguration 284,
Software 305, DateTime 306, CFARepeatPatternDim 33421, CFAPattern 33422, ExposureTime
33434, FNumber 33437, ExifIFD 34665, DNGVersion 50706, DNGBackwardVersion 50707,
UniqueCameraModel 50708, CFAPlaneColor 50710, CFALayout 50711, BlackLevelRepeatDim
50713, BlackLevel 50714, WhiteLevel 50717, ColorMatrix1 50721, AsShotNeutral 50728,
CalibrationIlluminant1 50778; EXIF: ExposureTime 33434, FNumber 33437,
PhotographicSensitivity 34855, SensitivityType 34864, ExifVersion 36864,
DateTimeOriginal 36867.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from datetime import datetime
from fractions import Fraction
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tunespec.core.io.session import atomic_write_bytes

__all__ = ["CANON_5D_MARK_III_COLOR_MATRIX", "CFA_PATTERNS", "write_dng"]

#: DNG CFAPattern codes (0 = R, 1 = G, 2 = B) by name.
CFA_PATTERNS: dict[str, list[int]] = {
    "RGGB": [0, 1, 1, 2],
    "BGGR": [2, 1, 1, 0],
    "GRBG": [1, 0, 2, 1],
    "GBRG": [1, 2, 0, 1],
}

#: XYZ(D65) -> camera matrix of the Canon EOS 5D Mark III, x 10000, as tabulated by
#: dcraw/LibRaw (``adobe_coeff``). Only for raw viewers' previews; TuneSpec never
#: uses it.
CANON_5D_MARK_III_COLOR_MATRIX: tuple[int, ...] = (
    6722, -635, -963, -4287, 12460, 2028, -908, 2162, 5668,
)  # fmt: skip

#: LibRaw refuses images smaller than this (identify(): width/height < 22).
_MIN_SIZE_PX = 22


def write_dng(
    path: str | PathLike[str],
    mosaic: NDArray[np.uint16],
    *,
    cfa_pattern: str = "RGGB",
    black_level: float | Sequence[float] = 2048,
    white_level: int = 15000,
    exposure_s: float | None = None,
    iso: int | None = None,
    f_number: float | None = None,
    make: str = "TuneSpec",
    model: str = "SimCamera",
    unique_camera_model: str | None = None,
    timestamp: datetime | None = None,
    description: str | None = None,
    color_matrix: Sequence[int] | None = CANON_5D_MARK_III_COLOR_MATRIX,
) -> Path:
    """Write a raw mosaic as an uncompressed CFA DNG, atomically.

    The file appears complete or not at all: it is written to a temporary file in
    the same folder, flushed to disk and renamed over ``path``.

    Parameters
    ----------
    path
        Where to write (``.dng`` by convention; the name is used as given).
    mosaic : (H, W) uint16
        Raw photosite values in DN, black level included. H, W >= 22 (LibRaw's
        minimum).
    cfa_pattern
        2 x 2 colour order from the top-left photosite, one of :data:`CFA_PATTERNS`.
    black_level
        One value, or four in CFA-cell order (row-major), raw DN.
    white_level
        Raw DN where the sensor clips (e.g. 15000 for a 14-bit Canon at ISO 100).
    exposure_s, iso
        Written to the EXIF sub-IFD (and ``ExposureTime`` to IFD0 as well).
    f_number
        The lens's f-number, EXIF ``FNumber`` (in both IFDs, as ``ExposureTime``);
        omitted when ``None``.
    make, model, unique_camera_model
        TIFF ``Make``/``Model`` and DNG ``UniqueCameraModel`` (default
        ``"make model"``).
    timestamp
        ``DateTime``/``DateTimeOriginal``; omitted when ``None``.
    description
        TIFF ``ImageDescription``, e.g. a note that the frame is simulated.
    color_matrix
        9 integers, ``ColorMatrix1`` x 10000 (D65) for viewers; ``None`` omits it.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ValueError
        For a mosaic that is not 2-D uint16 of at least 22 x 22, an unknown CFA
        pattern, or levels out of range.
    OSError
        When the file cannot be written (the temporary file is removed).
    """
    path = Path(path)
    mosaic = np.asarray(mosaic)
    height, width, blacks = _checked_mosaic(
        mosaic, cfa_pattern, black_level, white_level
    )
    ifd0: dict[int, tuple[int, bytes]] = {
        254: _long(0),  # NewSubFileType: the main image
        256: _long(width),
        257: _long(height),
        258: _short(16),  # BitsPerSample
        259: _short(1),  # Compression: none
        262: _short(_CFA),  # PhotometricInterpretation
        271: _ascii(make),
        272: _ascii(model),
        273: _long(0),  # StripOffsets: set below
        274: _short(1),  # Orientation: top left
        277: _short(1),  # SamplesPerPixel
        278: _long(height),  # RowsPerStrip: one strip
        279: _long(2 * width * height),  # StripByteCounts
        284: _short(1),  # PlanarConfiguration: chunky
        305: _ascii("TuneSpec"),
        33421: _short(2, 2),  # CFARepeatPatternDim
        33422: _byte(*CFA_PATTERNS[cfa_pattern]),
        50706: _byte(1, 4, 0, 0),  # DNGVersion
        50707: _byte(1, 2, 0, 0),  # DNGBackwardVersion (BlackLevelRepeatDim, ...)
        50708: _ascii(unique_camera_model or f"{make} {model}".strip()),
        50710: _byte(0, 1, 2),  # CFAPlaneColor: R, G, B
        50711: _short(1),  # CFALayout: rectangular
        50717: _long(int(white_level)),
    }
    if blacks.size == 4:
        ifd0[50713] = _short(2, 2)  # BlackLevelRepeatDim
    ifd0[50714] = _long(*(round(float(b)) for b in blacks))
    if color_matrix is not None:
        cm = [int(v) for v in color_matrix]
        if len(cm) != 9:
            raise ValueError("color_matrix needs 9 values")
        ifd0[50721] = _srational(*((v, 10000) for v in cm))  # ColorMatrix1
        ifd0[50728] = _rational((1, 1), (1, 1), (1, 1))  # AsShotNeutral
        ifd0[50778] = _short(_D65)  # CalibrationIlluminant1
    if description:
        ifd0[270] = _ascii(description)
    exif = _exif_tags(ifd0, exposure_s, iso, f_number, timestamp)

    head = _tiff_bytes(ifd0, exif)
    pixels = np.ascontiguousarray(mosaic, dtype="<u2")
    _write_atomic(path, (head, memoryview(pixels).cast("B")))
    return path


def _checked_mosaic(
    mosaic: NDArray,
    cfa_pattern: str,
    black_level: float | Sequence[float],
    white_level: int,
) -> tuple[int, int, NDArray[np.float64]]:
    """(height, width, black levels) of a mosaic :func:`write_dng` can write.

    Raises
    ------
    ValueError
        See :func:`write_dng`.
    """
    if mosaic.ndim != 2 or mosaic.dtype != np.uint16:
        raise ValueError(
            f"mosaic must be a 2-D uint16 array, got {mosaic.dtype} {mosaic.shape}"
        )
    height, width = mosaic.shape
    if height < _MIN_SIZE_PX or width < _MIN_SIZE_PX:
        raise ValueError(
            f"mosaic {width}x{height} is too small for LibRaw (>= {_MIN_SIZE_PX} px)"
        )
    if cfa_pattern not in CFA_PATTERNS:
        raise ValueError(
            f"unknown CFA pattern {cfa_pattern!r}; known: {', '.join(CFA_PATTERNS)}"
        )
    blacks = np.atleast_1d(np.asarray(black_level, dtype=float))
    if blacks.size not in (1, 4):
        raise ValueError("black_level must be one value or four (CFA-cell order)")
    if (
        not (0 < white_level <= 65535)
        or np.any(blacks < 0)
        or np.any(blacks >= white_level)
    ):
        raise ValueError(
            f"need 0 <= black_level < white_level <= 65535, got {blacks.tolist()} "
            f"and {white_level}"
        )
    return height, width, blacks


def _exif_tags(
    ifd0: dict[int, tuple[int, bytes]],
    exposure_s: float | None,
    iso: int | None,
    f_number: float | None,
    timestamp: datetime | None,
) -> dict[int, tuple[int, bytes]]:
    """The EXIF sub-IFD's tags (and their copies and pointer in ``ifd0``)."""
    exif: dict[int, tuple[int, bytes]] = {}
    # ExposureTime and FNumber: positive rationals, in both IFDs
    for tag, name, value, most in (
        (33434, "exposure_s", exposure_s, 1_000_000),
        (33437, "f_number", f_number, 1000),
    ):
        if value is None:
            continue
        if not value > 0:
            raise ValueError(f"{name} must be > 0, got {value}")
        frac = Fraction(value).limit_denominator(most)
        ifd0[tag] = exif[tag] = _rational((frac.numerator, frac.denominator))
    if iso is not None:
        if not 0 < iso <= 65535:
            raise ValueError(f"iso must be in 1..65535, got {iso}")
        exif[34855] = _short(int(iso))  # PhotographicSensitivity
        exif[34864] = _short(3)  # SensitivityType: ISO speed
    if timestamp is not None:
        text = timestamp.strftime("%Y:%m:%d %H:%M:%S")
        ifd0[306] = exif[36867] = _ascii(text)  # DateTime, DateTimeOriginal
    if exif:
        exif[36864] = (_UNDEFINED, b"0230")  # ExifVersion
        ifd0[34665] = _long(0)  # ExifIFD: set below
    return exif


# -- a minimal TIFF encoder (little endian) ---------------------------------------
_BYTE, _ASCII, _SHORT, _LONG, _RATIONAL, _UNDEFINED, _SRATIONAL = 1, 2, 3, 4, 5, 7, 10
#: PhotometricInterpretation CFA (TIFF/EP) and CalibrationIlluminant D65 (EXIF).
_CFA, _D65 = 32803, 21


def _byte(*values: int) -> tuple[int, bytes]:
    return _BYTE, bytes(values)


def _ascii(text: str) -> tuple[int, bytes]:
    return _ASCII, text.encode("ascii", "replace") + b"\0"


def _short(*values: int) -> tuple[int, bytes]:
    return _SHORT, struct.pack(f"<{len(values)}H", *values)


def _long(*values: int) -> tuple[int, bytes]:
    return _LONG, struct.pack(f"<{len(values)}I", *values)


def _rational(*pairs: tuple[int, int]) -> tuple[int, bytes]:
    return _RATIONAL, struct.pack(f"<{2 * len(pairs)}I", *(v for p in pairs for v in p))


def _srational(*pairs: tuple[int, int]) -> tuple[int, bytes]:
    return _SRATIONAL, struct.pack(
        f"<{2 * len(pairs)}i", *(v for p in pairs for v in p)
    )


#: Bytes per value of each field type (the entry's count is in values).
_TYPE_SIZE = {_BYTE: 1, _ASCII: 1, _SHORT: 2, _LONG: 4, _RATIONAL: 8, _UNDEFINED: 1}
_TYPE_SIZE[_SRATIONAL] = 8


def _ifd(entries: dict[int, tuple[int, bytes]], offset: int) -> bytes:
    """One IFD at file ``offset``, followed by the values that do not fit its entries.

    Entries are sorted by tag (TIFF 6.0 requires it); values longer than 4 bytes
    go after the IFD, each on a word boundary; the next-IFD offset is 0.
    """
    n = len(entries)
    extra_at = offset + 2 + 12 * n + 4
    table, extra = [struct.pack("<H", n)], bytearray()
    for tag in sorted(entries):
        kind, data = entries[tag]
        count = len(data) // _TYPE_SIZE[kind]
        if len(data) <= 4:
            table.append(struct.pack("<HHI", tag, kind, count) + data.ljust(4, b"\0"))
        else:
            table.append(struct.pack("<HHII", tag, kind, count, extra_at + len(extra)))
            extra += data + b"\0" * (len(data) % 2)
    table.append(struct.pack("<I", 0))
    return b"".join(table) + bytes(extra)


def _tiff_bytes(
    ifd0: dict[int, tuple[int, bytes]], exif: dict[int, tuple[int, bytes]]
) -> bytes:
    """Header, IFD0 and the EXIF IFD; the pixel strip follows them at the end.

    IFD0's size does not depend on the offsets it holds (LONG values inline), so it
    is laid out once to place the EXIF IFD and the strip, then written for real.
    """
    ifd0_at = 8
    size0 = len(_ifd(ifd0, ifd0_at))
    exif_at = ifd0_at + size0
    exif_bytes = _ifd(exif, exif_at) if exif else b""
    strip_at = exif_at + len(exif_bytes)
    strip_at += strip_at % 2
    ifd0 = {**ifd0, 273: _long(strip_at)}
    if exif:
        ifd0[34665] = _long(exif_at)
    head = b"II*\0" + struct.pack("<I", ifd0_at) + _ifd(ifd0, ifd0_at) + exif_bytes
    return head.ljust(strip_at, b"\0")


def _write_atomic(path: Path, chunks: Sequence[bytes | memoryview]) -> None:
    """Write ``chunks`` to ``path`` via a temporary file and a rename (the umask's
    permissions, as every other output)."""
    atomic_write_bytes(path, chunks, ".part")
