"""Image outputs of the per-pixel estimation, each in a format its users already read.

One folder per session (:class:`ImageOutputs`)::

    cube.hdr, cube.img   ENVI, float32, band-interleaved by pixel, wavelengths in nm
                         (Spectral Python ``spectral.open_image``, ENVI, GDAL)
    cube.zarr/           the same cube as a chunked Zarr array (rows, cols, bands),
                         attribute ``wavelength_nm``; for big data and parallel writes
    xyz.tif, lab.tif     CIE XYZ (D50, Y of the white 100) and CIELAB (ICC D50 white),
                         float32 (rows, cols, 3) TIFFs (tifffile)
    uncertainty.tif      float32 (rows, cols, 2): u(L*) and the RMS over wavelength of
                         the spectrum's standard uncertainty (k = 1)
    srgb.png             8-bit sRGB preview
    provenance.json      session, calibration, grid, noise model, software version;
                         written last, so its presence means the folder is complete

The big files are created at their full size first and then filled by blocks of
rows, each written at its own offset (:meth:`ImageOutputs.write_rows`), so any
number of processes can write disjoint row blocks at the same time and memory
stays that of a block. The Zarr chunks are whole row blocks for the same reason.

References
----------
ENVI header format: NV5 Geospatial, "ENVI Header Files" (ENVI 5.6 documentation).
Zarr storage specification v3 (zarr-specs, 2023). TIFF 6.0 (Adobe, 1992).
"""

from __future__ import annotations

import json
import os
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
    "PROVENANCE",
    "ImageOutputs",
    "SpectralImage",
    "open_image_outputs",
    "pwrite_all",
    "read_provenance",
    "remove_partial_outputs",
    "write_array",
]

CUBE_HDR = "cube.hdr"
CUBE_IMG = "cube.img"
CUBE_ZARR = "cube.zarr"
XYZ_TIF = "xyz.tif"
LAB_TIF = "lab.tif"
UNC_TIF = "uncertainty.tif"
SRGB_PNG = "srgb.png"
PROVENANCE = "provenance.json"
#: Columns of a Zarr chunk (rows are the block height).
ZARR_CHUNK_COLS = 512


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
    """

    folder: Path
    shape: tuple[int, int]
    n_bands: int
    block_rows: int
    offsets: dict[str, int]

    @classmethod
    def create(
        cls,
        folder: str | PathLike[str],
        shape: tuple[int, int],
        wavelength_nm: NDArray[np.float64],
        *,
        block_rows: int,
        provenance: dict[str, Any],
    ) -> ImageOutputs:
        """Create every output file at full size (contents to be written by blocks).

        Raises
        ------
        InputError
            An empty shape or grid.
        """
        import spectral.io.envi as envi
        import tifffile
        import zarr
        from zarr.codecs import BloscCodec

        rows, cols = (int(v) for v in shape)
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        if rows < 1 or cols < 1 or wl.size < 1 or block_rows < 1:
            raise InputError(f"images of {cols}x{rows} px and {wl.size} bands: empty")
        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        # the folder is rewritten: no longer finished until the new provenance
        (out / PROVENANCE).unlink(missing_ok=True)
        summary = _header_summary(provenance)
        envi.create_image(
            str(out / CUBE_HDR),
            {
                "description": "TuneSpec per-pixel reflectance factor (Eq. 5); "
                + summary,
                "wavelength": [f"{v:g}" for v in wl],
                "wavelength units": "nm",
                "data ignore value": "nan",
                "band names": [f"{v:g} nm" for v in wl],
            },
            shape=(rows, cols, wl.size),
            dtype=np.float32,
            interleave="bip",
            byteorder=0,
            force=True,
        )
        zarr.create_array(
            store=str(out / CUBE_ZARR),
            shape=(rows, cols, wl.size),
            chunks=(block_rows, min(cols, ZARR_CHUNK_COLS), wl.size),
            dtype="float32",
            compressors=BloscCodec(cname="lz4", clevel=5, shuffle="bitshuffle"),
            fill_value=float("nan"),
            attributes={
                "wavelength_nm": wl.tolist(),
                "dimensions": ["row", "col", "wavelength"],
                "quantity": "reflectance factor",
                "provenance": provenance,
            },
            overwrite=True,
        )
        offsets = {}
        for name, samples, what in (
            (XYZ_TIF, 3, "CIE XYZ, D50, CIE 1931 2 degree, Y(white) = 100"),
            (LAB_TIF, 3, "CIELAB, ICC D50 white"),
            (UNC_TIF, 2, "standard uncertainty (k=1): u(L*), RMS u(reflectance)"),
        ):
            tifffile.imwrite(
                out / name,
                shape=(rows, cols, samples),
                dtype="float32",
                photometric="minisblack",
                planarconfig="contig",
                metadata={"quantity": what, **_flat(provenance)},
            )
            with tifffile.TiffFile(out / name) as tif:
                page = tif.pages[0]
                if not page.is_contiguous:  # pragma: no cover - tifffile does for this
                    raise InputError("tifffile wrote a non-contiguous image", path=name)
                offsets[name] = int(page.dataoffsets[0])
        offsets[CUBE_IMG] = 0
        return cls(out, (rows, cols), int(wl.size), int(block_rows), offsets)

    def write_rows(
        self,
        row0: int,
        cube: NDArray[np.float32],
        xyz: NDArray[np.float32],
        lab: NDArray[np.float32],
        uncertainty: NDArray[np.float32],
    ) -> None:
        """Write a block of rows starting at ``row0`` into every file.

        Parameters
        ----------
        cube : (r, cols, n_bands)
        xyz, lab : (r, cols, 3)
        uncertainty : (r, cols, 2)
        """
        import zarr

        r, cols, n_bands = cube.shape
        if row0 % self.block_rows or cols != self.shape[1] or n_bands != self.n_bands:
            raise InputError(
                f"block at row {row0} of shape {cube.shape} does not fit the images "
                f"{self.shape} x {self.n_bands} in blocks of {self.block_rows} rows"
            )
        # ENVI BIP: each pixel's bands in turn, rows one after the other
        bip = np.ascontiguousarray(cube, dtype="<f4")
        self._pwrite(CUBE_IMG, row0 * n_bands * cols * 4, bip)
        arr = zarr.open_array(str(self.folder / CUBE_ZARR), mode="r+")
        arr[row0 : row0 + r] = bip
        for name, data in ((XYZ_TIF, xyz), (LAB_TIF, lab), (UNC_TIF, uncertainty)):
            samples = data.shape[2]
            pix = np.ascontiguousarray(data, dtype="<f4")
            self._pwrite(name, self.offsets[name] + row0 * cols * samples * 4, pix)

    def _pwrite(self, name: str, offset: int, data: NDArray[Any]) -> None:
        pwrite_all(self.folder / name, offset, data)

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


def pwrite_all(path: str | PathLike[str], offset: int, data: NDArray[Any]) -> None:
    """Write an array's bytes at ``offset`` of an existing file (positioned I/O: any
    number of writers may fill disjoint ranges of one file at the same time)."""
    fd = os.open(path, os.O_WRONLY)
    try:
        view = memoryview(np.ascontiguousarray(data)).cast("B")
        done = 0
        while done < view.nbytes:
            done += os.pwrite(fd, view[done:], offset + done)
    finally:
        os.close(fd)


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
        its standard deviation over the pixels, and the pixel count."""
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
        envi = spectral.open_image(str(out / CUBE_HDR))
        cube = envi.open_memmap(writable=False)
        wl = np.asarray(envi.bands.centers, dtype=np.float64)
        maps = [tifffile.memmap(out / n, mode="r") for n in (LAB_TIF, XYZ_TIF, UNC_TIF)]
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot open the images: {exc}", path=out) from None
    return SpectralImage(out, wl, cube, maps[0], maps[1], maps[2], prov)
