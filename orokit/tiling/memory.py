"""Hand memory a phase no longer uses back to the operating system.

Chunk arrays (tens of MB) are freed inside glibc's heaps, which keep the pages: after
the chunk pass and the isolation search a process held ~150-200 MB of free heap that the
next phases (tables, writing) then counted on top of their own. ``malloc_trim(0)``
returns it (glibc only; elsewhere this does nothing). :func:`release_library_pages`
does the same for the code pages of a library that is done (numba's compiler, LLVM).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import functools
from typing import Any

__all__ = ["fix_mmap_threshold", "limit_gdal_cache", "limit_malloc_arenas", "release_free_heap", "release_library_pages"]

#: GDAL's block cache (bytes) of the ``orokit`` program (:func:`limit_gdal_cache`): by default GDAL caches up
#: to 5 % of the RAM, and a whole-raster read kept its blocks in the cache (+16-20 MB peak at 15.1 M cells)
GDAL_CACHE_BYTES = 32 * 2**20
#: GDAL's block cache (bytes) while ``orokit analyze`` reads a whole raster into memory: GDAL reads a
#: whole window without reading a block twice, so the cache only holds blocks already copied out (at
#: 15.1 M cells 32 MB of them at the read's end, the process's peak with the raster: measured, session 15);
#: reading with 4 MB took no more CPU (tiled and striped, plain and compressed GeoTIFFs)
GDAL_WHOLE_READ_CACHE_BYTES = 4 * 2**20
#: the value of ``GDAL_CACHEMAX`` :func:`limit_gdal_cache` put in the environment (None: not set by it)
_GDAL_CACHE_SET: dict[str, str | None] = {"value": None}


@functools.lru_cache(maxsize=None)
def _libc_function(name: str, restype: Any = None, argtypes: tuple[Any, ...] = ()) -> Any:
    """glibc's function ``name`` with its ctypes signature, or None where the C library has none."""
    lib = ctypes.util.find_library("c")
    try:
        fn = getattr(ctypes.CDLL(lib), name) if lib else None
    except (OSError, AttributeError):
        return None
    if fn is not None and argtypes:
        fn.restype, fn.argtypes = restype, list(argtypes)
    return fn


def _trim() -> Any:
    return _libc_function("malloc_trim")


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


#: ``madvise`` advice: the pages of the range are dropped (file pages are read back from the page cache on use)
_MADV_DONTNEED = 4


def _madvise() -> Any:
    return _libc_function("madvise", ctypes.c_int, (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int))


def _library_mappings(name: str, smaps: str) -> list[tuple[int, int, int]]:
    """(start, end, resident bytes) of the read-only mappings of files named ``*name*`` (``""``: every file)
    holding no private page.

    ``smaps``: the text of ``/proc/self/smaps``. A writable mapping is left out (a thread
    could write a page between this read and the drop, and the write would be lost), and
    so is one with a private (copy-on-write) page, e.g. relocated data: dropping it would
    lose what was written.

    >>> text = "1000-3000 r-xp 0 08:01 7 /lib/libx.so\\nRss: 8 kB\\nAnonymous: 0 kB\\nPrivate_Dirty: 0 kB\\n"
    >>> _library_mappings("libx", text)
    [(4096, 12288, 8192)]
    >>> _library_mappings("libx", text.replace("r-xp", "rw-p"))
    []
    >>> _library_mappings("", text), _library_mappings("", text.replace("/lib/libx.so", "[vdso]"))
    ([(4096, 12288, 8192)], [])
    """
    found: list[tuple[int, int, int]] = []
    current: list[int] | None = None  # start, end, rss, private pages
    for line in smaps.splitlines():
        parts = line.split(None, 5)
        if not parts:
            continue
        if not parts[0].endswith(":"):  # a mapping's header: "start-end perms offset dev inode [path]"
            if current is not None and current[2] and not current[3]:
                found.append((current[0], current[1], current[2]))
            path = parts[5] if len(parts) > 5 else ""
            start, end = parts[0].split("-")
            current = ([int(start, 16), int(end, 16), 0, 0]  # a file's mapping ([vdso] and such are not)
                       if path.startswith("/") and name in path.rsplit("/", 1)[-1] and "w" not in parts[1]
                       else None)
        elif current is not None and len(parts) > 1:
            if parts[0] == "Rss:":
                current[2] = int(parts[1]) * 1024
            elif parts[0] in ("Anonymous:", "Private_Dirty:"):
                current[3] += int(parts[1])
    if current is not None and current[2] and not current[3]:
        found.append((current[0], current[1], current[2]))
    return found


def release_library_pages(name: str) -> int:
    """Drop the resident pages of the shared library ``*name*`` (``""``: of every mapped file) that are copies
    of its file; bytes dropped.

    For a library whose work is done (numba's LLVM once the kernels are loaded: ~65 MB of
    code at 15 M cells), or every file between two phases (``orokit analyze`` before the engine
    and before writing: the code of the phases before is not read again, what the next phase
    runs comes back; -50 MB of the writing's peak at 15.1 M cells, session 15): the pages stay
    in the page cache and come back on their next use, so nothing changes but the process's
    resident set. Only read-only mappings are dropped (code, constants), never a page the
    process wrote. Linux only (elsewhere 0).

    >>> release_library_pages("no-such-library") == 0
    True
    """
    madvise = _madvise()
    if madvise is None:
        return 0
    from orokit.io.procfs import read_self_smaps

    dropped = 0
    for start, end, rss in _library_mappings(name, read_self_smaps()):
        if madvise(start, end - start, _MADV_DONTNEED) == 0:
            dropped += rss
    return dropped


#: ``mallopt`` parameters: the most malloc arenas glibc creates; the size from which a block is its own mapping
_M_ARENA_MAX = -8
_M_MMAP_THRESHOLD = -3


def _mallopt() -> Any:
    return _libc_function("mallopt", ctypes.c_int, (ctypes.c_int, ctypes.c_int))


def limit_malloc_arenas(n: int) -> bool:
    """Let glibc's malloc create at most ``n`` arenas from now on; True when it could be set (glibc only).

    glibc gives threads that allocate at once arenas of their own (up to 8 per core), each
    keeping its freed pages; in ``orokit analyze`` at 15 M cells (GDAL's reader, numba's
    loader, the writers' threads) that was ~15-20 MB of the peak (measured). It holds for the
    whole process: for a program's entry point (``orokit analyze``), never a library call.
    """
    mallopt = _mallopt()
    return mallopt is not None and bool(mallopt(_M_ARENA_MAX, int(n)))


def fix_mmap_threshold(nbytes: int) -> bool:
    """Make every malloc block of ``nbytes`` or more its own mapping, handed back when freed; True when it
    could be set (glibc only).

    glibc starts at 128 kB but raises the threshold to the size of each mapped block freed (up to
    32 MB), so after the first few the arrays of a few MB are served from the heap and their pages
    stay resident once freed, under the phases that follow. A fixed threshold keeps them mappings.
    For a program's entry point (``orokit analyze``), never a library call.
    """
    mallopt = _mallopt()
    return mallopt is not None and bool(mallopt(_M_MMAP_THRESHOLD, int(nbytes)))


def limit_gdal_cache(nbytes: int = GDAL_CACHE_BYTES) -> bool:
    """Bound GDAL's block cache to ``nbytes`` for the rest of the process; False (nothing done) when the
    user set ``GDAL_CACHEMAX`` (environment), which wins. A bound this function set may be changed by
    calling it again (``orokit analyze`` lowers it for a whole read in memory).

    ``GDAL_CACHEMAX`` is set in the environment (each GDAL of the process reads it when it first sizes
    its cache; rasterio is not imported for this) and, if rasterio is loaded already, given to its
    GDAL at once. The cache size is global to the process (GDAL has no per-thread or per-dataset
    size): for a program's entry point (``orokit analyze``: ``orokit.cli.main.apply_process_settings``),
    never a library call.
    """
    import os
    import sys

    if "GDAL_CACHEMAX" in os.environ and os.environ["GDAL_CACHEMAX"] != _GDAL_CACHE_SET["value"]:
        return False  # the user's (a value this function set before may be changed)
    os.environ["GDAL_CACHEMAX"] = _GDAL_CACHE_SET["value"] = str(int(nbytes))
    if "rasterio" in sys.modules:  # its cache may be sized already
        from rasterio.env import set_gdal_config

        set_gdal_config("GDAL_CACHEMAX", int(nbytes))
    return True
