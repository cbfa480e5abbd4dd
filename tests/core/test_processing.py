"""Processing a session: dark frames, flat field (Eq. 2), ROIs, brackets, flags.

The frames are rendered here from a known scene (patch responses, an uneven light
field, a fixed-pattern dark signal) as uint16 mosaics, stored as ``.npy`` "raw" files
and read back through :class:`tunespec.core.io.raw.RawFrame`, so the expected responses
are known exactly: ``A' = mean(A_B[centre]) A / A_B`` of a patch is its response times
the light field's mean over the centre window.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tunespec.app.pipeline.processing import process_session, write_processed
from tunespec.core.errors import InputError
from tunespec.core.io.raw import RawFrame
from tunespec.core.io.responses_csv import read_responses_csv
from tunespec.core.io.session import CaptureSettings, Session
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.layout import TargetLayout, apply_homography, homography_from_corners
from tunespec.core.processing import (
    ProcessedSession,
    RoiSet,
    find_session_corners,
    flat_window,
)
from tunespec.core.progress import Cancelled
from tunespec.core.spectra import Spectra

#: Responses of noise-free frames go through uint16 quantisation (1 DN of ~13000).
ATOL_QUANTISED = 2e-4
#: Auto-detected corners land within this of the true ones on a clean rendering.
ATOL_CORNER_PX = 0.5

BLACK_DN = 2048.0
WHITE_DN = 15000.0
SHAPE = (320, 480)  # mosaic H, W
CORNERS = np.array([[70.0, 52.0], [410.0, 64.0], [398.0, 270.0], [82.0, 258.0]])
WHITE_REFLECTANCE = 0.9
MARGIN_REFLECTANCE = 0.05


def _layout() -> TargetLayout:
    return TargetLayout(
        name="test 3x4",
        rows=3,
        cols=4,
        width_mm=100.0,
        height_mm=75.0,
        margin_mm=(6.0, 6.0, 6.0, 6.0),
        patch_fraction=0.85,
        roi_fraction=0.2,
        patch_names=tuple(f"P{i}" for i in range(12)),
    )


def _light_field(xy: np.ndarray) -> np.ndarray:
    """Relative irradiance, 1 at the image centre, ~12 % less at the corners."""
    h, w = SHAPE
    r2 = ((xy[..., 0] - w / 2) / (w / 2)) ** 2 + ((xy[..., 1] - h / 2) / (h / 2)) ** 2
    return 1.0 - 0.06 * r2


def _patch_rgb() -> np.ndarray:
    """Reflectance-like factor per patch and channel, (12, 3)."""
    rng = np.random.default_rng(5)
    return 0.05 + 0.8 * rng.random((12, 3))


def _render(
    kind: str,
    gain_rgb: np.ndarray,
    *,
    patch_rgb: np.ndarray,
    dark_dn: np.ndarray,
    corners: np.ndarray = CORNERS,
) -> np.ndarray:
    """A uint16 RGGB mosaic of the white background, the target or darkness."""
    h, w = SHAPE
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    xy = np.stack([xx, yy], axis=-1)
    chan = np.array([[0, 1], [1, 2]])[np.arange(h)[:, None] % 2, np.arange(w)[None] % 2]
    if kind == "dark":
        signal = np.zeros(SHAPE)
    else:
        refl = np.full((h, w, 3), WHITE_REFLECTANCE)
        if kind == "target":
            lay = _layout()
            H_inv = np.linalg.inv(
                homography_from_corners(lay.outer_corners_mm(), corners)
            )
            mm = apply_homography(H_inv, xy)
            inside = (
                (mm[..., 0] >= 0)
                & (mm[..., 0] <= lay.width_mm)
                & (mm[..., 1] >= 0)
                & (mm[..., 1] <= lay.height_mm)
            )
            refl[inside] = MARGIN_REFLECTANCE
            quads = lay.patch_quads_mm(1.0)
            for i, q in enumerate(quads):
                m = (
                    (mm[..., 0] >= q[0, 0])
                    & (mm[..., 0] <= q[1, 0])
                    & (mm[..., 1] >= q[0, 1])
                    & (mm[..., 1] <= q[2, 1])
                )
                refl[m] = patch_rgb[i]
        sig = refl * gain_rgb[None, None, :] * _light_field(xy)[..., None]
        signal = np.take_along_axis(sig, chan[..., None], axis=-1)[..., 0]
    dn = BLACK_DN + dark_dn + signal * (WHITE_DN - BLACK_DN)
    return np.clip(np.round(dn), 0, 65535).astype(np.uint16)


def _npy_loader(path: Path) -> RawFrame:
    return RawFrame(path, np.load(path), "RGGB", np.full((2, 2), BLACK_DN), WHITE_DN)


def _spd(scale: float) -> Spectra:
    wl = np.arange(380.0, 781.0, 5.0)
    return Spectra(wl, scale * np.exp(-(((wl - 550) / 80) ** 2))[None], ("measured",))


GAINS = {"L1": np.array([0.5, 0.7, 0.3]), "WHITE": np.array([0.8, 0.9, 0.85])}


def _make_session(
    root: Path,
    *,
    patch_rgb: np.ndarray | None = None,
    gains: dict[str, np.ndarray] = GAINS,
    brackets: tuple[float, ...] = (1.0,),
    skip: tuple[str, ...] = (),
    with_corners: bool = False,
) -> tuple[Session, np.ndarray]:
    patch_rgb = _patch_rgb() if patch_rgb is None else patch_rgb
    exposures = {c: tuple(0.5 * f for f in brackets) for c in gains}
    settings = CaptureSettings(
        tuple(gains),
        exposure_mode="fixed",
        exposures_s=exposures,
        bracket_factors=brackets,
    )
    layout = _layout().with_corners(CORNERS) if with_corners else _layout()
    session = Session.create(root, settings=settings, layout=layout)
    rng = np.random.default_rng(0)
    dark_dn = rng.uniform(0, 30, SHAPE)  # fixed-pattern dark signal
    for spec in session.plan():
        if spec.id in skip:
            continue
        if spec.kind == "dark":
            mosaic = _render("dark", np.zeros(3), patch_rgb=patch_rgb, dark_dn=dark_dn)
        else:
            gain = gains[spec.channel] * spec.exposure_s / 0.5
            mosaic = _render(spec.kind, gain, patch_rgb=patch_rgb, dark_dn=dark_dn)
        stem = session.temp_stem(spec.id)
        np.save(stem.with_suffix(".npy"), mosaic)
        spd = None if spec.kind == "dark" else _spd(2.0)
        session.commit_frame(spec, stem.with_suffix(".npy"), spd=spd)
    return session, patch_rgb


def _centre_mean_field() -> float:
    """Mean light field over the 100 x 100 plane-pixel centre window, per channel."""
    h2, w2 = SHAPE[0] // 2, SHAPE[1] // 2
    r0, c0 = (h2 - 100) // 2, (w2 - 100) // 2
    rows = np.arange(r0, r0 + 100) * 2 + 0.5
    cols = np.arange(c0, c0 + 100) * 2 + 0.5
    yy, xx = np.meshgrid(rows, cols, indexing="ij")
    return float(_light_field(np.stack([xx, yy], -1)).mean())


def _expected(patch_rgb: np.ndarray, gains: dict[str, np.ndarray]) -> np.ndarray:
    f = _centre_mean_field()
    return np.stack([patch_rgb * g * f for g in gains.values()], axis=1)


def test_eq2_flat_field_and_dark_recover_patch_responses(tmp_path) -> None:
    session, patch_rgb = _make_session(tmp_path / "s", with_corners=True)
    fractions: list[float] = []
    out = process_session(session, loader=_npy_loader, progress=fractions.append)
    assert isinstance(out, ProcessedSession) and out.corners_source == "layout"
    r = out.responses
    assert r.patches == _layout().patch_names and r.illuminants == ("L1", "WHITE")
    np.testing.assert_allclose(r.rgb, _expected(patch_rgb, GAINS), atol=ATOL_QUANTISED)
    # the white background's level each light's responses are scaled to (Eq. 2's
    # mean A_B): the board's reflectance x the light's gain x the centre's field
    white = WHITE_REFLECTANCE * np.stack(list(GAINS.values())) * _centre_mean_field()
    np.testing.assert_allclose(r.white_rgb, white, atol=ATOL_QUANTISED)
    # uint16 rounding leaves about 1/sqrt(12) DN of spread per pixel, nothing else
    assert np.all(r.rgb_std < 1e-4)
    assert np.all(r.saturated == 0) and not out.flagged
    assert fractions[-1] == 1.0 and fractions == sorted(fractions)
    # illuminant = measured SPD x exposure_s
    np.testing.assert_allclose(out.illuminants["L1"], _spd(2.0).values[0] * 0.5)


def test_auto_corners_match_truth_and_give_the_same_responses(tmp_path) -> None:
    session, patch_rgb = _make_session(tmp_path / "s")
    out = process_session(session, loader=_npy_loader)
    assert out.corners_source == "auto"
    np.testing.assert_allclose(out.layout.corners_px, CORNERS, atol=ATOL_CORNER_PX)
    np.testing.assert_allclose(
        out.responses.rgb, _expected(patch_rgb, GAINS), atol=ATOL_QUANTISED
    )


def test_session_corner_finder_is_the_one_processing_uses(tmp_path) -> None:
    """The layout editor's finder: the same frames, the same detector, the same
    corners as processing with ``corners="auto"``."""
    session, _ = _make_session(tmp_path / "s")
    found, target = find_session_corners(session, loader=_npy_loader)
    out = process_session(session, loader=_npy_loader)
    np.testing.assert_array_equal(found.corners_px, out.layout.corners_px)
    assert found.residual_px == out.corner_residual_px
    assert (found.channel, found.white_id, found.target_id) == (
        "WHITE",
        "white_WHITE",
        "target_WHITE",
    )
    assert target.shape == (SHAPE[0] // 2, SHAPE[1] // 2)


def test_session_corner_finder_needs_a_white_and_a_target_frame(tmp_path) -> None:
    session, _ = _make_session(tmp_path / "s", skip=("target_L1", "target_WHITE"))
    ids = [f.id for f in session.frames]
    assert not any(i.startswith("target") for i in ids), ids
    with pytest.raises(InputError, match="white-background and a target frame"):
        find_session_corners(session, loader=_npy_loader)


def test_roi_pixel_count_follows_roi_fraction(tmp_path) -> None:
    session, _ = _make_session(tmp_path / "s", with_corners=True)
    a = process_session(session, loader=_npy_loader, roi_fraction=0.2)
    b = process_session(session, loader=_npy_loader, roi_fraction=0.4)
    ratio = b.responses.n_pixels.sum() / a.responses.n_pixels.sum()
    assert ratio == pytest.approx(2.0, rel=0.1)


def test_clipped_patch_is_flagged(tmp_path) -> None:
    rgb = _patch_rgb()
    rgb[3] = [1.6, 0.2, 0.2]  # red of P3 over full scale under every channel
    session, _ = _make_session(tmp_path / "s", patch_rgb=rgb, with_corners=True)
    out = process_session(session, loader=_npy_loader)
    assert ("P3", "WHITE") in out.flagged
    assert out.responses.saturated[3, 1] == 1.0
    assert np.all(np.delete(out.responses.saturated, 3, axis=0) == 0)
    assert any("clipped" in w for w in out.warnings)


def _full_well_loader(path: Path) -> RawFrame:
    """A sensor whose full well clips the charge at 97 % of the white level: a
    clipped photosite reads under the white level and is not flagged by it."""
    cap = BLACK_DN + 0.97 * (WHITE_DN - BLACK_DN)
    mosaic = np.minimum(np.load(path), np.uint16(round(cap)))
    return RawFrame(path, mosaic, "RGGB", np.full((2, 2), BLACK_DN), WHITE_DN)


@pytest.mark.parametrize(
    "loader", [_npy_loader, _full_well_loader], ids=["white-level", "full-well"]
)
def test_brackets_merge_clipped_pixels_in_the_linear_domain(tmp_path, loader) -> None:
    """Clipped cells take the short bracket, scaled; with the full well clipping
    below the white level too (cells just under full scale count as clipped, as in
    the image path: before, P3's red was the full well's reading, 5 % low)."""
    rgb = _patch_rgb()
    rgb[3] = [1.3, 0.2, 0.2]  # clipped at the long exposure, fine at 1/4 of it
    session, _ = _make_session(
        tmp_path / "s", patch_rgb=rgb, brackets=(1.0, 0.25), with_corners=True
    )
    out = process_session(session, loader=loader)
    assert not out.flagged
    # the short bracket has 4x the relative quantisation error
    np.testing.assert_allclose(
        out.responses.rgb, _expected(rgb, GAINS), atol=4 * ATOL_QUANTISED
    )


def test_missing_frames_fail_or_are_left_out(tmp_path) -> None:
    session, _ = _make_session(tmp_path / "s", skip=("target_L1",), with_corners=True)
    with pytest.raises(InputError, match="L1"):
        process_session(session, loader=_npy_loader)
    out = process_session(session, loader=_npy_loader, allow_incomplete=True)
    assert out.responses.illuminants == ("WHITE",)
    assert any("L1" in w for w in out.warnings)


def test_a_file_failing_its_checksum_fails_or_is_left_out(tmp_path) -> None:
    """The checksums are computed beside the processing, not before it: the result
    is the same as checking first (the error, or the channel left out)."""
    session, _ = _make_session(tmp_path / "s", with_corners=True)
    path = session.path_of(next(f for f in session.frames if f.id == "target_L1"))
    mosaic = np.load(path)
    mosaic[0, 0] += 1  # still a readable frame, but not the one recorded
    np.save(path, mosaic)
    with pytest.raises(InputError, match=r"L1: raw file .* fails its checksum"):
        process_session(session, loader=_npy_loader)
    out = process_session(session, loader=_npy_loader, allow_incomplete=True)
    assert out.responses.illuminants == ("WHITE",)
    assert any("L1" in w for w in out.warnings)
    full = process_session(session, loader=_npy_loader, verify=False)
    assert full.responses.illuminants == ("L1", "WHITE")


def test_outputs_are_what_calibrate_reads(tmp_path) -> None:
    session, _ = _make_session(tmp_path / "s", with_corners=True)
    out = process_session(session, loader=_npy_loader)
    write_processed(out, tmp_path / "r.csv", tmp_path / "l.csv")
    back = read_responses_csv(tmp_path / "r.csv")
    np.testing.assert_array_equal(back.rgb, out.responses.rgb)
    np.testing.assert_array_equal(back.white_rgb, out.responses.white_rgb)
    illum = read_spectra_csv(tmp_path / "l.csv")
    assert illum.names == ("L1", "WHITE")


def test_cancel_stops_between_frames(tmp_path) -> None:
    session, _ = _make_session(tmp_path / "s", with_corners=True)
    calls = iter(range(100))
    with pytest.raises(Cancelled):
        process_session(
            session, loader=_npy_loader, should_stop=lambda: next(calls) > 2
        )


def test_roiset_rejects_rois_outside_the_image() -> None:
    quad = np.array([[[-3.0, 1.0], [5.0, 1.0], [5.0, 6.0], [-3.0, 6.0]]])
    with pytest.raises(InputError, match="outside"):
        RoiSet.from_quads(["A"], quad, (10, 10))
    inside = np.array([[[1.0, 1.0], [5.0, 1.0], [5.0, 6.0], [1.0, 6.0]]])
    assert RoiSet.from_quads(["A"], inside, (10, 10)).n_pixels.tolist() == [30]


def test_gather_reads_the_same_values_as_raw_planes(tmp_path) -> None:
    rng = np.random.default_rng(2)
    mosaic = rng.integers(1500, 16000, size=(64, 96)).astype(np.uint16)
    frame = RawFrame(
        tmp_path / "x",
        mosaic,
        "GRBG",
        np.array([[2040.0, 2050.0], [2045.0, 2055.0]]),
        15000.0,
    )
    quad = np.array([[[3.2, 4.1], [30.5, 6.0], [28.0, 25.7], [5.0, 22.2]]])
    rois = RoiSet.from_quads(["A"], quad, frame.shape).with_window("W", 1, 5, 2, 9)
    values, saturated = rois.gather(frame)
    np.testing.assert_array_equal(values, frame.planes[:, rois.rows, rois.cols])
    np.testing.assert_array_equal(saturated, frame.saturated[rois.rows, rois.cols])
    assert saturated.any() and not saturated.all()


def test_channel_without_white_signal_borrows_the_flat_field(tmp_path) -> None:
    gains = {"L1": np.array([0.5, 0.7, 0.0]), "WHITE": GAINS["WHITE"]}
    session, patch_rgb = _make_session(tmp_path / "s", gains=gains, with_corners=True)
    out = process_session(session, loader=_npy_loader)
    assert out.stats["flat_fields_borrowed"] == 12  # blue under L1, every patch
    assert np.all(np.isfinite(out.responses.rgb))
    np.testing.assert_allclose(
        out.responses.rgb, _expected(patch_rgb, gains), atol=ATOL_QUANTISED
    )


@pytest.mark.parametrize("pad", [2, -2])
def test_a_frame_of_another_size_is_an_input_error(tmp_path, pad) -> None:
    """A frame retaken at another raw size must not be read at the wrong photosites."""
    session, _ = _make_session(tmp_path / "s", with_corners=True)

    def loader(path: Path) -> RawFrame:
        frame = _npy_loader(path)
        if path.stem != "target_L1":
            return frame
        m = frame.mosaic
        resized = np.pad(m, ((0, pad), (0, pad)), mode="edge") if pad > 0 else m[:pad]
        return RawFrame(path, resized, "RGGB", np.full((2, 2), BLACK_DN), WHITE_DN)

    with pytest.raises(InputError, match=r"target_L1.*mosaic.*retake") as info:
        process_session(session, loader=loader)
    assert "--retake target_L1" in str(info.value)


def test_an_unreadable_frame_names_it_and_says_how_to_retake(tmp_path) -> None:
    session, _ = _make_session(tmp_path / "s", with_corners=True)

    def loader(path: Path) -> RawFrame:
        if path.stem == "white_WHITE":
            raise InputError("cannot read as a camera raw file", path=path)
        return _npy_loader(path)

    with pytest.raises(InputError, match=r"frame white_WHITE: .*--retake white_WHITE"):
        process_session(session, loader=loader)


def test_flat_window_is_centred_and_cut_to_the_planes() -> None:
    assert flat_window((300, 400)) == (100, 200, 150, 250)
    assert flat_window((60, 400)) == (0, 60, 170, 230)
    with pytest.raises(InputError):
        flat_window((300, 400), 0)


@pytest.mark.parametrize(("corners", "brackets"), [("auto", (1.0,)),
                                                   ("layout", (1.0, 0.25))])  # fmt: skip
def test_frames_are_decoded_ahead_in_the_order_processing_reads_them(
    tmp_path, monkeypatch, corners, brackets
) -> None:
    """Every frame is read once, and on the read-ahead thread (its plan is the
    order processing asks for them in); the responses are those read in turn."""
    import threading

    session, _ = _make_session(
        tmp_path / "s", brackets=brackets, with_corners=corners == "layout"
    )
    loads: list[tuple[str, str]] = []

    def loader(path: Path) -> RawFrame:
        loads.append((path.name, threading.current_thread().name))
        return _npy_loader(path)

    out = process_session(session, loader=loader, corners=corners)
    names = [n for n, _ in loads]
    assert sorted(names) == sorted({p.name for p in session.root.rglob("*.npy")})
    assert len(names) == len(set(names)) == out.stats["frames_read"]
    assert all(t.startswith("tunespec-read-ahead") for _, t in loads)

    from tunespec.app.pipeline import processing as pp

    # no read-ahead: the same frames read in turn on this thread
    monkeypatch.setattr(pp._FrameReader, "read_ahead", lambda self, records: None)
    in_turn = process_session(session, loader=_npy_loader, corners=corners)
    np.testing.assert_array_equal(out.responses.rgb, in_turn.responses.rgb)
    np.testing.assert_array_equal(out.responses.rgb_std, in_turn.responses.rgb_std)


@pytest.mark.parametrize(
    ("exif", "message"),
    [
        ({"exposure_s": 0.25}, "exposed 0.25 s where the session records 0.5 s"),
        ({"iso": 400.0}, "at ISO 400 where the session records 100"),
        ({"aperture": 8.0}, "at f/8 where the session's first frame was at f/5.6"),
    ],
)
def test_a_raw_file_taken_otherwise_than_recorded_is_refused(
    tmp_path, exif, message
) -> None:
    """Eq. 1's illuminants are the readings x the recorded exposure and ISO, and
    Eq. 2 divides frames of one aperture: a raw file whose own EXIF says otherwise
    (a camera dial, a manual mode, a lens touched) is refused, naming the frame."""

    session, _ = _make_session(tmp_path / "s", with_corners=True)
    records = {session.path_of(f): f for f in session.frames}

    def loader(odd: dict) -> Callable[[Path], RawFrame]:
        def load(path: Path) -> RawFrame:
            # each file as recorded (0.5 s under L1, f/5.6), target_L1 with ``odd``
            f = records[path]
            frame = replace(_npy_loader(path), exposure_s=f.exposure_s, iso=f.iso,
                            aperture=5.6)  # fmt: skip
            return replace(frame, **odd) if f.id == "target_L1" else frame

        return load

    with pytest.raises(InputError, match="frame target_L1: its raw file") as err:
        process_session(session, loader=loader(exif))
    assert message in str(err.value), err.value
    assert "retake it" in str(err.value)
    out = process_session(session, loader=loader({}))  # as recorded: as before
    assert out.responses.illuminants == ("L1", "WHITE")


# -- the f-number: kept beside the responses, shown in the report's provenance --------
def _at_f(f_number: float | None) -> Callable[[Path], RawFrame]:
    """Frames whose raw files state ``f_number`` (``None``: none, the simulator's)."""
    return lambda path: replace(_npy_loader(path), aperture=f_number)


@pytest.mark.parametrize(
    ("f_number", "line", "shown"),
    [
        (8.0, "# f_number: 8\n", "f/8"),
        (float(np.float32(5.6)), "# f_number: 5.6\n", "f/5.6"),  # as LibRaw reads it
        (None, None, "not recorded"),
    ],
)
def test_the_f_number_of_the_frames_reaches_the_provenance(
    tmp_path, f_number, line, shown
) -> None:
    """Processing keeps the f-number the raw files state with the illuminants, their
    CSV keeps it in a comment line, the session read back from its files has it, and
    the report's provenance shows it per session; frames stating none get none."""
    from tunespec.app.pipeline.folder import read_processed
    from tunespec.app.pipeline.steps import session_provenance

    session, _ = _make_session(tmp_path / "s", with_corners=True)
    out = process_session(session, loader=_at_f(f_number))
    assert out.aperture == (None if f_number is None else pytest.approx(f_number))
    write_processed(out, tmp_path / "responses.csv", tmp_path / "illuminants.csv")
    text = (tmp_path / "illuminants.csv").read_text()
    if line is None:
        assert "f_number" not in text
    else:
        assert text.endswith(line)
    back = read_processed(tmp_path, out.layout)
    assert back.aperture == out.aperture
    np.testing.assert_array_equal(back.illuminants.values, out.illuminants.values)
    items, _, _ = session_provenance({"chart": session.root}, {"chart": back})
    assert items["chart aperture"] == shown
    assert items["chart frames"] == "5 (1 dark), ISO 100, exposure fixed"
    # without the processed session the manifest alone cannot say it: nothing said
    assert "chart aperture" not in session_provenance({"chart": session.root})[0]


@pytest.mark.parametrize("value", ["0.1", "200", "nan", "inf", "eight", ""])
def test_an_f_number_no_lens_has_is_refused_where_a_file_states_it(
    tmp_path, value
) -> None:
    """An illuminants CSV stating an f-number outside [0.5, 128] (or no number) is
    refused in one line naming the file, the line and the key, read as processing
    reads it back and as calibrate and estimate read illuminants."""
    from tunespec.core.io.spectral import read_spectral

    path = tmp_path / "illuminants.csv"
    path.write_text(f"wavelength_nm,L1\n400,1.0\n410,2.0\n# f_number: {value}\n")
    for kind in ("spectra", "illuminant"):
        with pytest.raises(InputError) as err:
            read_spectral(path, kind=kind)
        message = str(err.value)
        assert message.startswith(
            f"{path}:4: f_number: expected an f-number in [0.5, 128], got "
        ), message
        assert "\n" not in message
    path.write_text("wavelength_nm,L1\n400,1.0\n410,2.0\n# f_number: 11.0\n")
    assert read_spectra_csv(path).meta["f_number"] == "11"


def test_frames_are_checked_against_the_first_that_states_an_f_number(tmp_path) -> None:
    """A session whose first frame read states no f-number (taken with another
    tool, a lens without contacts) is still checked, against the first frame that
    does."""
    session, _ = _make_session(tmp_path / "s", with_corners=True)
    records = {session.path_of(f): f for f in session.frames}

    def loader(odd: float) -> Callable[[Path], RawFrame]:
        read: list[str] = []

        def load(path: Path) -> RawFrame:
            f = records[path]
            stated = None if not read else (odd if f.id == "target_L1" else 8.0)
            read.append(f.id)
            return replace(_npy_loader(path), aperture=stated)

        return load

    assert process_session(session, loader=loader(8.0)).aperture == 8.0
    with pytest.raises(InputError, match=r"at f/5\.6 where the session's first frame"):
        process_session(session, loader=loader(5.6))
