"""Settled isolation spilled to disk by the chunk tasks: the same result as carried up the merges."""
from __future__ import annotations

import tempfile
from pathlib import Path

import dask.array as da
import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

import orokit
import orokit.tiling.engine as te
from orokit.metrics.isolation import KernelMetric
from orokit.tiling.isolation import SettledIsolation

from helpers.outputs import assert_same_table_files

GRIDS = {
    "projected": (Affine(30.0, 0.0, 500000.0, 0.0, -30.0, 4000000.0), CRS.from_epsg(32633)),
    "geographic": (Affine(0.001, 0.0, 10.0, 0.0, -0.001, 46.0), CRS.from_epsg(4326)),
}


def _grid():
    rng = np.random.default_rng(11)
    z = np.round(rng.normal(size=(90, 110)).cumsum(0) + rng.normal(size=(90, 110)) * 2, 1)
    z[40:44, 50:57] = np.nan  # a void across a chunk corner
    return z


def _gathered(settled):
    """Every band of a spilled ``SettledIsolation`` in one dict of arrays."""
    assert isinstance(settled, SettledIsolation)
    return te._merge_iso([settled.read(b) for b in range(len(settled.bands))])


def _by_key(iso, cells):
    """The settled isolation of the peaks at ``cells``, ordered by cell, candidates trimmed to used columns."""
    sel = np.isin(iso["key"], cells)
    order = np.argsort(iso["key"][sel])
    out = {f: v[sel][order] for f, v in iso.items()}
    c = out["cand"]
    out["cand"] = c[:, :int((c >= 0).sum(axis=1).max(initial=0))]
    return out


@pytest.mark.parametrize("grid", GRIDS)
def test_spilled_settled_isolation_equals_the_carried_one(grid, tmp_path, monkeypatch):
    transform, crs = GRIDS[grid]
    z = _grid()
    metric = KernelMetric.from_grid(transform, crs)
    data = da.from_array(z, chunks=(17, 23))  # 6 x 5 chunks
    carried_parts = []
    real_merge = te._merge_task

    def merge(a, b, eps, **kw):
        carried_parts.extend([a[1], b[1]])
        return real_merge(a, b, eps, **kw)

    monkeypatch.setattr(te, "_merge_task", merge)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    spilled = te.tiled_orometry(data, min_prominence_m=1.0, scheduler="synchronous", isolation_metric=metric)
    assert len(carried_parts) == 2 * 29 and all(p is None for p in carried_parts)  # nothing travelled
    # the spill files stay for the isolation search, which reads them by rows of chunks
    (folder,) = tmp_path.iterdir()
    assert len(list(folder.iterdir())) == 30 and len(spilled.chunk_isolation.bands) == 6
    settled = _gathered(spilled.chunk_isolation)
    spilled.chunk_isolation.close()
    assert list(tmp_path.iterdir()) == []  # closed: the spill folder is gone
    carried_parts.clear()
    monkeypatch.setattr(te, "_same_disk", lambda scheduler: False)
    carried = te.tiled_orometry(data, min_prominence_m=1.0, scheduler="synchronous", isolation_metric=metric)
    assert any(p is not None for p in carried_parts)
    a, b = spilled.orometry, carried.orometry
    for f in ("peak_cell", "prominence", "key_saddle_cell", "parent", "prominence_exact", "ridge_saddle_cell"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    np.testing.assert_array_equal(spilled.chunk_stats, carried.chunk_stats)
    cells = a.peak_cell
    assert cells.size > 50
    # both may hold candidates the finalize dropped (the search leaves them out): the kept peaks' rows compared
    assert np.isin(carried.chunk_isolation["key"], settled["key"]).all()
    got, want = _by_key(settled, cells), _by_key(carried.chunk_isolation, cells)
    assert got["key"].size > 20
    for f in got:
        np.testing.assert_array_equal(got[f], want[f], err_msg=f)


def test_the_finalize_puts_the_columns_the_search_does_not_read_in_the_store(tmp_path):
    """With a column store the chunked engine's finalize writes the result's columns the isolation search
    does not read as it makes them (the result keeps empty arrays): the same values as without a store."""
    from orokit.errors import TilingError
    from orokit.io.spill_io import SpilledColumns
    from orokit.topology.engine import SPILLED_OROMETRY

    data = da.from_array(_grid(), chunks=(17, 23))
    plain = te.tiled_orometry(data, min_prominence_m=1.0, scheduler="synchronous").orometry
    store = SpilledColumns(parent=tmp_path)
    got = te.tiled_orometry(data, min_prominence_m=1.0, scheduler="threads", store=store).orometry
    assert plain.n_kept > 50 and got.n_kept == plain.n_kept
    np.testing.assert_array_equal(got.peak_cell, plain.peak_cell)
    np.testing.assert_array_equal(got.peak_z, plain.peak_z)
    for f in SPILLED_OROMETRY:
        assert getattr(got, f).size == 0 and getattr(got, f).dtype == getattr(plain, f).dtype, f
        np.testing.assert_array_equal(store.column(f), getattr(plain, f), err_msg=f)
    with pytest.raises(TilingError, match="in this process"):  # a worker process would fill a copy of it
        te.tiled_orometry(data, min_prominence_m=1.0, scheduler="processes", store=store)
    store.close()


def test_dasks_configured_process_scheduler_gets_no_column_store(make_dem, tmp_path):
    """``scheduler=None`` is dask's default, which ``dask.config`` (e.g. ``DASK_SCHEDULER=processes``)
    replaces: the finalize then runs in a worker process and must not get the caller's store (before: it
    filled a copy, the caller's columns stayed empty and ``orokit analyze --chunks`` failed with
    "operands could not be broadcast together")."""
    import dask

    assert te.in_process(None) and te.in_process("threads") and not te.in_process("processes")
    with dask.config.set(scheduler="processes"):
        assert not te.in_process(None)
    with dask.config.set(scheduler="synchronous"):
        assert te.in_process(None)
    dem = make_dem(_grid(), res=(30.0, 30.0))
    a = orokit.analyze(dem, min_prominence_m=1.0, geometry=False, isolation=False)
    with dask.config.set(scheduler="processes"):
        b = orokit.analyze(dem, min_prominence_m=1.0, chunks=(40, 40), geometry=False, blocks=True,
                           isolation=False)
    b.attrs = dict(a.attrs)
    orokit.write_analysis(a, tmp_path / "a")
    orokit.write_analysis(b, tmp_path / "b")
    assert_same_table_files(tmp_path / "a", tmp_path / "b")


def test_chunked_analysis_with_spill_writes_the_in_memory_files(make_dem, tmp_path, monkeypatch):
    """Many chunks, isolation on, a void: the tables' files are the in-memory run's, byte for byte;
    while the isolation search runs, the engine output's columns it does not read are on disk."""
    import gc

    import orokit.tiling.isolation as ti
    from orokit.topology.engine import SPILLED_OROMETRY, Orometry

    z = _grid()
    dem = make_dem(z, res=(30.0, 30.0))
    a = orokit.analyze(dem, min_prominence_m=1.0, geometry=False)
    held = []
    real_isolation = ti.tiled_isolation
    # only the chunked run's own engine output counts: the in-memory run's (or an earlier test's in this
    # worker) may still wait for the cycle collector; those alive are kept here so no new one takes their id
    gc.collect()
    earlier = [o for o in gc.get_objects() if isinstance(o, Orometry)]
    earlier_ids = {id(o) for o in earlier}

    def isolation(*args, **kwargs):
        cores = [o for o in gc.get_objects() if isinstance(o, Orometry) and id(o) not in earlier_ids]
        held.append(sum(getattr(c, f).size for c in cores for f in SPILLED_OROMETRY))
        return real_isolation(*args, **kwargs)

    monkeypatch.setattr(ti, "tiled_isolation", isolation)
    b = orokit.analyze(dem, min_prominence_m=1.0, chunks=(13, 16), geometry=False, blocks=True, scheduler="threads")
    assert held == [0]  # prominences, key saddles, parents, flags and ridges wait in the column store
    assert b.attrs["engine"] == "tiled" and b.peaks["isolation"].notna().sum() > 50
    b.attrs = dict(a.attrs)  # the same metadata (engine, timings)
    orokit.write_analysis(a, tmp_path / "a")
    orokit.write_analysis(b, tmp_path / "b")
    assert_same_table_files(tmp_path / "a", tmp_path / "b")


def test_reused_checkpoint_chunks_spill_their_isolation(make_dem, tmp_path):
    z = _grid()
    dem = make_dem(z)
    ck = tmp_path / "ck"
    a = orokit.analyze(dem, min_prominence_m=1.0, chunks=30, checkpoint=ck, scheduler="synchronous")
    b = orokit.analyze(dem, min_prominence_m=1.0, chunks=30, checkpoint=ck, scheduler="synchronous")  # all reused
    for c in ("isolation", "isolation_row", "isolation_col", "isolation_exact"):
        np.testing.assert_array_equal(a.peaks[c].to_numpy(), b.peaks[c].to_numpy(), err_msg=c)
    # the tables above would be equal without any settled isolation (the search finds it again):
    # the reused chunks' settled isolation itself is read back
    metric = KernelMetric.from_grid(*GRIDS["projected"])
    data = da.from_array(z, chunks=(17, 23))
    ck = tmp_path / "ck2"
    fresh = te.tiled_orometry(data, min_prominence_m=1.0, scheduler="synchronous", isolation_metric=metric,
                              checkpoint=ck)
    reused = te.tiled_orometry(data, min_prominence_m=1.0, scheduler="synchronous", isolation_metric=metric,
                               checkpoint=ck)
    cells = fresh.orometry.peak_cell
    got, want = _by_key(_gathered(reused.chunk_isolation), cells), _by_key(_gathered(fresh.chunk_isolation), cells)
    assert want["key"].size > 20
    for f in want:
        np.testing.assert_array_equal(got[f], want[f], err_msg=f)


def test_a_spill_after_its_run_ended_writes_nothing(tmp_path):
    """A chunk task the scheduler left running after an error or Ctrl-C must not make the removed spill
    folder again (it would stay in TMPDIR)."""
    from orokit.io.spill_io import read_spill, spill_folder, write_spill

    with spill_folder() as folder:
        write_spill(folder / "a.npz", {"key": np.arange(3)})
        assert read_spill(folder / "a.npz")["key"].tolist() == [0, 1, 2]
    assert not folder.exists()
    with pytest.raises(FileNotFoundError):
        write_spill(folder / "b.npz", {"key": np.arange(3)})
    assert not folder.exists()


@pytest.mark.parametrize("where", ["checkpoint", "dask-config"])
def test_spills_go_to_the_checkpoint_or_dask_temporary_directory(where, tmp_path, monkeypatch):
    """Not in TMPDIR when the user named a folder (TMPDIR is often RAM-backed): the checkpoint folder
    first, else dask's temporary-directory; the spill folder is removed at the end either way."""
    import dask

    z = _grid()
    metric = KernelMetric.from_grid(*GRIDS["projected"])
    data = da.from_array(z, chunks=(17, 23))
    tmpdir = tmp_path / "tmpdir"
    tmpdir.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmpdir))
    target = tmp_path / where
    written = []
    real_write = te.write_spill

    def write(path, arrays):
        written.append(path)
        real_write(path, arrays)

    monkeypatch.setattr(te, "write_spill", write)
    if where == "checkpoint":
        te.tiled_orometry(data, min_prominence_m=1.0, scheduler="synchronous", isolation_metric=metric,
                          checkpoint=target)
    else:
        with dask.config.set({"temporary-directory": str(target)}):
            te.tiled_orometry(data, min_prominence_m=1.0, scheduler="synchronous", isolation_metric=metric)
    # the 30 chunks' settled isolation, and the merges of an eighth of the raster or more their summaries
    assert sum(Path(p).name.startswith("iso_") for p in written) == 30
    assert sum(Path(p).name.startswith("summary_") for p in written) == 10
    assert all(target in Path(p).parents for p in written)
    assert list(tmpdir.iterdir()) == []
    assert not any(p.name.startswith("orokit-spill-") for p in target.iterdir())


def test_a_late_spill_during_the_removal_does_not_hide_the_run_error(tmp_path, monkeypatch):
    """After an error, a chunk task dask left running may add a file while the spill folder is being
    removed (after the listing, before the rmdir): the run's own error is raised, and the folder goes."""
    import errno
    import shutil

    from orokit.io.spill_io import spill_folder

    real = shutil.rmtree
    calls = []

    def racing(path, *args, **kwargs):
        calls.append(path)
        if len(calls) > 1:
            return real(path, *args, **kwargs)
        for p in Path(path).iterdir():
            p.unlink()
        (Path(path) / "late.npz.tmp").write_bytes(b"x")  # a late task's write, before the rmdir
        err = OSError(errno.ENOTEMPTY, "Directory not empty", str(path))
        if kwargs.get("ignore_errors"):
            return None
        raise err

    monkeypatch.setattr(shutil, "rmtree", racing)
    with pytest.raises(ValueError, match="the run's error"):
        with spill_folder(parent=tmp_path) as folder:
            (folder / "a.npz").write_bytes(b"a")
            raise ValueError("the run's error")
    assert len(calls) >= 2 and not folder.exists()


def test_a_folder_that_cannot_be_removed_is_named_in_a_warning(tmp_path, monkeypatch, caplog):
    """The removal never raises, but a spill folder it could not remove is not left silently."""
    import logging
    import shutil

    from orokit.io.spill_io import spill_folder

    monkeypatch.setattr(shutil, "rmtree", lambda *args, **kwargs: None)  # e.g. a file held open elsewhere
    with caplog.at_level(logging.WARNING, logger="orokit.io.spill_io"):
        with spill_folder(parent=tmp_path) as folder:
            (folder / "a.npz").write_bytes(b"a")
    assert folder.exists()
    assert any(str(folder) in r.getMessage() and r.levelno == logging.WARNING for r in caplog.records)


_KILLED_RUN = """
import os, signal, sys
import orokit, orokit.tiling.engine as te, orokit.tiling.isolation as ti
tif, ck, where = sys.argv[1:]
if where == "merge":  # in the chunk pass: some chunks finished, the spill folder full
    real, count = te._merge_task, []
    def merge(*a, **k):
        count.append(1)
        if len(count) == 6:
            os.kill(os.getpid(), signal.SIGKILL)
        return real(*a, **k)
    te._merge_task = merge
elif where == "write":  # in the chunk pass, while a chunk file is written: its temporary file half full
    import numpy as np
    real_savez, count = np.savez, []
    def savez(fh, **arrays):
        count.extend([1] if "/.chunk_" in str(getattr(fh, "name", "")) else [])
        if len(count) == 6:
            fh.write(b"PK" * 1000)
            fh.flush()
            os.kill(os.getpid(), signal.SIGKILL)
        return real_savez(fh, **arrays)
    np.savez = savez
else:  # in the isolation search: every chunk finished, the column store written
    ti.tiled_isolation = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)
orokit.analyze(tif, min_prominence_m=1.0, chunks=(13, 16), geometry=False, blocks=True, checkpoint=ck,
               scheduler="synchronous")
"""


@pytest.mark.parametrize("where, same_pid", [("merge", False), ("write", False), ("isolation", False),
                                             ("write", True)])
def test_a_rerun_after_a_killed_checkpoint_run_removes_its_folders_and_keeps_its_chunks(where, same_pid, make_dem,
                                                                                       tmp_path):
    """A run killed (SIGKILL) in the chunk pass (between chunks, or while a chunk file is written) or the
    isolation search leaves its spill and column folders, and the temporary file of the chunk being written, in
    the checkpoint folder; the rerun removes them, reuses the finished chunks (their files untouched) and
    writes the files of a run without a checkpoint. ``same_pid``: the rerun has the killed run's process id
    (a container's PID 1 both times; here its leftovers are renamed to the rerun's id)."""
    import gc
    import os
    import re
    import subprocess
    import sys

    z = _grid()
    tif = tmp_path / "d.tif"
    make_dem(z, res=(30.0, 30.0)).rio.to_raster(tif)
    ck = tmp_path / "ck"
    child = subprocess.run([sys.executable, "-c", _KILLED_RUN, str(tif), str(ck), where], capture_output=True)
    assert child.returncode == -9, child.stderr.decode()[-2000:]
    left = sorted(p.name.split("-")[1] for p in ck.iterdir() if p.name.startswith("orokit-"))
    # the column store exists from the start of the chunk pass (the finalize fills it), the spill folder until
    # the isolation search has read it
    assert left == ["columns", "spill"]
    assert len(list(ck.glob(".chunk_*.tmp-*"))) == (1 if where == "write" else 0)
    if same_pid:
        for p in [*ck.glob("orokit-*"), *ck.glob(".chunk_*.tmp-*")]:
            p.rename(p.with_name(re.sub(r"\d+@", f"{os.getpid()}@", p.name, count=1)))
    chunks = {p: p.stat().st_mtime_ns for p in ck.glob("chunk_*.npz")}
    assert len(chunks) >= (7 * 7 if where == "isolation" else 5)
    b = orokit.analyze(str(tif), min_prominence_m=1.0, chunks=(13, 16), geometry=False, blocks=True, checkpoint=ck,
                       scheduler="synchronous")
    mine = f"{os.getpid()}@"  # the rerun's own column store, alive with its result
    assert [p.name.split("-")[1] for p in ck.iterdir() if p.name.startswith("orokit-")] == ["columns"]
    assert not list(ck.glob(".*"))  # no temporary chunk file left
    assert all(mine in p.name for p in ck.iterdir() if p.name.startswith("orokit-"))
    assert all(p.stat().st_mtime_ns == t for p, t in chunks.items())  # reused, not written again
    a = orokit.analyze(str(tif), min_prominence_m=1.0, chunks=(13, 16), geometry=False, blocks=True,
                       scheduler="synchronous")
    b.attrs = dict(a.attrs)
    orokit.write_analysis(a, tmp_path / "a")
    orokit.write_analysis(b, tmp_path / "b")
    assert_same_table_files(tmp_path / "a", tmp_path / "b")
    del b
    gc.collect()
    assert not [p for p in ck.iterdir() if p.name.startswith("orokit-")]


def test_only_the_folders_of_ended_runs_on_this_host_are_stale(tmp_path):
    import os
    import socket
    import subprocess
    import sys

    from orokit.io.spill_io import SpilledColumns, remove_stale_folders, spill_folder

    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead = int(ended.stdout)
    host = socket.gethostname()
    names = {f"orokit-spill-{dead}@{host}-abc": False, f"orokit-columns-{dead}@{host}-x_1": False,
             "orokit-spill-k2j4h_9q": False,  # named before names held the process
             f"orokit-spill-{dead}@other.host-abc": True,
             # a running process's id, but no process holds it: an earlier run with this id (a container's
             # rerun is often PID 1 again, as the killed run was) or another PID namespace's
             f"orokit-columns-{os.getpid()}@{host}-abc": False,
             "orokit-mosaic-abc": True, "chunk_00000_00000.npz": True}
    for name in names:
        (tmp_path / name).mkdir()
        (tmp_path / name / "0000.bin").write_bytes(b"1")
    (tmp_path / "orokit-spill-file").write_bytes(b"1")  # a file, not a folder
    removed = remove_stale_folders(tmp_path)
    assert sorted(p.name for p in removed) == sorted(n for n, kept in names.items() if not kept)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*(n for n, k in names.items() if k), "orokit-spill-file"])
    with spill_folder(parent=tmp_path) as live:  # this run's own folders are named by its process
        store = SpilledColumns(parent=tmp_path)
        assert live.name.startswith(f"orokit-spill-{os.getpid()}@{host}-")
        assert store.folder.name.startswith(f"orokit-columns-{os.getpid()}@{host}-")
        assert remove_stale_folders(tmp_path) == [] and live.exists() and store.folder.exists()
    assert remove_stale_folders(tmp_path / "missing") == []


def test_opening_a_checkpoint_removes_the_temporary_chunk_files_of_ended_runs_only(tmp_path):
    import os
    import socket
    import subprocess
    import sys

    from orokit.io.checkpoint_io import chunk_path, open_checkpoint, write_chunk

    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead, host = int(ended.stdout), socket.gethostname()
    fingerprint = {"input": "x", "chunks": [13, 16]}
    open_checkpoint(tmp_path, fingerprint)
    names = {f".chunk_00001_00002.npz.tmp-{dead}@{host}-0123456789ab.npz": False,
             ".chunk_00000_00001.npz.tmp-0123456789ab.npz": False,  # named before names held the process
             f".checkpoint.json.tmp-{dead}@{host}-0123456789ab.json": False,
             f".chunk_00002_00002.npz.tmp-{os.getpid()}@{host}-0123456789ab.npz": False,  # held by none
             f".chunk_00003_00002.npz.tmp-{dead}@other.host-0123456789ab.npz": True,
             f".notes.txt.tmp-{dead}@{host}-0123456789ab.txt": True}  # not the checkpoint's own
    for name in names:
        (tmp_path / name).write_bytes(b"PK")
    write_chunk(chunk_path(tmp_path, 0, 0), {"a": np.arange(3)})
    assert open_checkpoint(tmp_path, fingerprint) == tmp_path
    kept = sorted(n for n, k in names.items() if k)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*kept, "checkpoint.json", "chunk_00000_00000.npz"])



def test_a_checkpoint_of_another_run_says_what_differs(tmp_path):
    """The refusal names the fingerprint's keys that differ (before: only "different input, chunks or
    threshold", which left a user guessing; session 18 saw it once after an interrupted run)."""
    from orokit.errors import TilingError
    from orokit.io.checkpoint_io import open_checkpoint

    open_checkpoint(tmp_path, {"graph": "read_dem-a", "chunks": [[16]], "min_prominence_m": 30.0})
    with pytest.raises(TilingError, match=r"another run .*graph, min_prominence_m differ\); use a new folder"):
        open_checkpoint(tmp_path, {"graph": "read_dem-b", "chunks": [[16]], "min_prominence_m": 10.0})


_HOLD = """
import fcntl, os, sys
path = sys.argv[1]
fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY if os.path.isdir(path) else os.O_RDWR)
fcntl.flock(fd, fcntl.LOCK_EX)  # as the run that made it holds it
print("held", flush=True)
sys.stdin.read()  # until the test closes the pipe
"""


@pytest.mark.parametrize("pid", ["ended", "running"])
def test_a_live_runs_folder_or_temporary_file_is_kept_whatever_its_name_says(pid, tmp_path):
    """A name whose process looks ended on this host (a run in another PID namespace with the same host name,
    e.g. a container on the host's network) is removed only when no process holds the path's lock: before,
    the name alone decided and a running run's spill folder or chunk file went. A name whose process id runs
    is removed once no process holds it (before: kept for good, e.g. a killed container run's as PID 1, rerun
    as PID 1)."""
    import os
    import socket
    import subprocess
    import sys

    from orokit.io.checkpoint_io import open_checkpoint
    from orokit.io.spill_io import remove_stale_folders

    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead, host = int(ended.stdout) if pid == "ended" else os.getpid(), socket.gethostname()
    fingerprint = {"input": "x", "chunks": [13, 16]}
    open_checkpoint(tmp_path, fingerprint)
    folder = tmp_path / f"orokit-spill-{dead}@{host}-abc"
    folder.mkdir()
    (folder / "iso_00000_00000.npz").write_bytes(b"PK")
    temp = tmp_path / f".chunk_00001_00002.npz.tmp-{dead}@{host}-0123456789ab.npz"
    temp.write_bytes(b"PK")
    holders = [subprocess.Popen([sys.executable, "-c", _HOLD, str(p)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                text=True) for p in (folder, temp)]
    try:
        assert [h.stdout.readline().strip() for h in holders] == ["held", "held"]
        assert remove_stale_folders(tmp_path) == []
        open_checkpoint(tmp_path, fingerprint)
        assert folder.is_dir() and (folder / "iso_00000_00000.npz").exists() and temp.exists()
    finally:
        for h in holders:
            h.communicate("")
    assert remove_stale_folders(tmp_path) == [folder]  # their process ended: the kernel let the locks go
    open_checkpoint(tmp_path, fingerprint)
    assert not folder.exists() and not temp.exists()


def test_a_runs_own_folders_and_chunk_temporaries_are_held_while_it_writes(tmp_path, monkeypatch):
    """The spill and column folders are locked from their making to their removal, a chunk's temporary file
    from before its first byte to its rename (so a cleaner in another PID namespace cannot take them)."""
    import numpy as np

    import orokit.io.atomic as atomic
    from orokit.io.checkpoint_io import chunk_path, write_chunk
    from orokit.io.spill_io import SpilledColumns, spill_folder

    def locked(path) -> bool:
        fd = atomic._open_to_lock(Path(path))
        try:
            return atomic._try_lock(fd) is False
        finally:
            atomic.os.close(fd)

    with spill_folder(parent=tmp_path) as live:
        store = SpilledColumns(parent=tmp_path)
        assert locked(live) and locked(store.folder)
        store.close()
    seen = []
    real_savez = np.savez

    def savez(fh, **arrays):
        seen.append(locked(fh.name))
        return real_savez(fh, **arrays)

    monkeypatch.setattr(np, "savez", savez)
    write_chunk(chunk_path(tmp_path, 0, 0), {"a": np.arange(3)})
    assert seen == [True] and not locked(chunk_path(tmp_path, 0, 0))


def test_making_a_held_path_gives_up_rather_than_loop(tmp_path, monkeypatch):
    """A path that never reads as the one locked (its inode seen to change every time) ends in an error after a
    bounded number of attempts, leaving nothing behind (not an endless loop)."""
    import orokit.io.atomic as atomic
    from orokit.io.spill_io import spill_folder

    monkeypatch.setattr(atomic, "_same_file", lambda fd, path: False)
    with pytest.raises(FileNotFoundError):
        with spill_folder(parent=tmp_path):
            pass
    with pytest.raises(FileNotFoundError):
        with atomic.atomic_path(tmp_path / "x.npz", lock=True) as tmp:
            tmp.write_bytes(b"x")
    assert list(tmp_path.iterdir()) == []
