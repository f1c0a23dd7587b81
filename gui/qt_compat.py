"""Work around a PySide6 reference-count bug that aborts the process.

With PySide6 6.12.0 on Python < 3.12, every ``Signal.emit()`` called from Python
drops one reference to ``True`` that it never took. After a few thousand emits
(the worker's progress, every decision) CPython deallocates ``True`` and aborts
with "Fatal Python error: bool_dealloc". Python 3.12+ makes ``True`` immortal, and
PySide6 6.11 does not have the bug. When the bug is detected, ``True`` and
``False`` get an enormous reference count so that the lost references never
reach zero. Nothing else changes; the check costs a few microseconds.
"""

from __future__ import annotations

import ctypes
import sys

_PROTECTION = 1 << 40
_applied = False


def leaks_true_on_emit() -> bool:
    from PySide6.QtCore import QObject, Signal

    class _Probe(QObject):
        ping = Signal()

    probe = _Probe()
    before = sys.getrefcount(True)
    for _ in range(8):
        probe.ping.emit()
    return sys.getrefcount(True) < before


def protect_bools() -> bool:
    """Apply the workaround if this PySide6 needs it; True when applied."""
    global _applied
    if _applied or sys.version_info >= (3, 12) or sys.implementation.name != "cpython":
        return _applied
    if leaks_true_on_emit():
        for obj in (True, False):
            # ob_refcnt is the first field of every CPython object (release builds).
            ctypes.c_ssize_t.from_address(id(obj)).value += _PROTECTION
        _applied = True
    return _applied
