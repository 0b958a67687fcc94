"""Spill files: arrays a run sets aside on disk until it needs them again.

A spill folder is a temporary folder of one run (removed when the run ends, also on
error), in ``parent`` when given (a checkpoint folder, or dask's ``temporary-directory``),
otherwise in ``TMPDIR``; each spill is an uncompressed ``.npz`` of arrays, written atomically, so a
file that exists is complete. A folder's name holds the process id and host of its run
(``orokit-spill-PID@HOST-XXXXXXXX``), and the run holds the folder's lock while it lives, so a later run
can remove the folders of a run that was killed (:func:`remove_stale_folders`).
"""
from __future__ import annotations

import logging
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, cast

import numpy as np

from orokit._typing import PathLike
from orokit.errors import OutputError
from orokit.io.atomic import atomic_path, hold_run_path, is_no_space_error, remove_unless_held

logger = logging.getLogger(__name__)

__all__ = ["take_spill", "spill_folder", "SpillFolder", "remove_folder", "remove_stale_folders", "run_tag", "run_ended", "on_this_host", "may_remove",
           "write_spill", "read_spill", "SpilledColumns"]

#: name prefixes of the temporary folders of a run (spills of the chunk tasks, the peak table's columns)
SPILL_PREFIX, COLUMNS_PREFIX = "orokit-spill-", "orokit-columns-"


def run_tag() -> str:
    """``PID@HOST-``: the part of a temporary name that names the run's process (the spill and column
    folders after their prefix, a checkpoint's temporary chunk files after ``.tmp-``)."""
    import os
    import socket

    return f"{os.getpid()}@{socket.gethostname()}-"


def run_ended(owner: str) -> bool:
    """True when ``owner`` (``PID@HOST``: :func:`run_tag` without its dash) names a process that is not running
    on this host, or is not of that form (a name made before names held the process); False for a running
    process or another host's."""
    pid, at, _ = owner.partition("@")
    if at and pid.isdigit():
        return on_this_host(owner) and not _alive(int(pid))
    return True


def on_this_host(owner: str) -> bool:
    """True when ``owner`` (``PID@HOST``) names a process of this host, running or not."""
    import socket

    pid, at, where = owner.partition("@")
    return bool(at) and pid.isdigit() and where == socket.gethostname()


def may_remove(path: PathLike, owner: str, remove: Callable[[Path], None] | None = None) -> bool:
    """Remove the temporary ``path`` of the run ``owner`` names (``PID@HOST``) if that run has ended; True
    when removed.

    A run holds its paths' locks while it lives (:func:`~orokit.io.atomic.hold_run_path`), and the kernel
    lets them go however it ends. A name of this host is therefore removed when no process holds its lock,
    even when its process id runs: another process got the id (a container's rerun is often PID 1 again, as
    the killed run was) or it is of another PID namespace. Where the filesystem refuses such locks, the name
    decides (:func:`run_ended`); another host's names are left (a filesystem exported to it does not show
    its locks here).
    """
    ended = run_ended(owner)
    if not (ended or on_this_host(owner)):
        return False
    return remove_unless_held(path, remove, lock_required=not ended)


def _make_folder(prefix: str, parent: PathLike | None) -> tuple[Path, int | None]:
    """A new folder of this run and the descriptor that holds its lock (:func:`~orokit.io.atomic.hold_run_path`)."""
    if parent is not None:
        Path(parent).mkdir(parents=True, exist_ok=True)
    for attempt in range(100):
        folder = Path(tempfile.mkdtemp(prefix=prefix + run_tag(), dir=parent))
        try:
            return folder, hold_run_path(folder)
        except FileNotFoundError:  # a cleaner removed it before it was locked: another one
            remove_folder(folder, attempts=1)  # (if it is still there)
            if attempt == 99:
                raise
    raise AssertionError("unreachable")


def _remove_and_close(folder: str, fd: int | None) -> None:
    """Remove a run's folder, then let its lock go."""
    import os

    try:
        remove_folder(folder)
    finally:
        if fd is not None:
            os.close(fd)


def _alive(pid: int) -> bool:
    import os

    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def remove_stale_folders(parent: PathLike) -> list[Path]:
    """Remove the spill and column folders in ``parent`` whose run has ended without removing them
    (a killed process: SIGKILL, out of memory, power loss); returns the folders removed.

    A folder is stale when no process holds its lock and its name is of this host (:func:`may_remove`;
    where the filesystem has no such locks: its name's process id is not running on this host), or its name
    holds no process id (made before names held one). A folder of another host, or that a process holds, is
    left alone; nothing else in ``parent`` (a checkpoint's chunk files) is touched.
    """
    root = Path(parent)
    if not root.is_dir():
        return []
    removed = []
    for folder in sorted(root.iterdir()):
        prefix = next((p for p in (SPILL_PREFIX, COLUMNS_PREFIX) if folder.name.startswith(p)), None)
        if prefix is None or not folder.is_dir():
            continue
        if may_remove(folder, folder.name[len(prefix):].rpartition("-")[0], remove_folder):
            removed.append(folder)
    if removed:
        logger.info("removed %d temporary folders left in %s by runs that were killed", len(removed), root)
    return removed


class SpillFolder:
    """A new temporary folder (in ``parent``, made if missing, else ``TMPDIR``) for the spills of one
    run, removed by :meth:`close`, when the object is garbage-collected, or at exit (see
    :func:`remove_folder`): its files can outlive the call that made them (the chunked engine's
    settled isolation, read by the isolation search after the engine returned)."""

    def __init__(self, prefix: str = SPILL_PREFIX, parent: PathLike | None = None) -> None:
        import weakref

        self.path, held = _make_folder(prefix, parent)
        self._finalizer = weakref.finalize(self, _remove_and_close, str(self.path), held)

    def close(self) -> None:
        """Remove the folder and its files."""
        self._finalizer()


@contextmanager
def spill_folder(prefix: str = SPILL_PREFIX, parent: PathLike | None = None) -> Iterator[Path]:
    """A new temporary folder (in ``parent``, made if missing, else ``TMPDIR``) for the spills of
    one run, removed on exit (see :func:`remove_folder`)."""
    owner = SpillFolder(prefix, parent)
    try:
        yield owner.path
    finally:
        owner.close()


def remove_folder(folder: PathLike, attempts: int = 20) -> None:
    """Remove ``folder`` and its files; never raises (it runs while the run's error is raised).

    After an error, dask's local schedulers let the tasks already running finish: one may add a
    file between the removal's listing and its ``rmdir`` ("directory not empty", which replaced the
    run's own error); the removal is then tried again (``attempts`` times, 50 ms apart), and a
    later write finds no folder (:func:`write_spill` does not make it again). A folder still
    there after the last attempt is named in a logged warning (it is never left silently).
    """
    import shutil
    import time

    for _ in range(attempts):
        shutil.rmtree(folder, ignore_errors=True)
        if not Path(folder).exists():
            return
        time.sleep(0.05)
    logger.warning("could not remove the temporary folder %s (%d attempts); delete it by hand to free its space",
                   folder, attempts)


def write_spill(path: PathLike, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` to ``path`` (an ``.npz``) atomically, without fsync (the file is temporary).

    Raises
    ------
    OutputError
        The disk of the spill folder is full (``TMPDIR``'s or the given parent's, not the output's).
    FileNotFoundError
        The folder is gone: its run ended (a task the scheduler left running after an
        error or Ctrl-C writes nothing, rather than making the folder again).
    """
    try:
        with atomic_path(path, fsync=False, parents=False) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **cast("dict[str, Any]", arrays))
    except OSError as exc:
        if not is_no_space_error(exc):
            raise
        raise OutputError(f"no space left on {Path(path).parent} for the run's temporary spill files ({exc}); "
                          "free some space there, or set TMPDIR (or dask's temporary-directory) to a folder with "
                          "room, and run again") from None


def read_spill(path: PathLike, names: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The arrays written by :func:`write_spill` (never unpickled): all, or only ``names``."""
    with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
        return {k: data[k] for k in (data.files if names is None else names)}


def take_spill(path: PathLike) -> dict[str, np.ndarray]:
    """:func:`read_spill` of every array, then the file removed (a spill read once, by its one consumer)."""
    data = read_spill(path)
    Path(path).unlink()
    return data


class SpilledColumns:
    """Whole columns set aside in a temporary folder and read back by ranges of rows.

    A table's columns that are read only block by block (the peak table's while its files are
    written) wait on disk instead of in memory. ``put(name, values)`` writes one 1-D array
    (raw bytes, no header); ``rows(name, start, stop)`` reads ``values[start:stop]`` into a new
    array (plain reads, no memory map: nothing stays resident). The folder (in ``parent`` when
    given, made if missing, else ``TMPDIR``) is removed by :meth:`close`, when the object is
    garbage-collected, or at exit. Safe to read from several threads.
    """

    def __init__(self, parent: PathLike | None = None, prefix: str = COLUMNS_PREFIX) -> None:
        import weakref

        self.folder, held = _make_folder(prefix, parent)
        self._columns: dict[str, tuple[Path, np.dtype, int]] = {}
        self._finalizer = weakref.finalize(self, _remove_and_close, str(self.folder), held)

    def __contains__(self, name: str) -> bool:
        return name in self._columns

    def __len__(self) -> int:
        return len(self._columns)

    def put(self, name: str, values: np.ndarray) -> None:
        """Set aside the 1-D array ``values`` as column ``name`` (replacing one of that name).

        Raises
        ------
        OutputError
            The disk of the folder is full.
        """
        values = np.ascontiguousarray(values)
        if values.ndim != 1 or values.dtype.hasobject:
            raise ValueError(f"column {name!r}: a 1-D array of numbers is needed, got {values.dtype} {values.shape}")
        path = self.folder / f"{len(self._columns):04d}.bin"
        if name in self._columns:
            path = self._columns[name][0]
        try:
            with open(path, "wb") as fh:
                values.tofile(fh)
        except OSError as exc:
            if not is_no_space_error(exc):
                raise
            raise OutputError(f"no space left on {self.folder.parent} for the run's temporary column files ({exc}); "
                              "free some space there, or set TMPDIR (or dask's temporary-directory) to a folder "
                              "with room, and run again") from None
        self._columns[name] = (path, values.dtype, int(values.size))

    def size(self, name: str) -> int:
        """Number of values of column ``name``."""
        return self._columns[name][2]

    def rows(self, name: str, start: int, stop: int) -> np.ndarray:
        """Values ``start:stop`` of column ``name`` (clipped to the column), as a new array."""
        path, dtype, n = self._columns[name]
        start, stop = max(0, int(start)), min(n, int(stop))
        count = max(0, stop - start)
        if not count:
            return np.empty(0, dtype)
        return np.fromfile(path, dtype=dtype, count=count, offset=start * dtype.itemsize)

    def column(self, name: str) -> np.ndarray:
        """The whole column ``name``."""
        return self.rows(name, 0, self.size(name))

    def close(self) -> None:
        """Remove the folder and its files (the columns can no longer be read)."""
        self._finalizer()
        self._columns.clear()
