"""Write a Bayer CFA DNG (the simulated camera's raw file) with pidng.

The file is what LibRaw/rawpy reads back bit for bit: ``raw_image_visible`` equals the
mosaic written, and the black level, white level, CFA pattern, exposure time, ISO,
make and model come back from the tags (checked in ``tests/core/test_raw.py``).

Storage is 16 bits per sample while ``WhiteLevel`` says where the 14-bit sensor
clips (the 5D Mark III's data are 14-bit). pidng 4.0.9's 14-bit packer is not usable:
``pidng.packing.pack14`` strides the samples by 6 but the bytes by 7, so it raises on
any width, and it keeps only 2 of the low 6 bits of each first sample. 16-bit samples
cost 1/7 more disk (44 MB for 5760 x 3840) and carry no decoding risk.

pidng's IFD-typed tag cannot be encoded (a ``str``/``bytes`` mix-up in
``dngTag.setValue``), so the EXIF sub-IFD (where LibRaw looks for the ISO speed) is
written through :class:`_SubIfdTag`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from datetime import datetime
from fractions import Fraction
from os import PathLike
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tunespec.core.session import create_temp_file

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
    from pidng.core import RAW2DNG
    from pidng.defs import CalibrationIlluminant, PhotometricInterpretation
    from pidng.dng import DNGTags, Tag, dngIFD, dngTag

    path = Path(path)
    mosaic = np.asarray(mosaic)
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

    tags = DNGTags()
    tags.set(Tag.ImageWidth, width)
    tags.set(Tag.ImageLength, height)
    tags.set(Tag.TileWidth, width)
    tags.set(Tag.TileLength, height)
    tags.set(Tag.Orientation, 1)
    tags.set(
        Tag.PhotometricInterpretation, PhotometricInterpretation.Color_Filter_Array
    )
    tags.set(Tag.SamplesPerPixel, 1)
    tags.set(Tag.BitsPerSample, 16)
    tags.set(Tag.PlanarConfiguration, 1)
    tags.set(Tag.CFARepeatPatternDim, [2, 2])
    tags.set(Tag.CFAPattern, CFA_PATTERNS[cfa_pattern])
    tags.set(Tag.CFAPlaneColor, [0, 1, 2])
    tags.set(Tag.CFALayout, 1)
    if blacks.size == 4:
        tags.set(Tag.BlackLevelRepeatDim, [2, 2])
        tags.set(Tag.BlackLevel, [round(b) for b in blacks])
    else:
        tags.set(Tag.BlackLevel, round(float(blacks[0])))
    tags.set(Tag.WhiteLevel, int(white_level))
    tags.set(Tag.DNGBackwardVersion, [1, 2, 0, 0])
    tags.set(Tag.Make, make)
    tags.set(Tag.Model, model)
    tags.set(Tag.UniqueCameraModel, unique_camera_model or f"{make} {model}".strip())
    if color_matrix is not None:
        cm = [int(v) for v in color_matrix]
        if len(cm) != 9:
            raise ValueError("color_matrix needs 9 values")
        tags.set(Tag.ColorMatrix1, [[v, 10000] for v in cm])
        tags.set(Tag.CalibrationIlluminant1, CalibrationIlluminant.D65)
        tags.set(Tag.AsShotNeutral, [[1, 1], [1, 1], [1, 1]])
    if description:
        tags.set(Tag.ImageDescription, description)
    exif = dngIFD()
    if exposure_s is not None:
        if not exposure_s > 0:
            raise ValueError(f"exposure_s must be > 0, got {exposure_s}")
        frac = Fraction(exposure_s).limit_denominator(1_000_000)
        tags.set(Tag.ExposureTime, [[frac.numerator, frac.denominator]])
        exif.tags.append(dngTag(Tag.ExposureTime, [[frac.numerator, frac.denominator]]))
    if iso is not None:
        if not 0 < iso <= 65535:
            raise ValueError(f"iso must be in 1..65535, got {iso}")
        exif.tags.append(dngTag(Tag.PhotographicSensitivity, [int(iso)]))
        exif.tags.append(dngTag(Tag.SensitivityType, [3]))  # ISO speed
    if timestamp is not None:
        text = timestamp.strftime("%Y:%m:%d %H:%M:%S")
        tags.set(Tag.DateTime, text)
        exif.tags.append(dngTag(Tag.DateTimeOriginal, text))
    if exif.tags:
        exif.tags.append(dngTag(Tag.ExifVersion, list(b"0230")))
        # DNGTags has no public way to add a custom tag object
        tags.__tags__[Tag.EXIF_IFD] = _sub_ifd_tag(Tag.EXIF_IFD, exif)

    writer = RAW2DNG()
    writer.options(tags, path="", compress=False)
    buf = writer.convert(np.ascontiguousarray(mosaic), filename="")
    _write_atomic(path, buf)
    return path


def _sub_ifd_tag(tag: tuple[int, tuple[int, int]], ifd: object) -> object:
    """A pidng tag pointing at a sub-IFD (works around ``dngTag.setValue``)."""
    from pidng.dng import Type, dngTag

    class _SubIfdTag(dngTag):  # type: ignore[misc]
        def setValue(self, value: list[object]) -> None:  # pidng's method name
            if self.DataType == Type.IFD:
                self.Value = b"\0\0\0\0"
                self.subIFD = value[0]
            else:
                super().setValue(value)

    return _SubIfdTag(tag, [ifd])


def _write_atomic(path: Path, data: bytes | bytearray) -> None:
    """Write ``data`` to ``path`` via a temporary file and a rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # the umask's permissions, as every other output (mkstemp's would be 0600)
    tmp = create_temp_file(path.parent, f".{path.name}.", ".part")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
