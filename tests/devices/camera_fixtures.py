"""Test helpers for the camera tests: a stub light and a fake python-gphoto2 module.

Kept out of ``conftest.py`` (owned by another part of the project); the camera test
modules import from here.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from tunespec.core.datasets import load_led_set
from tunespec.core.spectra import Spectra
from tunespec.devices.clock import Clock
from tunespec.devices.sim.camera import NOMINAL_PEAK_RADIANCE_W_SR_M2_NM


class StubLight:
    """A light source that only knows its true SPD (stands in for SimLightSource).

    Parameters
    ----------
    channel
        LED of the nominal set, or ``None`` for darkness.
    level
        The LED's level: its SPD is the nominal relative SPD times ``level`` times
        the nominal peak radiance (1e-3 W sr^-1 m^-2 nm^-1, as ``SimLightSource``).
    drift_per_s
        Relative change of the output per second of ``clock`` time (0: stable).
    """

    def __init__(
        self,
        channel: str | None = "WHITE_WARM",
        level: float = 1.0,
        *,
        clock: Clock | None = None,
        drift_per_s: float = 0.0,
    ) -> None:
        leds = load_led_set()
        self._wl = leds.wavelength_nm
        self._base = (
            np.zeros_like(self._wl)
            if channel is None
            else leds[channel] * level * NOMINAL_PEAK_RADIANCE_W_SR_M2_NM
        )
        self._clock = clock
        self._drift = drift_per_s

    def factor(self) -> float:
        t = 0.0 if self._clock is None else self._clock.now_s()
        return 1.0 + self._drift * t

    def emitted_spd(self) -> Spectra:
        return Spectra(self._wl, self._base[None] * self.factor(), ("emitted",))


# -- fake python-gphoto2 -----------------------------------------------------------
GP_ERROR_MESSAGES = {
    -1: "Unspecified error",
    -2: "Bad parameters",
    -7: "I/O problem",
    -10: "Timeout reading from or writing to the port",
    -52: "Could not find the requested device on the USB port",
    -53: "Could not claim the USB device",
    -105: "Unknown model",
    -110: "I/O in progress",
    -113: "Camera error",
}

SHUTTER_CHOICES_5D3 = [
    "bulb", "30", "25", "20", "15", "13", "10", "8", "6", "5", "4", "3.2", "2.5", "2",
    "1.6", "1.3", "1", "0.8", "0.6", "0.5", "0.4", "0.3", "1/4", "1/5", "1/6", "1/8",
    "1/10", "1/13", "1/15", "1/20", "1/25", "1/30", "1/40", "1/50", "1/60", "1/80",
    "1/100", "1/125", "1/160", "1/200", "1/250", "1/320", "1/400", "1/500", "1/640",
    "1/800", "1/1000", "1/1250", "1/1600", "1/2000", "1/2500", "1/3200", "1/4000",
    "1/5000", "1/6400", "1/8000",
]  # fmt: skip
ISO_CHOICES_5D3 = [
    "Auto", "100", "125", "160", "200", "250", "320", "400", "500", "640", "800",
    "1000", "1250", "1600", "2000", "2500", "3200", "4000", "5000", "6400", "8000",
    "10000", "12800", "16000", "20000", "25600",
]  # fmt: skip
FORMAT_CHOICES_5D3 = [
    "Large Fine JPEG", "Large Normal JPEG", "Medium Fine JPEG", "Small Fine JPEG",
    "RAW + Large Fine JPEG", "RAW", "mRAW", "sRAW",
]  # fmt: skip


class FakeGPhoto2Error(Exception):
    """Like ``gphoto2.GPhoto2Error``: ``code`` and ``string``."""

    def __init__(self, code: int) -> None:
        self.code = code
        self.string = GP_ERROR_MESSAGES.get(code, "Unknown error")
        super().__init__(f"[{code}] {self.string}")


class FakeWidget:
    """A node of the settings tree (section, radio or text widget)."""

    def __init__(
        self,
        name: str,
        value: str = "",
        choices: list[str] | None = None,
        children: list[FakeWidget] | None = None,
        readonly: bool = False,
    ) -> None:
        self.name = name
        self.value = value
        self.choices = choices
        self.children = children or []
        self.readonly = readonly

    def get_name(self) -> str:
        return self.name

    def get_value(self) -> str:
        return self.value

    def set_value(self, value: str) -> None:
        if self.readonly or (self.choices is not None and value not in self.choices):
            raise FakeGPhoto2Error(-2)
        self.value = value

    def get_readonly(self) -> int:
        return int(self.readonly)

    def count_choices(self) -> int:
        return len(self.choices or [])

    def get_choice(self, i: int) -> str:
        return (self.choices or [])[i]

    def count_children(self) -> int:
        return len(self.children)

    def get_child(self, i: int) -> FakeWidget:
        return self.children[i]

    def walk(self) -> list[FakeWidget]:
        out = [self]
        for c in self.children:
            out.extend(c.walk())
        return out


def canon_5d3_config(
    *, mode: str = "Manual", image_format: str = "Large Fine JPEG"
) -> FakeWidget:
    """The parts of a 5D Mark III's settings tree the driver uses (as libgphoto2 shows it)."""
    return FakeWidget(
        "main",
        children=[
            FakeWidget(
                "settings",
                children=[
                    FakeWidget(
                        "capturetarget", "Internal RAM", ["Internal RAM", "Memory card"]
                    ),
                ],
            ),
            FakeWidget(
                "status",
                children=[
                    FakeWidget("serialnumber", "0123456789", readonly=True),
                    FakeWidget("deviceversion", "1.3.5", readonly=True),
                ],
            ),
            FakeWidget(
                "imgsettings",
                children=[
                    FakeWidget("imageformat", image_format, list(FORMAT_CHOICES_5D3)),
                    FakeWidget("iso", "Auto", list(ISO_CHOICES_5D3)),
                ],
            ),
            FakeWidget(
                "capturesettings",
                children=[
                    FakeWidget(
                        "autoexposuremode",
                        mode,
                        ["P", "TV", "AV", "Manual", "Bulb"],
                        readonly=True,
                    ),
                    FakeWidget("shutterspeed", "1/60", list(SHUTTER_CHOICES_5D3)),
                ],
            ),
        ],
    )


@dataclass
class FakeCameraState:
    """What the fake camera and its card hold, and the errors it will raise.

    ``errors`` maps a method name to result codes raised by its next calls, in order.
    ``make_raw(settings) -> bytes`` gives the content of a captured frame.
    """

    cameras: list[tuple[str, str]] = field(
        default_factory=lambda: [("Canon EOS 5D Mark III", "usb:001,004")]
    )
    config: FakeWidget = field(default_factory=canon_5d3_config)
    card: dict[str, bytes] = field(default_factory=dict)
    errors: dict[str, list[int]] = field(default_factory=dict)
    calls: list[str] = field(default_factory=list)
    opened_port: str = ""
    make_raw: Callable[[dict[str, str]], bytes] | None = None
    exited: bool = False
    n_captured: int = 0

    def settings(self) -> dict[str, str]:
        return {w.name: w.value for w in self.config.walk() if not w.children}

    def maybe_fail(self, method: str) -> None:
        self.calls.append(method)
        queue = self.errors.get(method)
        if queue:
            raise FakeGPhoto2Error(queue.pop(0))


def make_fake_gphoto2(state: FakeCameraState | None = None) -> Any:
    """A stand-in for the ``gphoto2`` module driving :class:`FakeCameraState`."""
    st = state or FakeCameraState()

    class PortInfoList(list):  # type: ignore[type-arg]
        def load(self) -> None:
            self[:] = [addr for _, addr in st.cameras]

        def lookup_path(self, path: str) -> int:
            if path not in self:
                raise FakeGPhoto2Error(-5)
            return self.index(path)

    class CameraAbilitiesList(list):  # type: ignore[type-arg]
        def load(self) -> None:
            self[:] = [name for name, _ in st.cameras]

        def lookup_model(self, model: str) -> int:
            if model not in self:
                raise FakeGPhoto2Error(-105)
            return self.index(model)

    class Camera:
        @staticmethod
        def autodetect() -> list[tuple[str, str]]:
            st.maybe_fail("autodetect")
            return list(st.cameras)

        def set_port_info(self, port: str) -> None:
            st.opened_port = port

        def set_abilities(self, model: str) -> None:
            pass

        def init(self) -> None:
            st.maybe_fail("init")

        def exit(self) -> None:
            st.exited = True

        def get_config(self) -> FakeWidget:
            st.maybe_fail("get_config")
            return copy.deepcopy(st.config)

        def set_config(self, config: FakeWidget) -> None:
            st.maybe_fail("set_config")
            st.config = copy.deepcopy(config)

        def capture(self, kind: int) -> SimpleNamespace:
            st.maybe_fail("capture")
            st.n_captured += 1
            suffix = ".CR2" if st.settings()["imageformat"] == "RAW" else ".JPG"
            name = f"IMG_{st.n_captured:04d}{suffix}"
            data = st.make_raw(st.settings()) if st.make_raw else b"raw"
            st.card[f"/store_00020001/DCIM/100CANON/{name}"] = data
            return SimpleNamespace(folder="/store_00020001/DCIM/100CANON", name=name)

        def file_get(self, folder: str, name: str, kind: int) -> SimpleNamespace:
            st.maybe_fail("file_get")
            data = st.card[f"{folder}/{name}"]
            return SimpleNamespace(save=lambda p: Path(p).write_bytes(data))

        def file_delete(self, folder: str, name: str) -> None:
            st.maybe_fail("file_delete")
            del st.card[f"{folder}/{name}"]

        def wait_for_event(self, timeout_ms: int) -> tuple[int, Any]:
            st.calls.append("wait_for_event")
            return (0, None)

    return SimpleNamespace(
        GPhoto2Error=FakeGPhoto2Error,
        Camera=Camera,
        PortInfoList=PortInfoList,
        CameraAbilitiesList=CameraAbilitiesList,
        GP_CAPTURE_IMAGE=0,
        GP_FILE_TYPE_NORMAL=1,
        GP_EVENT_TIMEOUT=0,
        state=st,
    )


def dng_raw_maker(tmp_dir: Path) -> Callable[[dict[str, str]], bytes]:
    """``make_raw`` that returns a small CFA DNG tagged with the camera's settings."""
    from tunespec.devices.canon.gphoto2_camera import parse_shutter_speed
    from tunespec.devices.dng import write_dng

    rng = np.random.default_rng(0)

    def make(settings: dict[str, str]) -> bytes:
        mosaic = rng.integers(2048, 15000, (64, 96)).astype(np.uint16)
        path = write_dng(
            tmp_dir / "fake_frame.dng",
            mosaic,
            exposure_s=parse_shutter_speed(settings["shutterspeed"]),
            iso=int(settings["iso"]) if settings["iso"].isdigit() else None,
            make="Canon",
            model="Canon EOS 5D Mark III",
        )
        return path.read_bytes()

    return make
