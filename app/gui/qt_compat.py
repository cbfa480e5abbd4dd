"""Work-arounds for bugs of the Qt binding, applied once when the GUI is imported.

PySide6 6.12.0 on CPython 3.11 returns ``None`` from every void method (``setText``,
``processEvents``, ``QTimer.start`` ...) and ``True`` from ``Signal.emit()`` without
taking a reference (found here: 100 ``setObjectName`` calls lower
``sys.getrefcount(None)`` by 100, 50 emits lower ``sys.getrefcount(True)`` by 50;
PySide6 6.11.3 does neither). Both are static singletons, so nothing is freed, but
once a count reaches zero CPython aborts with "Fatal Python error: none_dealloc" (or
"bool_dealloc") - after some thousands of calls, i.e. during a capture or at exit.
CPython 3.12 made these objects immortal, which hides the bug there; on 3.11
:func:`apply` does the same by hand when a probe shows the leak. The real fix is a
binding without the bug (``PySide6-Essentials != 6.12.0``, or Python >= 3.12).
"""

from __future__ import annotations

import ctypes
import logging
import sys

__all__ = ["apply", "leaked_singletons"]

log = logging.getLogger(__name__)

#: References added to a leaking singleton: more than any session can lose.
_IMMORTAL_REFS = 1 << 40
_applied = False


def leaked_singletons(n: int = 16) -> list[object]:
    """The singletons (``None``, ``True``) the binding loses references to."""
    from PySide6.QtCore import QObject, Signal

    class _Probe(QObject):
        probed = Signal()

    probe = _Probe()
    leaks: list[object] = []
    before = sys.getrefcount(None)
    for _ in range(n):
        probe.setObjectName("probe")  # a void method
    if sys.getrefcount(None) <= before - n // 2:
        leaks.append(None)
    before = sys.getrefcount(True)
    for _ in range(n):
        probe.probed.emit()
    if sys.getrefcount(True) <= before - n // 2:
        leaks.append(True)
    return leaks


def apply() -> bool:
    """Apply the work-arounds needed here; returns True if one was applied."""
    global _applied
    if _applied or sys.version_info >= (3, 12):
        return False
    leaks = leaked_singletons()
    if not leaks:
        return False
    for obj in {*leaks, False}:  # False shares True's code paths
        # ob_refcnt is the first field of every PyObject (CPython < 3.12 layout)
        ctypes.c_ssize_t.from_address(id(obj)).value += _IMMORTAL_REFS
    _applied = True
    import PySide6

    log.warning(
        "PySide6 %s loses references to %s; made them immortal as a work-around "
        "(use PySide6 != 6.12.0 or Python >= 3.12 to fix it)",
        PySide6.__version__,
        " and ".join(map(repr, leaks)),
    )
    return True


apply()
