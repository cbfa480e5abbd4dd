"""A simulated goniometer: four rotation axes that move at once, with limits.

:class:`SimGoniometer` implements :class:`~tunespec.devices.goniometer.Goniometer`
in process (no transport): axes ``theta_i``, ``phi_i``, ``theta_r``, ``phi_r`` with
travel limits, a reference that ``home`` sets (moves before it are refused, as a
stage without reference would), position read-back with an optional repeatability
error, ``stop``, and a failure injected after a given number of moves (for the
kill-and-resume tests of a gonio session).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tunespec.devices.goniometer import ANGLE_AXES, AxisInfo, check_target
from tunespec.devices.protocols import (
    DeviceCommandError,
    DeviceConnectionError,
    DeviceIdentity,
)

__all__ = ["SimGoniometer"]

#: Travel of the simulated axes (degrees).
LIMITS_DEG = {"theta_i": (-90.0, 90.0), "phi_i": (-360.0, 360.0),
              "theta_r": (-90.0, 90.0), "phi_r": (-360.0, 360.0)}  # fmt: skip


class SimGoniometer:
    """An in-process goniometer (see the module docstring).

    Parameters
    ----------
    repeatability_deg
        Standard deviation of the position reached around the target.
    fail_after_moves
        Raise :class:`DeviceConnectionError` on this move (counting from 1), as a
        controller that loses power would; ``None`` never.
    seed
        Seed of the repeatability error.
    """

    def __init__(
        self,
        *,
        repeatability_deg: float = 0.0,
        fail_after_moves: int | None = None,
        seed: int = 0,
    ) -> None:
        self._pos = dict.fromkeys(ANGLE_AXES, 0.0)
        self._homed = False
        self._closed = False
        self._rng = np.random.default_rng(seed)
        self._sigma = float(repeatability_deg)
        self._fail_after = fail_after_moves
        #: Moves made (targets reached), in order.
        self.moves: list[dict[str, float]] = []

    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(
            "TuneSpec", "simulated goniometer", "SIM-GONIO", "1.0", "sim"
        )

    def axes(self) -> list[AxisInfo]:
        return [AxisInfo(n, "deg", *LIMITS_DEG[n]) for n in ANGLE_AXES]

    def home(self) -> None:
        self._check_open()
        self._pos = dict.fromkeys(ANGLE_AXES, 0.0)
        self._homed = True

    def is_homed(self) -> bool:
        return self._homed

    def move_to(self, targets: Mapping[str, float]) -> dict[str, float]:
        self._check_open()
        check_target(self.axes(), targets)
        if not self._homed:
            raise DeviceCommandError(
                "simulated goniometer: no reference position; home it first"
            )
        if self._fail_after is not None and len(self.moves) + 1 >= self._fail_after:
            self._closed = True
            raise DeviceConnectionError(
                "simulated goniometer: controller lost (injected)"
            )
        for name, value in targets.items():
            self._pos[name] = float(value) + self._sigma * float(
                self._rng.standard_normal()
            )
        self.moves.append(dict(targets))
        return dict(self._pos)

    def position(self) -> dict[str, float]:
        self._check_open()
        return dict(self._pos)

    def stop(self) -> None:
        """Moves are instantaneous: nothing is ever moving."""

    def close(self) -> None:
        self._closed = True

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceConnectionError("simulated goniometer: closed")
