"""Hand the heap that a chunked phase freed back to the operating system.

Chunk arrays (tens of MB) are freed inside glibc's heaps, which keep the pages: after
the chunk pass and the isolation search a process held ~150-200 MB of free heap that the
next phases (tables, writing) then counted on top of their own. ``malloc_trim(0)``
returns it (glibc only; elsewhere this does nothing).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import functools

__all__ = ["release_free_heap"]


@functools.lru_cache(maxsize=1)
def _trim():
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        return None


def release_free_heap() -> bool:
    """Return free heap pages to the OS (glibc ``malloc_trim``); True when it could run.

    >>> isinstance(release_free_heap(), bool)
    True
    """
    trim = _trim()
    if trim is None:
        return False
    trim(0)
    return True
