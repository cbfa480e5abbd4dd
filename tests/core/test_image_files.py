"""The image outputs open in other tools as what they are (issue 28): xarray reads
the Zarr cube as a labelled data set, the TIFFs carry the photometric and extra
sample tags of what they hold (tifffile's tag reading, and libtiff's tiffinfo where
installed)."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.io.image_formats import ImageOutputs, open_image_outputs

ROWS, COLS = 9, 7
WL = np.arange(400.0, 440.0, 5.0)
PROV = {"session": "/data/s1", "software": "tunespec 0.test", "started_utc": "T0"}


def _write(folder, formats=("envi", "zarr", "tiff")):
    rng = np.random.default_rng(8)
    cube = rng.uniform(0, 1, (ROWS, COLS, WL.size)).astype(np.float32)
    xyz = rng.uniform(0, 100, (ROWS, COLS, 3)).astype(np.float32)
    lab = rng.uniform(-50, 100, (ROWS, COLS, 3)).astype(np.float32)
    unc = rng.uniform(0, 1, (ROWS, COLS, 2)).astype(np.float32)
    out = ImageOutputs.create(folder, (ROWS, COLS), WL, block_rows=4,
                              provenance=PROV, formats=formats)  # fmt: skip
    for r0 in (0, 4, 8):
        sl = slice(r0, r0 + 4)
        out.write_rows(r0, cube[sl], xyz[sl], lab[sl], unc[sl])
    out.write_provenance(PROV)
    return cube, xyz, lab, unc


def test_xarray_opens_the_zarr_cube_labelled(tmp_path) -> None:
    import xarray as xr

    cube, *_ = _write(tmp_path / "img")
    ds = xr.open_zarr(tmp_path / "img" / "cube.zarr")
    da = ds["reflectance"]
    assert da.dims == ("y", "x", "wavelength")
    np.testing.assert_array_equal(da["wavelength"].values, WL)
    assert da["wavelength"].attrs["units"] == "nm"
    assert da.attrs["units"] == "1" and da.attrs["long_name"] == "reflectance factor"
    np.testing.assert_array_equal(da.values, cube)
    # label-based selection works: the 420 nm band
    np.testing.assert_array_equal(da.sel(wavelength=420.0).values, cube[:, :, 4])
    assert ds.attrs["provenance"]["session"] == "/data/s1"
    assert "estimate-image" in ds.attrs["history"]
    np.testing.assert_array_equal(ds["y"].values, np.arange(ROWS))


def test_tiff_tags_say_what_the_images_hold(tmp_path) -> None:
    import json

    import tifffile

    _, xyz, lab, unc = _write(tmp_path / "img")
    want = {
        "xyz.tif": (2, (), ["X", "Y", "Z"], xyz),  # RGB: three colour samples
        "lab.tif": (8, (), ["L*", "a*", "b*"], lab),  # CIELab
        "uncertainty.tif": (1, (0,), ["u(L*)", "RMS u(reflectance)"], unc),
    }
    for name, (photometric, extra, samples, data) in want.items():
        with tifffile.TiffFile(tmp_path / "img" / name) as tif:
            page = tif.pages[0]
            tags = page.tags
            assert tags["PhotometricInterpretation"].value == photometric, name
            assert tuple(int(v) for v in page.extrasamples) == extra, name
            assert tags["SampleFormat"].value in (3, (3,) * page.samplesperpixel)
            assert tags["BitsPerSample"].value in (32, (32,) * page.samplesperpixel)
            doc = json.loads(page.description)
            assert doc["samples"] == samples
            np.testing.assert_array_equal(page.asarray(), data)


@pytest.mark.skipif(shutil.which("tiffinfo") is None, reason="libtiff-tools absent")
def test_tiffinfo_reads_the_photometrics(tmp_path) -> None:
    _write(tmp_path / "img")
    text = {
        n: subprocess.run(
            ["tiffinfo", str(tmp_path / "img" / n)], capture_output=True, text=True
        ).stdout
        for n in ("xyz.tif", "lab.tif", "uncertainty.tif")
    }
    assert "Photometric Interpretation: RGB color" in text["xyz.tif"]
    assert "Photometric Interpretation: CIE L*a*b*" in text["lab.tif"]
    assert "Photometric Interpretation: min-is-black" in text["uncertainty.tif"]
    assert "Extra Samples: 1<unspecified>" in text["uncertainty.tif"]
    assert "Sample Format: IEEE floating point" in text["lab.tif"]


def test_formats_choose_the_files(tmp_path) -> None:
    cube, *_ = _write(tmp_path / "z", formats=("zarr", "tiff"))
    names = {p.name for p in (tmp_path / "z").iterdir()}
    assert "cube.hdr" not in names and "cube.img" not in names
    assert {"cube.zarr", "xyz.tif", "lab.tif", "uncertainty.tif"} <= names
    img = open_image_outputs(tmp_path / "z")  # the Zarr cube stands in for ENVI
    np.testing.assert_array_equal(np.asarray(img.cube[2:5, 1:3]), cube[2:5, 1:3])
    np.testing.assert_array_equal(img.wavelength_nm, WL)
    _write(tmp_path / "e", formats=("envi",))
    assert {p.name for p in (tmp_path / "e").iterdir()} == {
        "cube.hdr", "cube.img", "provenance.json",
    }  # fmt: skip
    with pytest.raises(InputError, match="--formats"):
        open_image_outputs(tmp_path / "e")
    with pytest.raises(InputError, match=r"formats \(--formats\): expected"):
        ImageOutputs.create(tmp_path / "x", (2, 2), WL, block_rows=1,
                            provenance={}, formats=("envi", "hdf5"))  # fmt: skip


def test_zarr_shard_is_what_zarr_writes_and_the_envi_file(tmp_path) -> None:
    """The cube's Zarr shard (row-block chunks in order, then the index), written
    by blocks at their offsets, holds the bytes zarr-python writes for the same
    array (but for the last chunk's padding beyond the image, a hole here, NaN
    there), and with ENVI too, cube.img is that file (one write of the cube)."""
    import os

    import spectral
    import zarr

    rng = np.random.default_rng(3)
    rows, cols, wl = 5, 1030, WL[:3]  # the last block holds 1 of 2 rows
    cube = rng.uniform(0, 1, (rows, cols, wl.size)).astype(np.float32)
    out = ImageOutputs.create(tmp_path / "ours", (rows, cols), wl, block_rows=2,
                              provenance=PROV, formats=("envi", "zarr"))  # fmt: skip
    for r0 in (4, 0, 2):
        sl = slice(r0, r0 + 2)
        out.write_rows(r0, cube[sl], cube[sl, :, :3], cube[sl, :, :3], cube[sl, :, :2])
    ours = zarr.open_group(str(tmp_path / "ours" / "cube.zarr"), mode="r")
    np.testing.assert_array_equal(ours["reflectance"][:], cube)
    ref = zarr.open_array(str(tmp_path / "ours" / "cube.zarr" / "reflectance"))
    assert ref.chunks == (2, cols, wl.size)  # the order the blocks are written in
    assert ref.shards == (6, cols, wl.size)
    theirs = zarr.create_array(
        store=str(tmp_path / "theirs.zarr"), shape=ref.shape, chunks=ref.chunks,
        shards=ref.shards, dtype="float32", compressors=None,
        fill_value=float("nan"),
    )  # fmt: skip
    theirs[:] = cube
    shard = ("c", "0", "0", "0")
    mine = (tmp_path / "ours" / "cube.zarr" / "reflectance").joinpath(*shard)
    want = (tmp_path / "theirs.zarr").joinpath(*shard).read_bytes()
    got = mine.read_bytes()
    image = rows * cols * wl.size * 4
    assert len(got) == len(want)
    assert got[:image] == want[:image]  # the image's rows
    assert got[-(3 * 16 + 4) :] == want[-(3 * 16 + 4) :]  # the index and its CRC32C
    # the ENVI cube is the shard file: the header's rows from offset 0
    assert os.path.samefile(tmp_path / "ours" / "cube.img", mine)
    envi = spectral.open_image(str(tmp_path / "ours" / "cube.hdr"))
    np.testing.assert_array_equal(envi.open_memmap(), cube)


def test_without_hard_links_the_cube_is_written_to_both(tmp_path, monkeypatch) -> None:
    import os

    import spectral
    import xarray as xr

    link = os.link

    def no_link(src, dst, **kwargs):  # the cube's link fails (zarr's own do not)
        if os.path.basename(dst).startswith("cube.img"):
            raise OSError("no hard links here")
        link(src, dst, **kwargs)

    monkeypatch.setattr(os, "link", no_link)
    cube, *_ = _write(tmp_path / "img")
    folder = tmp_path / "img"
    assert (folder / "cube.img").stat().st_nlink == 1
    assert not list(folder.glob("*.link"))
    envi = spectral.open_image(str(folder / "cube.hdr"))
    np.testing.assert_array_equal(envi.open_memmap(), cube)
    da = xr.open_zarr(folder / "cube.zarr")["reflectance"]
    np.testing.assert_array_equal(da.values, cube)


@pytest.mark.parametrize("how", ["direct", "no direct open", "direct write refused"])
def test_cube_rows_written_past_the_cache_read_back(tmp_path, monkeypatch, how) -> None:
    """Blocks of 5 MB at offsets off the 4 KiB alignment: the aligned middle goes
    to the disk directly (O_DIRECT), head and tail through the cache, and where the
    file system has no direct I/O (at open or at the write) all of it cached."""
    import errno
    import os

    import spectral
    import zarr

    import tunespec.core.io.image_formats as fmt

    direct = getattr(os, "O_DIRECT", 0)
    opened, real_open, real_pwrite = [], os.open, os.pwrite

    def watch_open(path, flags, *args, **kwargs):
        if flags & direct:
            opened.append(path)
            if how == "no direct open":
                raise OSError(errno.EINVAL, "no direct I/O here")
        return real_open(path, flags, *args, **kwargs)

    def refuse(fd, data, offset):
        if how == "direct write refused" and _is_direct(fd):
            raise OSError(errno.EINVAL, "Invalid argument")
        return real_pwrite(fd, data, offset)

    def _is_direct(fd):
        import fcntl

        return bool(fcntl.fcntl(fd, fcntl.F_GETFL) & direct)

    monkeypatch.setattr(os, "open", watch_open)
    monkeypatch.setattr(os, "pwrite", refuse)
    rng = np.random.default_rng(5)
    rows, cols, wl = 45, 1030, np.arange(400.0, 705.0, 5.0)  # 5 MB per 20 rows
    cube = rng.uniform(0, 1, (rows, cols, wl.size)).astype(np.float32)
    assert (20 * cols * wl.size * 4) % fmt.DIRECT_ALIGN  # offsets off the alignment
    out = ImageOutputs.create(tmp_path / "d", (rows, cols), wl, block_rows=20,
                              provenance=PROV, formats=("envi", "zarr"))  # fmt: skip
    for r0 in (40, 0, 20):
        sl = slice(r0, r0 + 20)
        out.write_rows(r0, cube[sl], cube[sl, :, :3], cube[sl, :, :3], None)
    envi = spectral.open_image(str(tmp_path / "d" / "cube.hdr"))
    np.testing.assert_array_equal(envi.open_memmap(), cube)
    z = zarr.open_array(str(tmp_path / "d" / "cube.zarr" / "reflectance"), mode="r")
    np.testing.assert_array_equal(z[:], cube)
    if direct:  # Linux: the two full blocks' middles were sent direct
        assert len(opened) >= 2


def test_formats_option_is_checked_by_the_parser(capsys) -> None:
    from tunespec.app.cli import build_parser

    parser = build_parser()
    argv = ["estimate-image", "s", "--sensitivities", "S.csv", "-o", "d"]
    assert parser.parse_args(argv).formats == ("envi", "zarr", "tiff")
    assert parser.parse_args([*argv, "--formats", "TIFF,zarr"]).formats == (
        "zarr", "tiff",
    )  # fmt: skip
    with pytest.raises(SystemExit) as exc:
        parser.parse_args([*argv, "--formats", "envi,hdf5"])
    assert exc.value.code == 2
    assert "expected a comma-separated list of envi, zarr, tiff" in (
        capsys.readouterr().err
    )
