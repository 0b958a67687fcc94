"""The process's own memory map, read from ``/proc`` (Linux), for :mod:`orokit.tiling.memory`."""
from __future__ import annotations

__all__ = ["read_self_smaps"]


def read_self_smaps() -> str:
    """Text of ``/proc/self/smaps`` (one block per mapping); ``""`` where there is none (not Linux).

    >>> isinstance(read_self_smaps(), str)
    True
    """
    try:
        with open("/proc/self/smaps") as f:
            return f.read()
    except OSError:
        return ""
