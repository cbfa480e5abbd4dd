"""Image outputs of the per-pixel estimation, each in a format its users already read.

One folder per session (:class:`ImageOutputs`)::

    cube.hdr, cube.img   ENVI, float32, band-interleaved by pixel, wavelengths in nm
                         (Spectral Python ``spectral.open_image``, ENVI, GDAL)
    cube.zarr/           the same cube as a Zarr v3 group that xarray opens as a
                         labelled data set (``xarray.open_zarr``): ``reflectance``
                         with named dimensions (``y``, ``x``, ``wavelength``), the
                         ``wavelength`` coordinate in nm, CF-style attributes
                         (``units``, ``long_name``) and the provenance in the
                         group's attributes; a chunk is a whole block of rows (all
                         columns and bands), the chunks in one shard (Zarr v3's
                         ``sharding_indexed`` codec) in row order, uncompressed:
                         the shard file is the ENVI file's bytes followed by the
                         shard index, so with both formats ``cube.img`` is a hard
                         link to it and the cube is written once
    xyz.tif              CIE XYZ (D50, Y of the white 100), float32 (rows, cols, 3),
                         photometric RGB (TIFF tag 262 = 2) whose three samples are
                         X, Y, Z as the ImageDescription's ``samples`` says (TIFF has
                         no XYZ photometric but LogLuv's, an encoding)
    lab.tif              CIELAB (ICC D50 white), photometric CIELab (262 = 8) with
                         IEEE float samples (339 = 3) holding L* (0-100), a*, b*
                         unscaled (not TIFF 6's 8/16-bit integer encoding)
    uncertainty.tif      float32 (rows, cols, 2), photometric MINISBLACK with one
                         unspecified extra sample (338 = 0): u(L*) and the RMS over
                         wavelength of the spectrum's standard uncertainty (k = 1),
                         named in the ImageDescription's ``samples``
    srgb.png             8-bit sRGB preview
    provenance.json      session, calibration, grid, noise model, software version;
                         written last, so its presence means the folder is complete

The big files are created at their full size first and then filled by blocks of
rows, each written at its own offset (:meth:`ImageOutputs.write_rows`), so any
number of processes can write disjoint row blocks at the same time and memory
stays that of a block. The Zarr chunks are whole row blocks for the same reason.
The ENVI file may be longer than the cube (the shard's index, and the padding of
the last chunk as a hole that reads as zeros): ENVI readers read the header's
lines x samples x bands from offset 0. The cube's and the TIFFs' rows go to the
disk directly (``O_DIRECT`` where the system and file system have it,
:func:`pwrite_direct`): through the page cache, the cube's 1.35 GB cost 2-3 s of
system time on the development machine (pages allocated, copied into, written
back), directly 0.05 s and the disk's own time, which the other blocks' computing
overlaps.

References
----------
ENVI header format: NV5 Geospatial, "ENVI Header Files" (ENVI 5.6 documentation).
Zarr storage specification v3 (zarr-specs, 2023). TIFF 6.0 (Adobe, 1992).
"""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tunespec.core.errors import InputError
from tunespec.core.limits import dumps_json

__all__ = [
    "CUBE_HDR",
    "IMAGE_FORMATS",
    "PROVENANCE",
    "ImageOutputs",
    "SpectralImage",
    "open_image_outputs",
    "pwrite_all",
    "pwrite_direct",
    "read_provenance",
    "remove_partial_outputs",
    "valid_formats",
    "write_array",
]

CUBE_HDR = "cube.hdr"
CUBE_IMG = "cube.img"
CUBE_ZARR = "cube.zarr"
#: The one shard of the cube's Zarr array (v3 default chunk key encoding).
ZARR_SHARD = ("reflectance", "c", "0", "0", "0")
XYZ_TIF = "xyz.tif"
LAB_TIF = "lab.tif"
UNC_TIF = "uncertainty.tif"
SRGB_PNG = "srgb.png"
PROVENANCE = "provenance.json"
#: The cube's array in ``cube.zarr`` and its dimension names (xarray's).
ZARR_CUBE = "reflectance"
ZARR_DIMENSIONS = ("y", "x", "wavelength")
#: What ``--formats`` chooses from: the ENVI cube, the Zarr cube, the colour TIFFs.
IMAGE_FORMATS = ("envi", "zarr", "tiff")
#: The TIFFs: file, photometric, extra samples, quantity, sample names.
_TIFF_LAYOUT = (
    (XYZ_TIF, "rgb", None, "CIE XYZ, D50, CIE 1931 2 degree, Y(white) = 100; "
     "photometric RGB holds X, Y, Z", ("X", "Y", "Z")),
    (LAB_TIF, "cielab", None, "CIELAB, ICC D50 white; float L* (0-100), a*, b*",
     ("L*", "a*", "b*")),
    (UNC_TIF, "minisblack", ["unspecified"], "standard uncertainty (k=1): u(L*), "
     "RMS u(reflectance)", ("u(L*)", "RMS u(reflectance)")),
)  # fmt: skip


@dataclass(frozen=True)
class ImageOutputs:
    """The output files of one session's images (picklable: sent to workers).

    Parameters
    ----------
    folder
        The output folder.
    shape
        ``(rows, cols)`` of the images.
    n_bands
        Wavelengths of the cube.
    block_rows
        Rows per block (Zarr chunk height); blocks start at multiples of it.
    offsets
        Byte offset of the pixel data in each raw-addressed file.
    cube_files
        The files the cube's rows are written to: the Zarr shard, ``cube.img``, or
        both (when they could not be one file, hard-linked).
    formats
        The formats written, a subset of :data:`IMAGE_FORMATS` (the sRGB preview
        and ``provenance.json`` always are).
    """

    folder: Path
    shape: tuple[int, int]
    n_bands: int
    block_rows: int
    offsets: dict[str, int]
    formats: tuple[str, ...] = IMAGE_FORMATS
    cube_files: tuple[str, ...] = ()

    @classmethod
    def create(
        cls,
        folder: str | PathLike[str],
        shape: tuple[int, int],
        wavelength_nm: NDArray[np.float64],
        *,
        block_rows: int,
        provenance: dict[str, Any],
        formats: Sequence[str] = IMAGE_FORMATS,
    ) -> ImageOutputs:
        """Create every output file at full size (contents to be written by blocks).

        Raises
        ------
        InputError
            An empty shape or grid, an unknown format.
        """
        rows, cols = (int(v) for v in shape)
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        if rows < 1 or cols < 1 or wl.size < 1 or block_rows < 1:
            raise InputError(f"images of {cols}x{rows} px and {wl.size} bands: empty")
        chosen = valid_formats(formats)
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        # the folder is rewritten: no longer finished until the new provenance
        (out / PROVENANCE).unlink(missing_ok=True)
        offsets: dict[str, int] = {}
        cube_files: list[str] = []
        if "envi" in chosen:
            _create_envi(out, (rows, cols), wl, provenance)
            offsets[CUBE_IMG] = 0
            cube_files.append(CUBE_IMG)
        if "zarr" in chosen:
            shard = _create_zarr(out, (rows, cols), wl, block_rows, provenance)
            offsets[shard] = 0
            if "envi" not in chosen or not _link(out / shard, out / CUBE_IMG):
                cube_files.append(shard)
        if "tiff" in chosen:
            offsets.update(_create_tiffs(out, (rows, cols), provenance))
        return cls(
            out, (rows, cols), int(wl.size), int(block_rows), offsets, chosen,
            tuple(cube_files),
        )  # fmt: skip

    def write_rows(
        self,
        row0: int,
        cube: NDArray[np.float32],
        xyz: NDArray[np.float32],
        lab: NDArray[np.float32],
        uncertainty: NDArray[np.float32] | None,
    ) -> None:
        """Write a block of rows starting at ``row0`` into every file.

        Parameters
        ----------
        cube : (r, cols, n_bands)
        xyz, lab : (r, cols, 3)
        uncertainty : (r, cols, 2), optional
            ``None`` leaves the uncertainty TIFF's rows to
            :meth:`write_uncertainty`.
        """
        _, cols, n_bands = cube.shape
        if row0 % self.block_rows or cols != self.shape[1] or n_bands != self.n_bands:
            raise InputError(
                f"block at row {row0} of shape {cube.shape} does not fit the images "
                f"{self.shape} x {self.n_bands} in blocks of {self.block_rows} rows"
            )
        # ENVI BIP: each pixel's bands in turn, rows one after the other; the Zarr
        # shard's chunks in row order hold the same bytes at the same offsets
        bip = np.ascontiguousarray(cube, dtype="<f4")
        for name in self.cube_files:
            pwrite_direct(self.folder / name, self.cube_offset(row0), bip)
        if "tiff" in self.formats:
            for name, data in ((XYZ_TIF, xyz), (LAB_TIF, lab), (UNC_TIF, uncertainty)):
                if data is not None:
                    self._write_tiff_rows(name, row0, data)

    def cube_offset(self, row0: int) -> int:
        """The byte offset of row ``row0`` in the cube files (each pixel's bands in
        turn, rows one after the other)."""
        return row0 * self.shape[1] * self.n_bands * 4

    def write_uncertainty(self, row0: int, uncertainty: NDArray[np.float32]) -> None:
        """Rows of the uncertainty TIFF (r, cols, 2) from ``row0`` (any row: the
        TIFF is one strip), when :meth:`write_rows` left them out."""
        if "tiff" in self.formats:
            self._write_tiff_rows(UNC_TIF, row0, uncertainty)

    def _write_tiff_rows(self, name: str, row0: int, data: NDArray[np.float32]) -> None:
        cols, samples = data.shape[1], data.shape[2]
        pix = np.ascontiguousarray(data, dtype="<f4")
        pwrite_direct(
            self.folder / name, self.offsets[name] + row0 * cols * samples * 4, pix
        )

    def write_preview(self, srgb: NDArray[np.uint8]) -> Path:
        """The sRGB preview (rows, cols, 3) as PNG."""
        import cv2

        path = self.folder / SRGB_PNG
        if not cv2.imwrite(str(path), np.ascontiguousarray(srgb[:, :, ::-1])):
            raise OSError(f"cannot write {path}")
        return path

    def write_provenance(self, provenance: dict[str, Any]) -> Path:
        """``provenance.json``, atomically: the folder's completion mark."""
        from tunespec.core.io.session import atomic_write_text

        path = self.folder / PROVENANCE
        atomic_write_text(path, dumps_json(provenance))
        return path


def remove_partial_outputs(folder: str | PathLike[str]) -> None:
    """Remove the image files of an unfinished folder (no ``provenance.json``), so
    that a failed run (a full disk) leaves no truncated images behind."""
    import shutil

    out = Path(folder)
    if (out / PROVENANCE).exists():
        return
    for name in (CUBE_HDR, CUBE_IMG, XYZ_TIF, LAB_TIF, UNC_TIF, SRGB_PNG):
        (out / name).unlink(missing_ok=True)
    shutil.rmtree(out / CUBE_ZARR, ignore_errors=True)


def write_array(path: str | PathLike[str], data: NDArray[Any]) -> None:
    """An array's raw bytes as a new file (a full disk raises ``ENOSPC``, where
    ``ndarray.tofile`` raises an ``OSError`` without an error number)."""
    with open(path, "wb") as fh:
        fh.write(memoryview(np.ascontiguousarray(data)).cast("B"))


def valid_formats(formats: Sequence[str] | str) -> tuple[str, ...]:
    """The image formats asked for (``"envi,zarr"`` or a sequence), checked, in the
    order of :data:`IMAGE_FORMATS`.

    Raises
    ------
    InputError
        An unknown or no format.
    """
    names = formats.split(",") if isinstance(formats, str) else list(formats)
    names = [n.strip().lower() for n in names if n.strip()]
    unknown = [n for n in names if n not in IMAGE_FORMATS]
    if unknown or not names:
        raise InputError(
            f"image formats (--formats): expected a comma-separated list of "
            f"{', '.join(IMAGE_FORMATS)}, got {','.join(names) or 'nothing'!r}"
        )
    return tuple(f for f in IMAGE_FORMATS if f in names)


def _create_envi(
    out: Path, shape: tuple[int, int], wl: NDArray[np.float64], prov: dict[str, Any]
) -> None:
    import spectral.io.envi as envi

    envi.create_image(
        str(out / CUBE_HDR),
        {
            "description": "TuneSpec per-pixel reflectance factor (Eq. 5); "
            + _header_summary(prov),
            "wavelength": [f"{v:g}" for v in wl],
            "wavelength units": "nm",
            "data ignore value": "nan",
            "band names": [f"{v:g} nm" for v in wl],
        },
        shape=(*shape, wl.size),
        dtype=np.float32,
        interleave="bip",
        byteorder=0,
        force=True,
    )


def _link(source: Path, target: Path) -> bool:
    """``target`` replaced by a hard link to ``source``; False (``target`` left as
    it is) where the file system has none: the cube is then written to both."""
    tmp = target.with_name(target.name + ".link")
    try:
        tmp.unlink(missing_ok=True)
        os.link(source, tmp)
        os.replace(tmp, target)
    except OSError:
        tmp.unlink(missing_ok=True)
        return False
    return True


def _create_zarr(
    out: Path,
    shape: tuple[int, int],
    wl: NDArray[np.float64],
    block_rows: int,
    prov: dict[str, Any],
) -> str:
    """The Zarr v3 group xarray reads as a labelled data set (dimension names in
    each array's metadata, the wavelength coordinate as an array of its own,
    consolidated metadata so ``xarray.open_zarr`` opens it without a warning).

    The cube is one shard of row-block chunks, created here at full size with its
    index (:func:`_create_shard`); returns the shard file, relative to ``out``."""
    import shutil
    import warnings

    import zarr

    path = out / CUBE_ZARR
    if path.exists():
        shutil.rmtree(path)
    rows, cols = shape
    group = zarr.open_group(
        str(path),
        mode="w",
        zarr_format=3,
        attributes={
            "title": "TuneSpec per-pixel reflectance factor",
            "source": prov.get("software", "tunespec"),
            "history": f"{prov.get('started_utc', '')} tunespec estimate-image "
            f"{prov.get('session', '')}".strip(),
            "references": "Trichromatic Reflectance Capture Using a Tunable Light "
            "Source, Eq. 5 (Wiener estimation per 2x2 Bayer superpixel)",
            "provenance": prov,
        },
    )
    n_blocks = -(-rows // block_rows)
    group.create_array(
        ZARR_CUBE,
        shape=(rows, cols, wl.size),
        # a chunk per block of rows (the order the blocks are written in), all of
        # them in one shard: the ENVI file's layout
        chunks=(block_rows, cols, wl.size),
        shards=(n_blocks * block_rows, cols, wl.size),
        dtype="float32",
        # uncompressed: lz4 + bitshuffle saved a fifth of the bytes for more CPU
        # than writing them takes, and the chunks keep the ENVI file's offsets
        compressors=None,
        fill_value=float("nan"),
        dimension_names=ZARR_DIMENSIONS,
        attributes={
            "units": "1",
            "long_name": "reflectance factor",
            "quantity": "reflectance factor (perfect diffuser = 1)",
            "wavelength_nm": wl.tolist(),
        },
    )
    coord = group.create_array(
        "wavelength",
        shape=(wl.size,),
        dtype="float64",
        dimension_names=("wavelength",),
        attributes={
            "units": "nm",
            "long_name": "wavelength",
            "standard_name": "radiation_wavelength",
        },
    )
    coord[:] = wl
    for name, n in (("y", rows), ("x", cols)):
        axis = group.create_array(
            name,
            shape=(n,),
            dtype="int32",
            dimension_names=(name,),
            attributes={
                "units": "1",
                "long_name": f"{'row' if name == 'y' else 'column'} of 2x2 Bayer "
                "superpixels (rectified: of the target plane)",
            },
        )
        axis[:] = np.arange(n, dtype=np.int32)
    with warnings.catch_warnings():
        # zarr-python's consolidated metadata, which xarray reads for v3 stores
        warnings.filterwarnings("ignore", message="Consolidated metadata")
        zarr.consolidate_metadata(str(path))
    _create_shard(path.joinpath(*ZARR_SHARD), n_blocks, block_rows * cols * wl.size * 4)
    return str(Path(CUBE_ZARR).joinpath(*ZARR_SHARD))


def _create_shard(path: Path, n_chunks: int, chunk_bytes: int) -> None:
    """The cube's shard file at full size: ``n_chunks`` chunks of ``chunk_bytes``
    in order (left as a hole, to be written by the blocks), then the shard index
    that zarr's ``sharding_indexed`` codec reads at the end: (offset, length) of
    each chunk as little-endian uint64 and the index's CRC32C (zarr's default
    index codecs ``bytes``, ``crc32c``)."""
    import google_crc32c  # zarr's own CRC32C implementation (a zarr dependency)

    starts = np.arange(n_chunks, dtype="<u8") * np.uint64(chunk_bytes)
    index = np.stack([starts, np.full(n_chunks, chunk_bytes, dtype="<u8")], axis=1)
    data = index.astype("<u8").tobytes()
    data += int(google_crc32c.value(data)).to_bytes(4, "little")
    path.parent.mkdir(parents=True, exist_ok=True)
    size = n_chunks * chunk_bytes
    with open(path, "wb") as fh:
        fh.truncate(size)
        fh.seek(size)
        fh.write(data)


def _create_tiffs(
    out: Path, shape: tuple[int, int], prov: dict[str, Any]
) -> dict[str, int]:
    """The colour TIFFs, created at full size; their pixel data offsets."""
    import tifffile

    offsets = {}
    for name, photometric, extra, what, samples in _TIFF_LAYOUT:
        kwargs: dict[str, Any] = {"extrasamples": extra} if extra else {}
        tifffile.imwrite(
            out / name,
            shape=(*shape, len(samples)),
            dtype="float32",
            photometric=photometric,
            planarconfig="contig",
            metadata={"quantity": what, "samples": list(samples), **_flat(prov)},
            **kwargs,
        )
        with tifffile.TiffFile(out / name) as tif:
            page = tif.pages[0]
            if not page.is_contiguous:  # pragma: no cover - tifffile does for this
                raise InputError("tifffile wrote a non-contiguous image", path=name)
            offsets[name] = int(page.dataoffsets[0])
    return offsets


def pwrite_all(path: str | PathLike[str], offset: int, data: NDArray[Any]) -> None:
    """Write an array's bytes at ``offset`` of an existing file (positioned I/O: any
    number of writers may fill disjoint ranges of one file at the same time)."""
    fd = os.open(path, os.O_WRONLY)
    try:
        _pwrite_view(fd, memoryview(np.ascontiguousarray(data)).cast("B"), offset)
    finally:
        os.close(fd)


#: Alignment of direct writes: file offset, length and memory address (4 KiB: the
#: logical block size of common disks and file systems, a multiple of the others).
DIRECT_ALIGN = 4096
#: Bytes per direct write (the bounce buffer's size, per thread).
DIRECT_CHUNK = 16 << 20
#: Smaller writes go through the page cache (a direct write waits for the disk).
DIRECT_MIN = 1 << 20
_BOUNCE = threading.local()


def pwrite_direct(path: str | PathLike[str], offset: int, data: NDArray[Any]) -> None:
    """:func:`pwrite_all`, with the :data:`DIRECT_ALIGN`-aligned middle of the range
    written past the page cache (``O_DIRECT``, through a page-aligned buffer of
    this thread); the unaligned head and tail, and everything where the system
    (not Linux) or the file system (tmpfs) has no direct I/O, go through the cache.

    Large outputs written once: the cache's pages would only be allocated, filled
    and written back, at a cost in system time above the disk's own, and would
    push other files out of the cache.
    """
    direct = getattr(os, "O_DIRECT", 0)
    view = memoryview(np.ascontiguousarray(data)).cast("B")
    head = -offset % DIRECT_ALIGN
    end = (offset + view.nbytes) // DIRECT_ALIGN * DIRECT_ALIGN - offset
    if not direct or end - head < DIRECT_MIN:
        pwrite_all(path, offset, data)
        return
    fd = os.open(path, os.O_WRONLY)
    try:
        _pwrite_view(fd, view[:head], offset)
        _pwrite_view(fd, view[end:], offset + end)
        try:
            dfd = os.open(path, os.O_WRONLY | direct)
        except OSError:  # no direct I/O on this file system
            _pwrite_view(fd, view[head:end], offset + head)
            return
        try:
            done = _pwrite_aligned(dfd, view[head:end], offset + head)
        finally:
            os.close(dfd)
        _pwrite_view(fd, view[head + done : end], offset + head + done)
    finally:
        os.close(fd)


def _pwrite_aligned(fd: int, view: memoryview, offset: int) -> int:
    """Write ``view`` (aligned offset and length) with ``fd`` opened ``O_DIRECT``
    through this thread's page-aligned bounce buffer; returns the bytes written
    (fewer where the file system refuses direct writes: the caller writes the
    rest through the cache)."""
    import errno
    import mmap

    # memory already aligned (a buffer placed for it, see core.scratch.scratch's
    # phase) is written as it is; else through the bounce buffer
    aligned = np.frombuffer(view, dtype=np.uint8).ctypes.data % DIRECT_ALIGN == 0
    bounce = None
    if not aligned:
        bounce = getattr(_BOUNCE, "buffer", None)
        if bounce is None:
            bounce = _BOUNCE.buffer = mmap.mmap(-1, DIRECT_CHUNK)  # page-aligned
    done = 0
    while done < view.nbytes:
        n = min(DIRECT_CHUNK, view.nbytes - done)
        if bounce is None:
            source = view[done : done + n]
        else:
            bounce[:n] = view[done : done + n]
            source = memoryview(bounce)[:n]
        try:
            got = os.pwrite(fd, source, offset + done)
        except OSError as exc:
            if exc.errno != errno.EINVAL:  # a full disk, ...: the caller's error
                raise
            return done
        if got <= 0 or got % DIRECT_ALIGN:  # short, off the alignment: rest cached
            return done + max(got, 0)
        done += got
    return done


def _pwrite_view(fd: int, view: memoryview, offset: int) -> None:
    """All of ``view`` at ``offset`` of ``fd`` (a short write, from a signal or a
    full disk, is continued)."""
    done = 0
    while done < view.nbytes:
        done += os.pwrite(fd, view[done:], offset + done)


def read_provenance(folder: str | PathLike[str]) -> dict[str, Any] | None:
    """The provenance of a finished image folder, ``None`` if it is not finished."""
    from tunespec.core.limits import read_json

    path = Path(folder) / PROVENANCE
    if not path.is_file():
        return None
    doc = read_json(path)
    return doc if isinstance(doc, dict) else None


def _header_summary(provenance: dict[str, Any]) -> str:
    """One line for the ENVI description: no braces or commas (ENVI's list syntax)."""
    keys = ("session", "calibration", "grid_nm", "software")
    text = "; ".join(f"{k}={provenance.get(k, '')}" for k in keys if k in provenance)
    return text.replace("{", "(").replace("}", ")").replace(",", " ")


def _flat(provenance: dict[str, Any]) -> dict[str, str]:
    """Provenance as string values (TIFF shaped metadata is one JSON object)."""
    return {
        f"tunespec_{k}": v if isinstance(v, str) else json.dumps(v)
        for k, v in provenance.items()
    }


@dataclass(frozen=True, eq=False)
class SpectralImage:
    """A finished image folder, opened for reading (memory-mapped, nothing loaded).

    Parameters
    ----------
    folder
        The folder.
    wavelength_nm : (n_bands,)
    cube : (rows, cols, n_bands) float32, read-only memory map (ENVI BIP)
    lab, xyz : (rows, cols, 3) float32, read-only memory maps (the TIFFs)
    uncertainty : (rows, cols, 2) float32: u(L*), RMS u(reflectance)
    provenance : dict
    """

    folder: Path
    wavelength_nm: NDArray[np.float64]
    cube: NDArray[np.float32]
    lab: NDArray[np.float32]
    xyz: NDArray[np.float32]
    uncertainty: NDArray[np.float32]
    provenance: dict[str, Any]

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.cube.shape[0]), int(self.cube.shape[1]))

    def srgb(self) -> NDArray[np.uint8]:
        """The sRGB preview, (rows, cols, 3) uint8."""
        import cv2

        img = cv2.imread(str(self.folder / SRGB_PNG), cv2.IMREAD_COLOR)
        if img is None:
            raise InputError("cannot read the preview", path=self.folder / SRGB_PNG)
        return np.ascontiguousarray(img[:, :, ::-1])

    def region(self, row0: int, row1: int, col0: int, col1: int) -> dict[str, Any]:
        """Mean and spread of a rectangle: L*a*b* (mean, std), the mean spectrum and
        its standard deviation over the pixels, the pixel count and the pixels' mean
        RMS standard uncertainty of reflectance (``u_reflectance_mean``)."""
        r0, r1 = sorted((max(0, row0), min(self.shape[0], row1)))
        c0, c1 = sorted((max(0, col0), min(self.shape[1], col1)))
        if r1 <= r0 or c1 <= c0:
            raise InputError("the region holds no pixel")
        lab = np.asarray(self.lab[r0:r1, c0:c1], dtype=np.float64).reshape(-1, 3)
        spec = np.asarray(self.cube[r0:r1, c0:c1], dtype=np.float64)
        spec = spec.reshape(-1, spec.shape[-1])
        return {
            "n_pixels": int(lab.shape[0]),
            "lab_mean": lab.mean(axis=0),
            "lab_std": lab.std(axis=0),
            "reflectance_mean": spec.mean(axis=0),
            "reflectance_std": spec.std(axis=0),
            "u_reflectance_mean": float(
                np.mean(self.uncertainty[r0:r1, c0:c1, 1], dtype=np.float64)
            ),
        }


def open_image_outputs(folder: str | PathLike[str]) -> SpectralImage:
    """Open a finished image folder (see the module notes) without loading it.

    Raises
    ------
    InputError
        The folder is not finished (no ``provenance.json``) or a file is missing.
    """
    import spectral
    import tifffile

    out = Path(folder)
    prov = read_provenance(out)
    if prov is None:
        raise InputError(
            "not a finished image folder (no provenance.json); run estimate-image",
            path=out,
        )
    try:
        if (out / CUBE_HDR).is_file():
            envi = spectral.open_image(str(out / CUBE_HDR))
            cube = envi.open_memmap(writable=False)
            wl = np.asarray(envi.bands.centers, dtype=np.float64)
        else:  # written with --formats zarr,tiff: the Zarr cube, read lazily
            import zarr

            group = zarr.open_group(str(out / CUBE_ZARR), mode="r")
            cube = group[ZARR_CUBE]
            wl = np.asarray(group["wavelength"][:], dtype=np.float64)
        maps = [tifffile.memmap(out / n, mode="r") for n in (LAB_TIF, XYZ_TIF, UNC_TIF)]
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(
            f"cannot open the images (the viewer needs the TIFFs and a cube: "
            f"estimate-image --formats with tiff and envi or zarr): {exc}",
            path=out,
        ) from None
    return SpectralImage(out, wl, cube, maps[0], maps[1], maps[2], prov)
