"""Returning pages a phase no longer needs (``orokit.tiling.memory``)."""
from __future__ import annotations

import mmap
import os
import subprocess
import sys

import pytest

from orokit.io.procfs import read_self_smaps
from orokit.tiling.memory import _library_mappings, release_library_pages

CODE = """
import numba, numpy as np
from orokit.io.procfs import read_self_smaps
from orokit.tiling.memory import _library_mappings, release_library_pages

@numba.njit(cache=False)
def f(x):
    return x.sum() * 2

a = np.arange(10.0)
assert f(a) == 90.0
before = sum(rss for _, _, rss in _library_mappings("libllvmlite", read_self_smaps()))
dropped = release_library_pages("libllvmlite")
after = sum(rss for _, _, rss in _library_mappings("libllvmlite", read_self_smaps()))
assert f(a) == 90.0  # the loaded function runs
assert f(np.arange(4, dtype=np.int32)) == 12  # and LLVM compiles again: its pages come back
print(before, dropped, after)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/smaps is Linux's")
def test_library_pages_are_dropped_and_the_library_still_works():
    out = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, check=True)
    before, dropped, after = map(int, out.stdout.split())
    assert before > 1 << 20 and dropped > 1 << 20  # LLVM's compiler code: tens of MB
    assert after < before - dropped // 2


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/smaps is Linux's")
def test_mappings_with_private_pages_are_left_alone():
    # libpython's data segment is written (relocations, globals): never in the list
    with open("/proc/self/smaps") as f:
        text = f.read()
    written = set()
    start = None
    for line in text.splitlines():
        parts = line.split()
        if not parts[0].endswith(":"):
            start = int(parts[0].split("-")[0], 16) if len(parts) > 5 and "libpython" in parts[5] else None
        elif start is not None and parts[0] == "Private_Dirty:" and int(parts[1]):
            written.add(start)
    if not written:
        pytest.skip("no libpython with written pages in this process (a static interpreter)")
    assert not written & {s for s, _, _ in _library_mappings("libpython", read_self_smaps())}


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/smaps is Linux's")
def test_only_read_only_mappings_are_listed_whatever_the_path(tmp_path):
    """A writable private mapping whose pages are all clean is still left out (a thread could write one
    between the listing and the drop: the write would be lost); a path with a space is still found."""
    folder = tmp_path / "a folder"
    folder.mkdir()
    path = folder / "orokit-review-mapping.bin"
    path.write_bytes(bytes(range(256)) * 64)  # 4 pages
    with open(path, "rb") as f:
        ro = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    with open(path, "r+b") as f:
        cow = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_COPY)  # private, writable: rw-p
    try:
        assert sum(ro[::4096]) + sum(cow[::4096]) == 0  # every page read: resident and clean
        found = _library_mappings("orokit-review-mapping", read_self_smaps())
        assert len(found) == 1 and found[0][2] > 0
        assert found[0][1] - found[0][0] == len(ro)
    finally:
        ro.close()
        cow.close()


EVERY_FILE = """
import numba, numpy as np
from orokit.tiling.memory import release_library_pages

@numba.njit(cache=False)
def f(x):
    return x.sum() * 2

assert f(np.arange(10.0)) == 90.0
import json  # a module not loaded yet: its file is read after the drop
dropped = release_library_pages("")
assert f(np.arange(10.0)) == 90.0 and f(np.arange(4, dtype=np.int32)) == 12  # runs, and compiles again
print(dropped, json.dumps([float(np.sort(np.random.default_rng(0).random(1000))[0])]) != "")
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/smaps is Linux's")
def test_every_files_pages_are_dropped_and_the_process_goes_on():
    """``""``: every mapped file (what ``orokit analyze`` does between its phases)."""
    out = subprocess.run([sys.executable, "-c", EVERY_FILE], capture_output=True, text=True, check=True)
    dropped, ok = out.stdout.split()
    assert int(dropped) > 16 << 20 and ok == "True"  # numpy's, numba's, LLVM's, Python's code


def test_unknown_library():
    assert release_library_pages("no-such-library-here") == 0


ARENAS = """
import ctypes, sys, threading
import numpy as np
from orokit.tiling.memory import limit_malloc_arenas

if sys.argv[1] == "limit":
    assert limit_malloc_arenas(2)
keep, meet = [], threading.Barrier(6)

def work():
    keep.append(np.ones(1000))  # from this thread's arena (below the mmap threshold)
    meet.wait()  # all six alive at once: none reuses an arena another one left

threads = [threading.Thread(target=work) for _ in range(6)]
for t in threads:
    t.start()
for t in threads:
    t.join()
ctypes.CDLL(None).malloc_stats()  # one "Arena N:" block per arena, on stderr
"""


def _glibc() -> bool:
    import ctypes

    return sys.platform.startswith("linux") and hasattr(ctypes.CDLL(None), "gnu_get_libc_version")


@pytest.mark.skipif(not _glibc(), reason="mallopt(M_ARENA_MAX) and malloc_stats are glibc's")
def test_malloc_arenas_are_limited_in_the_process_that_asks():
    """Six threads allocating at once get arenas of their own; after limit_malloc_arenas(2), two in all
    (run in child processes: the setting holds for a whole process, so never in the test's own)."""
    def arenas(mode: str) -> int:
        out = subprocess.run([sys.executable, "-c", ARENAS, mode], capture_output=True, text=True, check=True)
        return sum(line.startswith("Arena ") for line in out.stderr.splitlines())

    assert arenas("default") > 2
    assert arenas("limit") == 2


def test_fix_mmap_threshold_maps_large_blocks_in_a_fresh_process():
    """After it, a freed block of some MB leaves no resident heap pages (glibc otherwise raises its
    threshold to the size of the first mapped block freed and serves the next ones from the heap).

    The blocks are larger than anything the interpreter's start-up frees, so the test block cannot be
    served from already resident free heap chunks (a 6 MB block once was, in a CI run under load). The
    children run without the environment's glibc malloc settings: any of ``MALLOC_TRIM_THRESHOLD_``,
    ``MALLOC_TOP_PAD_``, ``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_MMAP_MAX_`` (or their ``GLIBC_TUNABLES``) turns
    glibc's raised threshold off, so the default block is a mapping of its own too. dask.distributed's
    Nanny puts ``MALLOC_TRIM_THRESHOLD_=65536`` in its own process's environment for good: in the full
    suite, the xdist worker that had run ``tests/tiling/test_distributed.py`` passed it to these children."""
    code = """
import ctypes, sys
from orokit.tiling.memory import fix_mmap_threshold
if sys.argv[1] == "fix":
    assert fix_mmap_threshold(1 << 20)
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = [ctypes.c_size_t]
libc.free.argtypes = [ctypes.c_void_p]
libc.free(libc.malloc(30 << 20))  # mapped (above 128 kB); freeing it raises glibc's own threshold to 30 MB
def heap():
    kb, name, spans = 0, None, []
    with open("/proc/self/smaps") as f:
        for line in f:
            p = line.split()
            if not p[0].endswith(":"):
                name = p[5] if len(p) > 5 else ""
                if name == "[heap]":
                    spans.append(tuple(int(a, 16) for a in p[0].split("-")))
            elif p[0] == "Rss:" and name == "[heap]":
                kb += int(p[1])
    return kb, spans
before, _ = heap()
p = libc.malloc(24 << 20)
ctypes.memset(p, 1, 24 << 20)
in_heap = any(lo <= p < hi for lo, hi in heap()[1])
libc.free(p)
print(heap()[0] - before, int(in_heap))
"""
    if not sys.platform.startswith("linux"):
        pytest.skip("glibc and /proc only")
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"}
    runs = {mode: subprocess.run([sys.executable, "-c", code, mode], capture_output=True, text=True, env=env,
                                 check=True).stdout.split() for mode in ("default", "fix")}
    grown = {mode: int(kb) for mode, (kb, _) in runs.items()}
    in_heap = {mode: flag == "1" for mode, (_, flag) in runs.items()}
    # with the fix the block is its own mapping and nothing stays resident; without it glibc serves the
    # block from the heap and keeps its pages (what the fix is for)
    assert not in_heap["fix"] and grown["fix"] < 1 << 10
    assert in_heap["default"] and grown["default"] >= 20 << 10


def test_a_consuming_merge_hands_the_free_heap_back_after_each_large_field(monkeypatch):
    """The top merges' parts are freed field by field into the heap, whose pages stay resident beside the
    merged summary unless handed back: a consuming merge trims after every field of ``_TRIM_BYTES`` or more
    (here every field), and merges to the same summary as one that keeps its inputs."""
    import numpy as np

    import orokit.tiling.summary as ts

    rng = np.random.default_rng(3)
    z = np.pad(rng.normal(size=(40, 60)).cumsum(1), 1, constant_values=np.nan)
    shape = (40, 60)

    def halves():
        return (ts.chunk_summary(z[:, :32], 0, 0, shape, 0.5), ts.chunk_summary(z[:, 30:], 0, 30, shape, 0.5))

    kept = ts.merge_summaries(*halves(), 0.5, reduce=False)
    calls = []
    monkeypatch.setattr(ts, "release_free_heap", lambda: calls.append(1) or True)
    monkeypatch.setattr(ts, "_TRIM_BYTES", 0)
    a, b = halves()
    got = ts.merge_summaries(a, b, 0.5, consume=True, reduce=False)
    assert a.consumed and b.consumed and len(calls) == len(ts._FIELDS)
    assert got.n_nodes > 20
    for f in ts._FIELDS:
        np.testing.assert_array_equal(getattr(got, f), getattr(kept, f), err_msg=f)
    calls.clear()
    monkeypatch.setattr(ts, "_TRIM_BYTES", 1 << 40)
    ts.merge_summaries(*halves(), 0.5, consume=True, reduce=False)
    assert calls == []  # small fields: no trim
