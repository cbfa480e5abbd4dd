"""Device protocols (what capture code may rely on) and the errors devices raise.

Devices are synchronous and blocking, owned by exactly one thread, and every call has
a timeout. Nothing here imports Qt. Messages of :class:`DeviceError` are written for
the operator: what failed, on which device, and what to check.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, Protocol, Self, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from tunespec.core.spectra import Spectra

__all__ = [
    "Camera",
    "Channel",
    "DeviceBusyError",
    "DeviceCommandError",
    "DeviceConnectionError",
    "DeviceError",
    "DeviceIdentity",
    "DeviceProtocolError",
    "DeviceTimeoutError",
    "LightSource",
    "LightStatus",
    "SimulatedCamera",
    "SimulatedStage",
    "TargetStage",
]


class ClosesOnExit:
    """``with device:`` closes it on leaving (the devices' ``close`` is idempotent)."""

    def close(self) -> None:  # pragma: no cover - every user defines it
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class DeviceError(Exception):
    """A device failed; the message tells the operator what to check."""


class DeviceTimeoutError(DeviceError, TimeoutError):
    """The device did not answer in time."""


class DeviceConnectionError(DeviceError, ConnectionError):
    """The device could not be opened, or the connection was lost."""


class DeviceProtocolError(DeviceError):
    """The device answered something that does not follow its protocol."""


class DeviceCommandError(DeviceError):
    """The device understood the command and refused it (an error reply)."""


class DeviceBusyError(DeviceError):
    """The device is in use by another program or busy with another operation."""


@dataclass(frozen=True)
class DeviceIdentity:
    """Who a device is, for the session manifest and the report."""

    vendor: str
    model: str
    serial: str
    firmware: str = ""
    spec: str = ""  # the spec string it was opened from, e.g. "cal1:///dev/ttyUSB0"


@dataclass(frozen=True)
class Channel:
    """One LED channel of a light source."""

    index: int
    name: str
    peak_nm: float
    kind: Literal["narrowband", "white"] = "narrowband"


@dataclass(frozen=True)
class LightStatus:
    """Light source status: temperature, warm-up, on-time, anything else in ``extra``."""

    ready: bool
    temperature_c: float = float("nan")
    on_time_s: float = 0.0
    message: str = ""
    extra: dict[str, str] = field(default_factory=dict)


@runtime_checkable
class LightSource(Protocol):
    """A spectrally tunable light source with an internal spectroradiometer.

    Blocking; not thread-safe: used from exactly one owner thread.
    """

    @property
    def identity(self) -> DeviceIdentity: ...

    def channels(self) -> list[Channel]:
        """The LED channels, in device order."""
        ...

    def set_levels(self, levels: NDArray[np.float64]) -> None:
        """Set every channel's level in [0, 1] (shape (n_channels,))."""
        ...

    def levels(self) -> NDArray[np.float64]:
        """The levels now set, shape (n_channels,)."""
        ...

    def all_off(self) -> None:
        """Switch every channel off."""
        ...

    def measure_spd(self) -> Spectra:
        """The SPD emitted now, as the internal spectroradiometer reports it.

        One spectrum named ``"measured"``, spectral radiance in W sr^-1 m^-2 nm^-1
        (the simulators use the same unit), on the spectroradiometer's wavelengths.
        """
        ...

    def status(self) -> LightStatus: ...

    def close(self) -> None:
        """Switch everything off and release the connection."""
        ...


@runtime_checkable
class Camera(Protocol):
    """A camera shooting raw frames to files. Blocking; one owner thread."""

    @property
    def identity(self) -> DeviceIdentity: ...

    @property
    def exposure_s(self) -> float: ...

    def set_exposure(self, exposure_s: float) -> None: ...

    @property
    def iso(self) -> int: ...

    def set_iso(self, iso: int) -> None: ...

    def capture(self, stem: Path) -> Path:
        """Expose one frame and write its raw file to ``stem`` + the camera's suffix.

        Returns the path written (``.dng`` for the simulator, ``.cr2`` for a Canon).
        The file is complete when this returns.
        """
        ...

    def close(self) -> None: ...


@runtime_checkable
class TargetStage(Protocol):
    """What is in front of the camera: the operator (hardware) or the simulated scene.

    ``present("white")`` asks for the white background, ``present("target")`` for the
    chart or sample target; it returns once it is in place.
    """

    def present(self, what: Literal["white", "target"]) -> None: ...


@runtime_checkable
class SimulatedStage(TargetStage, Protocol):
    """A simulated scene as the stage: it knows the bench it stands on.

    The simulator's side of a bench (``devices.sim.scene.SimScene``), reached through
    this protocol instead of casts (ophyd's ``SynGauss`` exposes its truth the same way).
    """

    def bench_options(self) -> dict[str, object]:
        """Arguments describing the bench (pose, field of view, light field, board)."""
        ...


@runtime_checkable
class SimulatedCamera(Camera, Protocol):
    """A simulated camera: a :class:`Camera` that also knows its truth.

    ``devices.sim.camera.SimCamera`` implements it; the pipeline scores a run
    against ``truth()`` and moves the same camera to another target with
    ``looking_at``.
    """

    @property
    def resolution(self) -> tuple[int, int]:
        """``(width, height)`` of the mosaic in pixels."""
        ...

    def looking_at(self, scene: Any, *, seed: int | None = None) -> SimulatedCamera:
        """The same camera facing another simulated scene."""
        ...

    def shading(self, xy_px: Any) -> NDArray[np.float64]:
        """Relative irradiance (fall-off x vignetting) at mosaic pixels ``(..., 2)``."""
        ...

    def truth(self) -> dict[str, Any]:
        """Everything the simulation was built with (sensitivities, corners, ...)."""
        ...

    def write_truth(self, folder: str | PathLike[str]) -> list[Path]:
        """Write the truth beside a run (CSV/JSON) and return the files."""
        ...
