"""core.io.raw: decoding real raw files and the plane arithmetic."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.io.raw import (
    RawFrame,
    full_to_plane_px,
    load_raw,
    plane_to_full_px,
    quad_mask,
)

DATA = Path(__file__).resolve().parents[1] / "data"
TINYDNG = DATA / "tinydng_colorchart.dng"
LOSSY = DATA / "keeppix_canon5dmk3_lossy.dng"

#: float32 planes against float64 arithmetic on 14-bit values
ATOL_FLOAT32 = 1e-6


def _frame(mosaic: np.ndarray, pattern: str = "RGGB", black=(0.0, 0.0, 0.0, 0.0),
           white: float = 100.0) -> RawFrame:  # fmt: skip
    return RawFrame(
        path=Path("synthetic"),
        mosaic=np.asarray(mosaic, dtype=np.uint16),
        cfa_pattern=pattern,
        black_level_cfa=np.asarray(black, dtype=float).reshape(2, 2),
        white_level=white,
    )


# -- real files --------------------------------------------------------------------
def test_tinydng_levels_pattern_and_metadata() -> None:
    f = load_raw(TINYDNG)
    # frozen values: shared/data/raw-samples/SOURCE.md (rawpy 0.28, LibRaw 0.22)
    assert f.cfa_pattern == "RGGB"
    np.testing.assert_array_equal(f.black_level_cfa, np.full((2, 2), 2056.0))
    assert f.black_level == 2056.0
    assert f.white_level == 15000.0
    assert f.mosaic.shape == (1156, 1734) and f.mosaic.dtype == np.uint16
    assert f.shape == (578, 867)
    assert (f.make, f.model) == ("Canon", "Canon EOS Kiss X4")
    assert f.camera == "Canon EOS Kiss X4"
    # the visible area starts after LibRaw's margins (left 152, top 26)
    assert f.mosaic[0, :4].tolist() == [2056, 2093, 2080, 2077]


def test_tinydng_planes_match_direct_arithmetic() -> None:
    f = load_raw(TINYDNG)
    p = f.planes
    assert p.shape == (3, 578, 867) and p.dtype == np.float32
    m = f.mosaic.astype(np.float64)
    scale = 15000.0 - 2056.0
    r = (m[0::2, 0::2] - 2056.0) / scale
    g = ((m[0::2, 1::2] - 2056.0) + (m[1::2, 0::2] - 2056.0)) / (2 * scale)
    b = (m[1::2, 1::2] - 2056.0) / scale
    np.testing.assert_allclose(p[0], r, atol=ATOL_FLOAT32)
    np.testing.assert_allclose(p[1], g, atol=ATOL_FLOAT32)
    np.testing.assert_allclose(p[2], b, atol=ATOL_FLOAT32)
    # frozen: plane means of this file (dim scene, far below white)
    np.testing.assert_allclose(
        p.mean(axis=(1, 2)), [0.0259008, 0.0559971, 0.0407317], atol=1e-6
    )
    assert not f.saturated.any()


def test_lossy_linear_dng_is_not_bayer() -> None:
    with pytest.raises(InputError, match="not a Bayer") as err:
        load_raw(LOSSY)
    assert str(LOSSY) in str(err.value)


def test_missing_and_garbage_files_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found") as err:
        load_raw(tmp_path / "nope.cr2")
    assert "nope.cr2" in str(err.value)
    bad = tmp_path / "bad.cr2"
    bad.write_bytes(b"this is not a raw file" * 10)
    with pytest.raises(InputError, match=r"bad\.cr2"):
        load_raw(bad)
    truncated = tmp_path / "cut.dng"
    truncated.write_bytes(TINYDNG.read_bytes()[:4096])
    with pytest.raises(InputError, match=r"cut\.dng"):
        load_raw(truncated)


# -- plane arithmetic on synthetic frames -------------------------------------------
@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_planes_follow_the_cfa_pattern(pattern: str) -> None:
    value = {"R": 10, "G": 50, "B": 90}
    cell = np.array([value[c] for c in pattern]).reshape(2, 2)
    mosaic = np.tile(cell, (3, 4))
    f = _frame(mosaic, pattern, black=(0, 0, 0, 0), white=100)
    np.testing.assert_allclose(f.planes[:, 0, 0], [0.1, 0.5, 0.9], atol=ATOL_FLOAT32)
    assert f.planes.shape == (3, 3, 4)


def test_per_site_black_levels_and_green_mean() -> None:
    # G1 at black 4, G2 at black 6: each normalised with its own black
    mosaic = np.tile(np.array([[24, 54], [56, 84]]), (2, 2))
    f = _frame(mosaic, "RGGB", black=(4, 4, 6, 4), white=104)
    g = 0.5 * (50 / 100 + 50 / 98)
    np.testing.assert_allclose(f.planes[:, 0, 0], [0.2, g, 0.8], atol=ATOL_FLOAT32)
    assert f.black_level == pytest.approx(4.5)


@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG"])
def test_planes_minus_is_planes_less_the_dark(pattern: str, monkeypatch) -> None:
    import tunespec.core.io.raw as raw_mod

    monkeypatch.setattr(raw_mod, "_STRIP_BYTES", 8 * 30 * 3)  # strips of 3 rows
    rng = np.random.default_rng(1)
    f = _frame(rng.integers(0, 1000, (23, 61)), pattern, black=(4, 6, 5, 7),
               white=1000)  # fmt: skip
    dark = rng.uniform(-0.01, 0.02, f.planes.shape).astype(np.float32)
    out = np.full(f.planes.shape, np.nan, dtype=np.float32)
    got = f.planes_minus(dark, out=out)
    assert got is out and got.shape == (3, 11, 30)
    np.testing.assert_allclose(got, f.planes - dark, rtol=0, atol=ATOL_FLOAT32)
    with pytest.raises(ValueError, match="dark"):
        f.planes_minus(dark[:, 1:])


def test_saturated_when_any_photosite_reaches_white() -> None:
    mosaic = np.full((4, 6), 50, dtype=np.uint16)
    mosaic[1, 2] = 100  # G2 of cell (0, 1) at the white level
    mosaic[3, 5] = 99  # just below
    f = _frame(mosaic, white=100)
    expected = np.zeros((2, 3), dtype=bool)
    expected[0, 1] = True
    np.testing.assert_array_equal(f.saturated, expected)


def test_odd_sized_mosaic_is_cropped_to_whole_cells() -> None:
    f = _frame(np.zeros((5, 7)))
    assert f.planes.shape == (3, 2, 3)


def test_planes_in_window_equals_slice_of_planes() -> None:
    rng = np.random.default_rng(0)
    f = _frame(rng.integers(0, 100, (40, 60)), black=(1, 2, 3, 4))
    np.testing.assert_array_equal(f.planes_in(3, 11, 5, 20), f.planes[:, 3:11, 5:20])
    np.testing.assert_array_equal(f.saturated_in(0, 20, 0, 30), f.saturated)
    with pytest.raises(InputError, match="empty window"):
        f.planes_in(5, 5, 0, 10)


def test_roi_stats_match_masked_planes() -> None:
    rng = np.random.default_rng(1)
    f = _frame(rng.integers(0, 101, (60, 80)), white=100)
    quad = np.array([[5.2, 4.1], [20.7, 6.0], [19.5, 18.3], [4.4, 17.0]])
    stats = f.roi_stats(quad)
    mask = quad_mask(quad, 0, 0, 40, 30)
    vals = f.planes[:, mask].astype(np.float64)
    np.testing.assert_allclose(stats.mean[0], vals.mean(axis=1), atol=1e-12)
    np.testing.assert_allclose(stats.std[0], vals.std(axis=1, ddof=1), atol=1e-12)
    assert stats.n_pixels[0] == mask.sum()
    assert stats.n_saturated[0] == f.saturated[mask].sum()
    # reversed winding, and a quad outside the frame
    both = f.roi_stats(np.stack([quad[::-1], quad + 1000]))
    np.testing.assert_allclose(both.mean[0], stats.mean[0], atol=1e-12)
    assert both.n_pixels[1] == 0 and np.all(np.isnan(both.mean[1]))
    with pytest.raises(InputError, match="ROI quads"):
        f.roi_stats(np.zeros((2, 3, 2)))


def test_quad_mask_and_coordinate_round_trip() -> None:
    square = [[1.0, 1.0], [3.0, 1.0], [3.0, 3.0], [1.0, 3.0]]
    m = quad_mask(square, 0, 0, 5, 5)
    assert m.sum() == 9 and m[1:4, 1:4].all()
    xy = np.array([[0.5, 0.5], [101.5, 37.5]])
    np.testing.assert_allclose(plane_to_full_px(full_to_plane_px(xy)), xy)
    np.testing.assert_allclose(full_to_plane_px(xy), [[0, 0], [50.5, 18.5]])


def test_a_frame_whose_exif_disagrees_with_its_record_is_refused() -> None:
    """The image stages read their frames themselves: a raw file exposed otherwise
    than its session records is refused there as processing refuses it."""
    from types import SimpleNamespace

    from tunespec.app.pipeline.image_session import _Frame, _planes
    from tunespec.core.errors import InputError
    from tunespec.core.io.raw import load_raw

    job = SimpleNamespace(plane_shape=load_raw(TINYDNG).shape)  # 1 s, no ISO
    planes, _ = _planes(job, _Frame(str(TINYDNG), 1.0, 100))
    assert planes.shape == (3, *job.plane_shape)
    with pytest.raises(InputError, match=r"exposed 1 s where the session records 2 s"):
        _planes(job, _Frame(str(TINYDNG), 2.0, 100))
    _planes(job, _Frame(str(TINYDNG), 1.05, 400))  # within 10 %; no ISO to compare


@pytest.mark.parametrize(
    ("written", "read"),
    [(8.0, 8.0), (5.6, 5.6), (0.5, 0.5), (128.0, 128.0), (200.0, None), (0.3, None),
     (None, None)],
)  # fmt: skip
def test_an_f_number_outside_the_plausible_range_is_taken_as_none(
    tmp_path: Path, written: float | None, read: float | None
) -> None:
    """The lens's f-number as the raw file's EXIF FNumber states it; outside
    0.5-128 (a corrupt tag, or 0 for a lens without contacts) it is not one."""
    from tunespec.devices.dng import write_dng

    path = tmp_path / "f.dng"
    write_dng(
        path, np.full((64, 64), 3000, np.uint16), exposure_s=0.01, f_number=written
    )
    aperture = load_raw(path).aperture
    assert aperture == (None if read is None else pytest.approx(read, rel=1e-6))
