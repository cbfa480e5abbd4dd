"""Gphoto2Camera against a fake python-gphoto2 module (and a real camera if asked)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from tests.devices.camera_fixtures import dng_raw_maker
from tunespec.core.io.raw import load_raw
from tunespec.devices.canon.gphoto2_camera import (
    Gphoto2Camera,
    import_gphoto2,
    map_gphoto2_error,
    parse_shutter_speed,
)
from tunespec.devices.protocols import (
    Camera,
    DeviceBusyError,
    DeviceCommandError,
    DeviceConnectionError,
    DeviceTimeoutError,
)
from tunespec.devices.testing import (
    FakeCameraState,
    FakeGPhoto2Error,
    canon_5d3_config,
    make_fake_gphoto2,
)


def _open(state: FakeCameraState | None = None, **kw) -> tuple[Gphoto2Camera, FakeCameraState]:  # fmt: skip
    gp = make_fake_gphoto2(state)
    return Gphoto2Camera.open(kw.pop("spec", "gphoto2"), gp_module=gp, **kw), gp.state


def test_open_prepares_raw_capture_to_card() -> None:
    cam, st = _open()
    assert isinstance(cam, Camera)
    s = st.settings()
    assert s["imageformat"] == "RAW" and s["capturetarget"] == "Memory card"
    assert cam.identity.vendor == "Canon" and cam.identity.model == "EOS 5D Mark III"
    assert cam.identity.serial == "0123456789" and cam.identity.firmware == "1.3.5"
    assert cam.exposure_s == pytest.approx(1 / 60)
    assert cam.iso == 0  # camera on Auto ISO until set
    assert st.opened_port == "usb:001,004"


def test_open_by_port_and_unknown_port() -> None:
    state = FakeCameraState(
        cameras=[("Canon EOS 5D Mark III", "usb:001,004"), ("Canon EOS 5D Mark III", "usb:002,007")]
    )  # fmt: skip
    _, st = _open(state, spec="gphoto2:usb:002,007")
    assert st.opened_port == "usb:002,007"
    with pytest.raises(DeviceConnectionError, match=r"no camera at port 'usb:009,009'"):
        _open(FakeCameraState(), spec="gphoto2:usb:009,009")
    with pytest.raises(DeviceConnectionError, match="not a gphoto2 camera spec"):
        _open(FakeCameraState(), spec="canon")


def test_no_camera_found() -> None:
    with pytest.raises(DeviceConnectionError, match="no camera found"):
        _open(FakeCameraState(cameras=[]))


def test_mode_dial_not_on_manual() -> None:
    state = FakeCameraState(config=canon_5d3_config(mode="AV"))
    with pytest.raises(DeviceCommandError, match=r"mode dial is on 'AV'.*M"):
        _open(state)
    assert state.exited  # released again


@pytest.mark.parametrize(
    ("seconds", "choice", "actual_s"),
    [
        (6.0, "6", 6.0),
        (0.01, "1/100", 0.01),
        (0.0105, "1/100", 0.01),
        (1 / 3.0, "0.3", 0.3),
        (7.0, "8", 8.0),  # nearest in stops: log2(8/7) = 0.19 < log2(7/6) = 0.22
        (1 / 8000, "1/8000", 1 / 8000),
    ],
)
def test_exposure_maps_to_nearest_shutter_speed(seconds, choice, actual_s) -> None:
    cam, st = _open()
    cam.set_exposure(seconds)
    assert st.settings()["shutterspeed"] == choice
    assert cam.exposure_s == pytest.approx(actual_s)


def test_exposure_outside_timed_range() -> None:
    cam, _ = _open()
    with pytest.raises(
        DeviceCommandError, match=r"outside the camera's timed range 0.000125-30 s"
    ):
        cam.set_exposure(60.0)
    with pytest.raises(DeviceCommandError, match="must be > 0"):
        cam.set_exposure(0.0)


def test_iso_round_trip_and_unavailable_value() -> None:
    cam, st = _open()
    cam.set_iso(400)
    assert st.settings()["iso"] == "400" and cam.iso == 400
    cam.set_iso(110)  # nearest third stop: 100 (0.14 stop) rather than 125 (0.18)
    assert cam.iso == 100
    with pytest.raises(DeviceCommandError, match="ISO 50 is not offered"):
        cam.set_iso(50)


def test_shutter_speed_parsing() -> None:
    assert parse_shutter_speed("1/100") == pytest.approx(0.01)
    assert parse_shutter_speed("6") == 6.0
    assert parse_shutter_speed("0.8") == 0.8
    assert parse_shutter_speed('30"') == 30.0
    assert parse_shutter_speed("2.5s") == 2.5
    for bad in ("bulb", "Bulb", "auto", "", "1/0", "-1"):
        assert parse_shutter_speed(bad) is None


def test_capture_downloads_raw_atomically(tmp_path: Path) -> None:
    state = FakeCameraState(make_raw=dng_raw_maker(tmp_path))
    cam, st = _open(state)
    cam.set_exposure(6)
    cam.set_iso(100)
    out = cam.capture(tmp_path / "frames" / "L01_target")
    assert out == tmp_path / "frames" / "L01_target.cr2"
    frame = load_raw(out)
    assert frame.exposure_s == 6.0 and frame.iso == 100.0
    assert [p.name for p in out.parent.iterdir()] == ["L01_target.cr2"]  # no .part left
    assert len(st.card) == 1  # kept on the card by default
    assert "wait_for_event" in st.calls


def test_capture_deletes_from_card_when_asked(tmp_path: Path) -> None:
    cam, st = _open(FakeCameraState(), delete_from_card=True)
    cam.capture(tmp_path / "x")
    assert st.card == {}


def test_capture_refuses_a_jpeg(tmp_path: Path) -> None:
    cam, st = _open()
    st.config = canon_5d3_config(image_format="Large Fine JPEG")  # changed on camera
    with pytest.raises(DeviceCommandError, match="not a raw file"):
        cam.capture(tmp_path / "x")


def test_failed_download_leaves_no_file(tmp_path: Path) -> None:
    cam, st = _open()
    st.errors["file_get"] = [-7]
    with pytest.raises(DeviceConnectionError, match="lost the USB connection"):
        cam.capture(tmp_path / "x")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("method", "code", "error", "fragment"),
    [
        (
            "init",
            -53,
            DeviceBusyError,
            r"another program \(gvfs-gphoto2-volume-monitor\?\) holds the camera",
        ),
        ("init", -105, DeviceConnectionError, "does not know this camera model"),
        ("init", -52, DeviceConnectionError, "camera not found on USB"),
        ("autodetect", -53, DeviceBusyError, "holds the camera"),
        ("set_config", -110, DeviceBusyError, "the camera is busy"),
        ("get_config", -10, DeviceTimeoutError, "did not answer in time"),
    ],
)
def test_open_errors_are_mapped(method, code, error, fragment) -> None:
    state = FakeCameraState(errors={method: [code]})
    with pytest.raises(error, match=fragment):
        _open(state)


@pytest.mark.parametrize(
    ("code", "error", "fragment"),
    [
        (-1, DeviceCommandError, "lens on MF"),
        (-113, DeviceCommandError, "autofocus"),
        (-110, DeviceBusyError, "busy"),
        (-53, DeviceBusyError, "holds the camera"),
        (-7, DeviceConnectionError, "lost the USB connection"),
        (-115, DeviceCommandError, "memory card is full"),
        (-999, DeviceCommandError, r"camera: capture failed \(\[-999\]"),
    ],
)
def test_capture_errors_are_mapped(tmp_path: Path, code, error, fragment) -> None:
    cam, st = _open()
    st.errors["capture"] = [code]
    with pytest.raises(error, match=fragment):
        cam.capture(tmp_path / "x")


def test_map_error_keeps_the_libgphoto2_text() -> None:
    err = map_gphoto2_error(FakeGPhoto2Error(-53), "opening")
    assert "Could not claim the USB device" in str(err)


def test_close_is_idempotent_and_final(tmp_path: Path) -> None:
    cam, st = _open()
    cam.close()
    cam.close()
    assert st.exited
    with pytest.raises(DeviceConnectionError, match="closed"):
        cam.capture(tmp_path / "x")


def test_missing_module_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "gphoto2", None)  # import gphoto2 -> ImportError
    with pytest.raises(DeviceConnectionError, match=r"tunespec\[gphoto2\]"):
        import_gphoto2()
    with pytest.raises(DeviceConnectionError, match="python-gphoto2 is not installed"):
        Gphoto2Camera.open("gphoto2")


# -- real camera ------------------------------------------------------------------
@pytest.mark.hardware
@pytest.mark.skipif(
    not os.environ.get("TUNESPEC_CAMERA", "").startswith("gphoto2"),
    reason="set TUNESPEC_CAMERA=gphoto2[:PORT] with a 5D Mark III connected",
)
def test_real_camera_capture(tmp_path: Path) -> None:
    cam = Gphoto2Camera.open(os.environ["TUNESPEC_CAMERA"])
    try:
        cam.set_iso(100)
        cam.set_exposure(1 / 100)
        out = cam.capture(tmp_path / "hw")
        frame = load_raw(out)
        assert frame.cfa_pattern == "RGGB"
        assert frame.exposure_s == pytest.approx(0.01, rel=0.05)
    finally:
        cam.close()
