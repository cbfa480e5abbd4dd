"""Progress and cancellation hooks for long-running functions.

A long-running function takes ``progress: ProgressFn | None`` (called with a fraction
in [0, 1]) and ``should_stop: StopFn | None``, and raises :class:`Cancelled` when
``should_stop()`` turns true.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

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


def sub_progress(
    progress: ProgressFn | None, start: float, stop: float
) -> ProgressFn | None:
    """``progress`` for a part of a job that runs from ``start`` to ``stop`` of it.

    The one place progress is sub-ranged: a step reporting 0..1 is mapped linearly
    onto ``[start, stop]`` of the caller's bar. ``None`` stays ``None``.

    Examples
    --------
    >>> seen = []
    >>> sub_progress(seen.append, 0.5, 0.75)(0.5)
    >>> seen
    [0.625]
    """
    if progress is None:
        return None
    width = stop - start

    def sub(fraction: float) -> None:
        report(progress, start + width * fraction)

    return sub


def progress_ranges(weights: Mapping[str, float]) -> dict[str, tuple[float, float]]:
    """The ``(start, stop)`` range of every named part, in proportion to ``weights``.

    Examples
    --------
    >>> progress_ranges({"a": 1.0, "b": 3.0})
    {'a': (0.0, 0.25), 'b': (0.25, 1.0)}
    """
    total = float(sum(weights.values()))
    out: dict[str, tuple[float, float]] = {}
    acc = 0.0
    for name, w in weights.items():
        out[name] = (acc / total, (acc + w) / total)
        acc += w
    return out
