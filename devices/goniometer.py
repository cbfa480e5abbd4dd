"""The goniometer: a device Protocol, the geometry it sets, and axis limits.

A gonio-imager measures a sample at several illumination and viewing geometries
``(theta_i, phi_i, theta_r, phi_r)`` (degrees; theta from the sample normal, phi the
azimuth). The goniometer sets them with motorised axes. What capture code may rely on
is :class:`Goniometer` (a small Protocol, as ``LightSource`` and ``Camera`` in
:mod:`tunespec.devices.protocols`): named axes with limits, homing, a blocking move with
position read-back, and stop. Implementations: the simulated goniometer
(:class:`tunespec.devices.sim.gonio.SimGoniometer`) and the Zaber ASCII driver
(:mod:`tunespec.devices.zaber`).

The axes used here are named after the angles they set (``theta_i``, ``phi_i``,
``theta_r``, ``phi_r``): one rotation stage per angle, as in a four-axis
gonioreflectometer (light arm, sample azimuth, camera arm, camera azimuth); a
driver's configuration maps each name to a stage.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from tunespec.core.errors import InputError
from tunespec.devices.protocols import DeviceIdentity

__all__ = [
    "ANGLE_AXES",
    "AxisInfo",
    "Geometry",
    "Goniometer",
    "check_target",
]

#: The four angles of a geometry, and the axis names that set them.
ANGLE_AXES = ("theta_i", "phi_i", "theta_r", "phi_r")


@dataclass(frozen=True)
class Geometry:
    """One illumination / viewing geometry, angles in degrees.

    ``theta_*`` in [0, 90) from the sample normal, ``phi_*`` in [-360, 360] azimuth.
    """

    theta_i: float
    phi_i: float
    theta_r: float
    phi_r: float

    def __post_init__(self) -> None:
        for name in ANGLE_AXES:
            v = getattr(self, name)
            if (
                not isinstance(v, int | float)
                or isinstance(v, bool)
                or not math.isfinite(v)
            ):
                raise InputError(
                    f"{name}: expected a finite angle in degrees, got {v!r}"
                )
            limit = (0.0, 89.9) if name.startswith("theta") else (-360.0, 360.0)
            if not limit[0] <= v <= limit[1]:
                raise InputError(
                    f"{name} = {v:g} deg outside {limit[0]:g}..{limit[1]:g}"
                )

    def as_dict(self) -> dict[str, float]:
        """``{"theta_i": ..., ...}``: the axis targets of a one-stage-per-angle gonio."""
        return {name: float(getattr(self, name)) for name in ANGLE_AXES}

    @property
    def label(self) -> str:
        """A file-name-safe label, e.g. ``ti45_pi0_tr0_pr0``."""
        return f"ti{self.theta_i:g}_pi{self.phi_i:g}_tr{self.theta_r:g}_pr{self.phi_r:g}".replace(
            "-", "m"
        ).replace(".", "p")


@dataclass(frozen=True)
class AxisInfo:
    """A motorised axis: its name, unit and travel limits (in that unit)."""

    name: str
    unit: str
    min: float
    max: float


@runtime_checkable
class Goniometer(Protocol):
    """Motorised axes that set a geometry. Blocking; one owner thread.

    Every method has a timeout; failures raise
    :class:`~tunespec.devices.protocols.DeviceError` subclasses with a message for the
    operator.
    """

    @property
    def identity(self) -> DeviceIdentity: ...

    def axes(self) -> list[AxisInfo]:
        """The axes, with their limits."""
        ...

    def home(self) -> None:
        """Home every axis (find the reference position); blocks until done."""
        ...

    def is_homed(self) -> bool:
        """Whether every axis has a reference position."""
        ...

    def move_to(self, targets: Mapping[str, float]) -> dict[str, float]:
        """Move the named axes to ``targets`` and wait; return the positions read back.

        Raises
        ------
        InputError
            Unknown axis or a target outside its limits (nothing moves).
        DeviceError
            The move failed, timed out (the axes are stopped) or ended elsewhere.
        """
        ...

    def position(self) -> dict[str, float]:
        """Every axis's position as read back from the device."""
        ...

    def stop(self) -> None:
        """Stop every axis now (decelerating)."""
        ...

    def close(self) -> None: ...


def check_target(axes: list[AxisInfo], targets: Mapping[str, float]) -> None:
    """InputError unless every target names an axis and lies within its limits."""
    by_name = {a.name: a for a in axes}
    for name, value in targets.items():
        if name not in by_name:
            raise InputError(
                f"unknown goniometer axis {name!r}; axes: {', '.join(by_name)}"
            )
        a = by_name[name]
        if not (isinstance(value, int | float) and math.isfinite(value)):
            raise InputError(f"axis {name}: target {value!r} is not a finite number")
        if not a.min <= value <= a.max:
            raise InputError(
                f"axis {name}: target {value:g} {a.unit} outside its limits "
                f"{a.min:g}..{a.max:g} {a.unit}"
            )
