"""Camera conformance: every Camera implementation behaves the same to capture code.

Parametrized over the simulator, the gphoto2 driver on a fake gphoto2 module and, when
``TUNESPEC_CAMERA`` names one (``gphoto2`` or ``gphoto2:usb:001,004``), a real camera
(marked ``hardware``).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.devices.camera_fixtures import StubLight, dng_raw_maker
from tunespec.core.io.raw import load_raw
from tunespec.devices.canon.gphoto2_camera import Gphoto2Camera
from tunespec.devices.protocols import Camera, DeviceError, DeviceIdentity
from tunespec.devices.sim.camera import SimCamera
from tunespec.devices.sim.scene import SimScene
from tunespec.devices.testing import FakeCameraState, make_fake_gphoto2

HARDWARE_SPEC = os.environ.get("TUNESPEC_CAMERA", "")

#: Settings every camera offers exactly (Canon third-stop values).
EXPOSURES_S = (1 / 100, 0.5, 6.0)
ISOS = (100, 400)


@pytest.fixture(
    params=[
        "sim",
        "gphoto2-fake",
        pytest.param(
            "hardware",
            marks=[
                pytest.mark.hardware,
                pytest.mark.skipif(
                    not HARDWARE_SPEC, reason="set TUNESPEC_CAMERA to a camera spec"
                ),
            ],
        ),
    ]
)
def camera(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Camera]:
    cam: Camera
    if request.param == "sim":
        cam = SimCamera(
            StubLight("WHITE_WARM"), SimScene.colorchecker_sg(), resolution=(256, 192)
        )
    elif request.param == "gphoto2-fake":
        fake_dir = tmp_path / "fake-card"
        fake_dir.mkdir()
        state = FakeCameraState(make_raw=dng_raw_maker(fake_dir))
        cam = Gphoto2Camera.open("gphoto2", gp_module=make_fake_gphoto2(state))
    else:
        cam = Gphoto2Camera.open(HARDWARE_SPEC)
    yield cam
    cam.close()


def test_is_a_camera_with_identity(camera: Camera) -> None:
    assert isinstance(camera, Camera)
    ident = camera.identity
    assert isinstance(ident, DeviceIdentity)
    assert all(isinstance(v, str) for v in dataclasses.astuple(ident))
    assert ident.vendor and ident.model


@pytest.mark.parametrize("exposure_s", EXPOSURES_S)
def test_exposure_round_trip(camera: Camera, exposure_s: float) -> None:
    camera.set_exposure(exposure_s)
    assert isinstance(camera.exposure_s, float)
    assert camera.exposure_s == pytest.approx(exposure_s, rel=1e-9)


@pytest.mark.parametrize("iso", ISOS)
def test_iso_round_trip(camera: Camera, iso: int) -> None:
    camera.set_iso(iso)
    assert camera.iso == iso and isinstance(camera.iso, int)


def test_capture_writes_a_raw_file_rawpy_reads(camera: Camera, tmp_path: Path) -> None:
    camera.set_iso(100)
    camera.set_exposure(1 / 100)
    out_dir = tmp_path / "frames"
    path = camera.capture(out_dir / "L01_target")
    assert path.parent == out_dir and path.stem == "L01_target"
    assert path.suffix in (".dng", ".cr2")
    assert [p.name for p in out_dir.iterdir()] == [path.name]  # nothing half-written
    frame = load_raw(path)
    assert frame.cfa_pattern == "RGGB"
    assert frame.mosaic.ndim == 2 and frame.mosaic.dtype == np.uint16
    assert 0 <= frame.black_level < frame.white_level <= 65535
    planes = frame.planes
    assert planes.shape == (3, *frame.shape) and planes.dtype == np.float32
    # full-scale units: black is 0 (noise goes a little below), white is 1
    assert planes.max() <= 1.0 + 1e-6
    assert planes.min() >= -frame.black_level / (frame.white_level - frame.black_level)
    assert frame.saturated.shape == frame.shape
    assert frame.exposure_s == pytest.approx(0.01, rel=1e-6)
    assert frame.iso == 100


def test_closed_camera_refuses(camera: Camera, tmp_path: Path) -> None:
    camera.close()
    with pytest.raises(DeviceError):
        camera.capture(tmp_path / "x")
