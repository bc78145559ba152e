"""A guard against a reference-count bug of PySide6 6.12.0 on Python 3.11.

Measured here (PySide6-Essentials 6.12.0, CPython 3.11.7): emitting Qt signals to Python slots
and painting pyqtgraph items decrement the reference counts of ``True`` and ``None`` more often
than they increment them (``sys.getrefcount(True)`` falls by exactly one per ``emit``). pyqtgraph
emits signals on every ``setData`` and range change, so after a few seconds of redraws a count
reaches zero and the interpreter aborts ("Fatal Python error: bool_dealloc" or "none_dealloc",
exit code -6), during painting or in its final garbage collection. Python 3.12 made ``True``,
``False`` and ``None`` immortal, so the bug is harmless there.

Responsibility: :func:`guard_bool_refcounts` gives ``True``, ``False`` and ``None`` a reference
count so large (2**40) that the leak cannot reach zero in the life of a process: what CPython
3.12 does. It acts only on CPython < 3.12 with shiboken6 6.12.0 and is idempotent; remove this
module once the PySide6 pin excludes 6.12.0 (or requires Python >= 3.12).
"""

from __future__ import annotations

import ctypes
import sys

__all__ = ["guard_bool_refcounts"]

#: References added to True, False and None (CPython 3.12 immortal objects have about 2**32).
_EXTRA_REFS = 1 << 40


def _affected() -> bool:
    if sys.implementation.name != "cpython" or sys.version_info >= (3, 12):
        return False
    try:
        import shiboken6  # Qt's binding: loaded only where the guard is asked for
    except ImportError:
        return False
    return str(getattr(shiboken6, "__version__", "")).startswith("6.12.0")


def guard_bool_refcounts() -> bool:
    """Protect ``True``, ``False`` and ``None`` from PySide6 6.12.0's signal refcount leak.

    Returns
    -------
    bool
        True if the guard is active (applied now or before), False if this interpreter and
        Qt binding are not affected.
    """
    if not _affected():
        return False
    for obj in (True, False, None):
        refcount = ctypes.c_ssize_t.from_address(id(obj))  # ob_refcnt, the first field
        if refcount.value < _EXTRA_REFS:
            refcount.value += _EXTRA_REFS
    return True
