"""Outputs survive concurrent writers, full disks, Ctrl-C and killed runs (issue 15).

Every writing command locks its output for the whole run, removes the temporary files an
interrupted run left for it, and replaces the previous output only once the new one is
complete. Tests go through the CLI (CliRunner, or a subprocess where a second process or a
signal is needed).
"""
from __future__ import annotations

import errno
import fcntl
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from orokit.cli.main import cli
from orokit.errors import OutputError
from orokit.io.atomic import Staging, lock_path_for, output_lock, remove_stale_temps, staged_folder

ANALYSIS = ["peaks.csv", "peaks.parquet", "saddles.parquet", "dividetree.gpkg", "analysis.json"]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _leftovers(*folders: Path) -> list[str]:
    """Hidden temporary files / folders / locks in ``folders``."""
    return sorted(p.name for f in folders if f.is_dir() for p in f.iterdir() if p.name.startswith("."))


@pytest.fixture()
def dem_tif(tmp_path, make_dem):
    rng = np.random.default_rng(3)
    z = np.cumsum(np.cumsum(rng.normal(size=(40, 50)), 0), 1) * 5 + 1000
    path = tmp_path / "dem.tif"
    make_dem(z.astype("float32")).rio.to_raster(path)
    return path


@pytest.fixture()
def dem_tif_b(tmp_path, make_dem):
    rng = np.random.default_rng(4)
    z = np.cumsum(np.cumsum(rng.normal(size=(30, 30)), 0), 1) * 5 + 500
    path = tmp_path / "dem_b.tif"
    make_dem(z.astype("float32")).rio.to_raster(path)
    return path


def _analyze(dem: Path, out: Path, *extra: str):
    return CliRunner().invoke(cli, ["analyze", str(dem), "-o", str(out), "--no-progress",
                                    "--min-prominence", "5", *extra])


class _OtherProcessLock:
    """The output lock held by another process (a real one: flock is per process here)."""

    def __init__(self, target: Path):
        code = textwrap.dedent(f"""
            import sys
            from orokit.io.atomic import output_lock
            with output_lock({str(target)!r}):
                print("locked", flush=True)
                sys.stdin.read()
        """)
        self.proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     text=True)
        assert self.proc.stdout.readline().strip() == "locked"

    def release(self):
        self.proc.stdin.close()
        assert self.proc.wait(timeout=60) == 0
        self.proc.stdout.close()  # no unclosed pipe (ResourceWarning is an error in the test suite)


# --- locks ------------------------------------------------------------------------------

def test_lock_is_refused_while_another_process_holds_it_and_leaves_no_file(tmp_path):
    out = tmp_path / "out"
    other = _OtherProcessLock(out)
    try:
        with pytest.raises(OutputError, match="being written by another orokit process.*pid"):
            with output_lock(out):
                pass
    finally:
        other.release()
    assert not lock_path_for(out).exists()  # the holder removed its lock file
    with output_lock(out):
        with output_lock(out):  # re-entrant within one process
            assert lock_path_for(out).exists()
    assert list(tmp_path.iterdir()) == []  # no zero-byte lock file after a clean run


def test_lock_survives_a_holder_removing_the_file_between_open_and_flock(tmp_path):
    """A stale lock file (a killed holder) does not block; the lock is the flock, not the file."""
    out = tmp_path / "out"
    lock_path_for(out).write_text("pid 999999: killed run")
    with output_lock(out):
        pass
    assert not lock_path_for(out).exists()


def test_concurrent_analyze_into_one_folder_is_refused(tmp_path, dem_tif, dem_tif_b):
    out = tmp_path / "out"
    assert _analyze(dem_tif, out).exit_code == 0
    before = _snapshot(out)
    other = _OtherProcessLock(out)  # another orokit process is writing `out`
    try:
        res = _analyze(dem_tif_b, out, "--overwrite")
    finally:
        other.release()
    assert res.exit_code == 1, res.output
    assert "being written by another orokit process" in res.output and str(out) in res.output
    assert "Traceback" not in res.output
    assert _snapshot(out) == before  # the finished analysis is intact
    # once the other run is over, the overwrite goes through, and leaves no lock or temp file
    assert _analyze(dem_tif_b, out, "--overwrite").exit_code == 0
    assert _snapshot(out) != before
    assert _leftovers(out, tmp_path) == []


@pytest.mark.parametrize("command", ["type", "features"])
def test_single_file_commands_take_the_lock(tmp_path, dem_tif, command):
    out = tmp_path / ("t.json" if command == "type" else "f.parquet")
    other = _OtherProcessLock(out)
    try:
        res = CliRunner().invoke(cli, [command, str(dem_tif), "-o", str(out), "--z-units", "m"])
    finally:
        other.release()
    assert res.exit_code == 1 and "being written by another orokit process" in res.output, res.output
    assert not out.exists()


def test_library_write_takes_the_lock(tmp_path, make_dem):
    import orokit
    from orokit.analysis import write_analysis

    r = orokit.analyze(make_dem(np.arange(30.0).reshape(5, 6) % 7), min_prominence_m=0)
    out = tmp_path / "out"
    fd = os.open(lock_path_for(out), os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # another open file description: as another process
        with pytest.raises(OutputError, match="another orokit process"):
            write_analysis(r, out)
    finally:
        os.close(fd)
        lock_path_for(out).unlink()
    write_analysis(r, out)
    assert (out / "analysis.json").exists()
    assert _leftovers(out, tmp_path) == []


# --- stale temporary files ----------------------------------------------------------------

def test_rerun_removes_stale_temporary_files_of_the_same_output(tmp_path, dem_tif):
    out = tmp_path / "out"
    assert _analyze(dem_tif, out).exit_code == 0
    stale = [out / ".peaks.csv.tmp-0123456789ab.csv", out / ".dividetree.gpkg.tmp-ba9876543210.gpkg"]
    for p in stale:
        p.write_bytes(b"half")
    staging = tmp_path / ".out.tmp-aaaaaaaaaaaa"
    staging.mkdir()
    (staging / "peaks.csv").write_text("half")
    keep = [out / ".notes.txt", tmp_path / ".other.tmp-0123456789ab"]  # not ours
    for p in keep:
        p.write_text("keep")
    assert _analyze(dem_tif, out, "--overwrite").exit_code == 0
    assert not any(p.exists() for p in stale) and not staging.exists()
    assert all(p.exists() for p in keep)


def test_remove_stale_temps_only_for_given_names(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / ".dem.tif.tmp-0123456789ab.tif").write_bytes(b"x")
    (out / ".validation.json.tmp-0123456789ab.json").write_bytes(b"x")
    removed = remove_stale_temps(out, names=("dem.tif",))
    assert [p.name for p in removed] == [".dem.tif.tmp-0123456789ab.tif"]
    assert (out / ".validation.json.tmp-0123456789ab.json").exists()


# --- staged writes, disk full -------------------------------------------------------------

def _enospc_after(n_bytes: int):
    """A writer that writes ``n_bytes`` to its target, then fails as a full disk does."""

    def writer(obj, path, *args, **kwargs):
        with open(path, "wb") as fh:
            fh.write(b"\0" * n_bytes)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    return writer


def test_staged_folder_keeps_the_old_output_on_failure(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.txt").write_text("old a")
    (out / "done").write_text("old marker")
    with pytest.raises(OutputError, match=f"no space left on {out}"):
        with staged_folder(out, marker="done") as stage:
            (stage / "a.txt").write_text("new a")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert _snapshot(out) == {"a.txt": b"old a", "done": b"old marker"}
    assert _leftovers(tmp_path) == []
    with staged_folder(out, marker="done", stale=("b.txt",)) as stage:
        (stage / "a.txt").write_text("new a")
        (stage / "done").write_text("new marker")
    assert _snapshot(out) == {"a.txt": b"new a", "done": b"new marker"}


def test_staging_of_files_in_several_folders(tmp_path):
    a, b = tmp_path / "x" / "a.tif", tmp_path / "y" / "b.png"
    stage = Staging()
    stage.file(a).write_text("A")
    stage.file(b).write_text("B")
    assert not a.exists() and not b.exists()
    stage.commit()
    assert a.read_text() == "A" and b.read_text() == "B"
    assert _leftovers(a.parent, b.parent) == []


@pytest.mark.parametrize("n_bytes", [0, 4096])
def test_analyze_disk_full_keeps_previous_analysis(tmp_path, dem_tif, dem_tif_b, monkeypatch, n_bytes):
    import orokit.io.divide_tree_io as dtio

    out = tmp_path / "out"
    assert _analyze(dem_tif, out).exit_code == 0
    before = _snapshot(out)
    monkeypatch.setattr(dtio, "write_divide_tree_gpkg", _enospc_after(n_bytes))
    res = _analyze(dem_tif_b, out, "--overwrite")
    assert res.exit_code == 1
    assert f"no space left on {out.resolve()}" in res.output and "Traceback" not in res.output
    assert _snapshot(out) == before  # byte-identical
    assert _leftovers(out, tmp_path) == []


def test_analyze_full_temporary_folder_is_named_not_the_output(tmp_path, dem_tif, monkeypatch):
    """Chunked analyze spills settled isolation to TMPDIR: a full TMPDIR is reported there (the output's
    disk has room), without a traceback, and nothing is left in either folder."""
    import tempfile

    import orokit.io.spill_io as spill_io

    spills = tmp_path / "tmpdir"
    spills.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(spills))

    class _Full:  # a file on a full disk: every write fails
        def __init__(self, path, mode):
            self.fh = open(path, mode)

        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __getattr__(self, name):
            return getattr(self.fh, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    monkeypatch.setattr(spill_io, "open", _Full, raising=False)
    out = tmp_path / "out"
    res = _analyze(dem_tif, out, "--chunks", "16")
    assert res.exit_code == 1, res.output
    assert f"no space left on {spills}" in res.output and "TMPDIR" in res.output, res.output
    assert "Traceback" not in res.output and not out.exists()
    assert _leftovers(spills, tmp_path) == [] and list(spills.iterdir()) == []


def test_render_disk_full_keeps_previous_raster(tmp_path, monkeypatch):
    import orokit.io.raster_io as raster_io
    from orokit.topology.divide_tree import DivideTree

    tree = DivideTree.from_arrays([[1000.0, 1000.0, 600.0], [3000.0, 1000.0, 550.0]], [[2000.0, 1000.0, 450.0]],
                                  [[0, 1, 0]], crs=None, attrs={"extent": [0.0, 0.0, 4000.0, 2000.0]})
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(tree, gpkg)
    tif, png = tmp_path / "dem.tif", tmp_path / "hs.png"
    args = ["render", str(gpkg), "-o", str(tif), "--preview", str(png), "--resolution", "100m", "--no-erosion",
            "--seed", "1"]
    assert CliRunner().invoke(cli, args).exit_code == 0
    before = (tif.read_bytes(), png.read_bytes())
    # the raster is complete, the preview hits a full disk: neither old file may change
    monkeypatch.setattr(raster_io, "write_hillshade_png", _enospc_after(100))
    res = CliRunner().invoke(cli, args[:-1] + ["2", "--overwrite"])
    assert res.exit_code == 1 and "no space left on" in res.output and "Traceback" not in res.output, res.output
    assert (tif.read_bytes(), png.read_bytes()) == before
    assert _leftovers(tmp_path) == []


def test_render_checks_free_space_before_writing(tmp_path, monkeypatch):
    import shutil
    from collections import namedtuple

    from orokit.io.atomic import check_free_space

    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**9, 10**9 - 1000, 1000))
    with pytest.raises(OutputError, match=r"no space left on .*needs about 2.0 MB, 0.0 MB are free"):
        check_free_space(tmp_path / "x.tif", 2e6, what="x.tif")


def test_render_on_a_nearly_full_disk_names_its_raster_and_the_sizes(tmp_path, monkeypatch):
    """A 600 kB tmpfs: the message said '.r.tif.tmp-....tif needs about 1 MB, 1 MB are free' (the staged file's
    name, and sizes rounded to whole MB)."""
    import shutil
    from collections import namedtuple

    from orokit.io.divide_tree_io import write_divide_tree_gpkg
    from orokit.topology.divide_tree import DivideTree

    tree = DivideTree.from_arrays([[1000.0, 1000.0, 600.0], [3000.0, 1000.0, 550.0]], [[2000.0, 1000.0, 450.0]],
                                  [[0, 1, 0]], crs=None, attrs={"extent": [0.0, 0.0, 4000.0, 2000.0]})
    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(tree, gpkg)
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**9, 10**9 - 600_000, 600_000))
    out = tmp_path / "r.tif"
    res = CliRunner().invoke(cli, ["render", str(gpkg), "-o", str(out), "--resolution", "5m", "--no-erosion",
                                   "--seed", "1"])
    assert res.exit_code == 1, res.output
    assert "r.tif (8" in res.output and ".tmp-" not in res.output, res.output  # 800 x 400 cells: 2.2 MB
    assert "needs about 2.2 MB, 0.6 MB are free" in res.output, res.output
    assert not out.exists() and _leftovers(tmp_path) == []


# --- Ctrl-C ---------------------------------------------------------------------------------

@pytest.mark.parametrize("sig, swallow, status, word", [("SIGINT", False, 130, "interrupted"),
                                                          ("SIGTERM", False, 143, "terminated"),
                                                          ("SIGINT", True, 130, "interrupted")],
                         ids=["SIGINT", "SIGTERM", "SIGINT-swallowed"])
def test_signal_during_the_numba_stage_exits_cleanly(tmp_path, dem_tif, sig, swallow, status, word):
    """SIGINT (Ctrl-C) or SIGTERM (kill) arrives while the engine's numba kernels run (injected there, so the test is
    deterministic); the previous analysis stays and no temporary file is left. "swallowed": the injected wrapper
    catches the KeyboardInterrupt (as a finalizer or a worker thread might), so the run goes on; the signal was
    recorded, so nothing is replaced and the exit status still says "interrupted"."""
    out = tmp_path / "out"
    assert _analyze(dem_tif, out).exit_code == 0
    before = _snapshot(out)
    # patch every numba kernel the engine calls: the first one called sends the signal
    code = textwrap.dedent("""
        import os, signal, sys
        import orokit.topology._kernels as k
        import orokit.topology.engine as e
        fired = []
        def wrap(f):
            def g(*a, **kw):
                if not fired:
                    fired.append(1)
                    try:
                        os.kill(os.getpid(), getattr(signal, sys.argv[1]))
                        for _ in range(1000):  # the handler runs between bytecodes
                            pass
                    except KeyboardInterrupt:
                        if sys.argv[2] != "swallow":
                            raise
                return f(*a, **kw)
            return g
        for mod in (k, e):
            for n in dir(mod):
                f = getattr(mod, n)
                if hasattr(f, "py_func"):
                    setattr(mod, n, wrap(f))
        from orokit.cli.main import cli
        cli(sys.argv[3:])
    """)
    proc = subprocess.run([sys.executable, "-c", code, sig, "swallow" if swallow else "raise", "analyze",
                           str(dem_tif), "-o", str(out), "--overwrite", "--no-progress", "--min-prominence", "5"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == status, proc.stderr
    assert word in proc.stderr and "Traceback" not in proc.stderr
    assert _snapshot(out) == before
    assert _leftovers(out, tmp_path) == []


def test_waiting_lock_gets_it_once_the_holder_is_done(tmp_path):
    import threading

    log = tmp_path / "log.csv"
    other = _OtherProcessLock(log)
    threading.Timer(0.5, other.release).start()
    with output_lock(log, wait_s=60.0):  # would raise OutputError if the wait did not work
        assert lock_path_for(log).exists()
    assert not lock_path_for(log).exists()


def _refuse(monkeypatch, error: int, *, op: str):
    """``os.open`` (creating a lock file) or ``os.write`` (the holder's text) fails with ``error``."""
    real = getattr(os, op)

    def failing(*args, **kwargs):
        if op == "open" and str(args[0]).endswith(".lock") and args[1] & os.O_CREAT:
            raise OSError(error, os.strerror(error), str(args[0]))
        if op == "write" and args[1].startswith(b"pid "):
            raise OSError(error, os.strerror(error))
        return real(*args, **kwargs)

    monkeypatch.setattr(os, op, failing)


@pytest.mark.parametrize("error", [errno.EROFS, errno.EACCES])
def test_an_output_in_a_folder_that_cannot_be_written_is_named_with_the_fix(tmp_path, dem_tif, monkeypatch, error):
    """A read-only filesystem or a folder without write permission (before: a traceback from the lock's open)."""
    out = tmp_path / "out"
    _refuse(monkeypatch, error, op="open")
    res = _analyze(dem_tif, out)
    assert isinstance(res.exception, SystemExit) and res.exit_code == 1, res.output
    assert f"cannot write {out}: {os.strerror(error).lower()}" in res.output and "--output" in res.output
    assert not out.exists()


def test_an_output_folder_that_cannot_be_written_into_is_refused_before_the_work(tmp_path, dem_tif, monkeypatch):
    """`-o DIR` where DIR exists but refuses writes (a read-only mount point: its lock lies beside it, in a
    writable folder): refused at the start, naming DIR (before: the whole analysis ran, then a traceback from
    the commit's unlink)."""
    out = tmp_path / "out"
    assert _analyze(dem_tif, out).exit_code == 0
    before = {f.name: f.read_bytes() for f in out.iterdir()}
    real = os.access

    def access(path, mode, *args, **kwargs):
        return False if Path(path) == out and mode & os.W_OK else real(path, mode, *args, **kwargs)

    monkeypatch.setattr(os, "access", access)
    res = _analyze(dem_tif, out, "--overwrite")
    assert isinstance(res.exception, SystemExit) and res.exit_code == 1, res.output
    assert f"cannot write into {out}: permission denied" in res.output and "--output" in res.output
    assert "peaks with prominence" not in res.output  # refused before the analysis
    assert {f.name: f.read_bytes() for f in out.iterdir()} == before


def _refuse_files_in(monkeypatch, folder: Path, error: int) -> None:
    """Creating a file inside ``folder`` fails with ``error`` (a folder of a read-only mount)."""
    real = os.open

    def failing(path, flags, *args, **kwargs):
        if Path(path).parent == folder and flags & os.O_CREAT:
            raise OSError(error, os.strerror(error), str(path))
        return real(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", failing)


def test_a_refused_csv_names_the_csv_option(tmp_path, dem_tif, monkeypatch):
    """`compare --csv DIR/x.csv` where DIR refuses writes: the message names --csv, the option that gave the
    path (before: '-o/--output', which compare does not have)."""
    folder = tmp_path / "ro"
    folder.mkdir()
    _refuse_files_in(monkeypatch, folder, errno.EACCES)
    res = CliRunner().invoke(cli, ["compare", str(dem_tif), str(dem_tif), "--csv", str(folder / "x.csv"),
                                   "--no-progress"])
    assert isinstance(res.exception, SystemExit) and res.exit_code == 1, res.output
    assert f"cannot write {folder / 'x.csv'}: permission denied" in res.output
    assert "(--csv)" in res.output and "--output" not in res.output


def test_a_refused_checkpoint_folder_names_the_checkpoint_option(tmp_path, dem_tif, monkeypatch):
    """`analyze --checkpoint DIR` where DIR exists and refuses writes (its checkpoint.json's lock lies inside):
    the message names --checkpoint; a refused -o folder still names -o/--output."""
    ckpt = tmp_path / "ck"
    ckpt.mkdir()
    _refuse_files_in(monkeypatch, ckpt, errno.EROFS)
    res = _analyze(dem_tif, tmp_path / "out", "--chunks", "16", "--checkpoint", str(ckpt))
    assert isinstance(res.exception, SystemExit) and res.exit_code == 1, res.output
    assert "read-only file system" in res.output and str(ckpt) in res.output
    assert "(--checkpoint)" in res.output and "--output" not in res.output
    assert not (tmp_path / "out").exists()
    monkeypatch.undo()
    _refuse_files_in(monkeypatch, tmp_path, errno.EROFS)
    res = _analyze(dem_tif, tmp_path / "out2", "--chunks", "16", "--checkpoint", str(ckpt))
    assert res.exit_code == 1 and f"cannot write {tmp_path / 'out2'}" in res.output
    assert "(-o/--output)" in res.output and "--checkpoint" not in res.output


def test_a_checkpoint_on_a_read_only_file_system_is_one_line(tmp_path, dem_tif, monkeypatch):
    """Any write a read-only file system refuses (here the checkpoint folder's) ends in one line naming the
    path, exit 1 (before: a traceback)."""
    ckpt = tmp_path / "ck"
    real = os.mkdir

    def mkdir(path, *args, **kwargs):
        if Path(path) == ckpt:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(os, "mkdir", mkdir)
    res = _analyze(dem_tif, tmp_path / "out", "--chunks", "16", "--checkpoint", str(ckpt))
    assert isinstance(res.exception, SystemExit) and res.exit_code == 1, res.output
    assert f"cannot write {ckpt}: read-only file system" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "out").exists()


def test_a_full_disk_leaves_no_lock_file_behind(tmp_path, dem_tif, monkeypatch):
    """The lock's holder text cannot be written on a full disk: the lock still holds and its file goes at the
    end (before: ENOSPC there, the descriptor leaked and the empty lock file stayed)."""
    out = tmp_path / "out"
    _refuse(monkeypatch, errno.ENOSPC, op="write")
    with output_lock(out):
        assert lock_path_for(out).exists()
    assert _leftovers(tmp_path) == []
    assert _analyze(dem_tif, out).exit_code == 0
    assert _leftovers(tmp_path, out) == []
