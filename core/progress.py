"""Progress and cancellation hooks for long-running functions.

A long-running function takes ``progress: ProgressFn | None`` (called with a fraction
in [0, 1]) and ``should_stop: StopFn | None``, and raises :class:`Cancelled` when
``should_stop()`` turns true.
"""

from __future__ import annotations

from collections.abc import Callable

ProgressFn = Callable[[float], None]
StopFn = Callable[[], bool]


class Cancelled(Exception):
    """Raised by a long-running function when ``should_stop()`` returned true."""


def report(progress: ProgressFn | None, fraction: float) -> None:
    """Call ``progress(fraction)`` if a callback was given (fraction clipped to [0, 1])."""
    if progress is not None:
        progress(min(1.0, max(0.0, float(fraction))))


def check_stop(should_stop: StopFn | None) -> None:
    """Raise :class:`Cancelled` if ``should_stop`` says so."""
    if should_stop is not None and should_stop():
        raise Cancelled("cancelled by the operator")
