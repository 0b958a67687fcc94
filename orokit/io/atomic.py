"""Safe output: atomic files, a lock per output for a whole run, staged output sets.

Every orokit writer goes through :func:`atomic_path` (or the small wrappers below), so
an interrupted or failed write never leaves a half-written file under the final name
and an older file at that name stays intact until the new one is complete.

A command that writes several files uses :func:`output_lock` for its whole run (a
second writer of the same output fails at once with :class:`~orokit.errors.OutputError`),
removes what a killed run left with :func:`remove_stale_temps`, and writes through a
:class:`Staging`: every new file goes to a hidden temporary path (a folder output to a
hidden folder beside it) and replaces the old one only when all are complete, so a
failure (disk full, Ctrl-C) keeps the previous output byte-identical.
"""
from __future__ import annotations

import contextlib
import errno
import logging
import os
import shutil
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from orokit.errors import OrokitError, OutputError

if TYPE_CHECKING:  # orokit._typing imports numpy: not before the CLI's process settings (numpy's BLAS threads)
    from orokit._typing import PathLike

logger = logging.getLogger(__name__)

__all__ = ["atomic_path", "atomic_open", "write_text_atomic", "write_bytes_atomic", "temp_path_for",
           "output_lock", "lock_path_for", "remove_stale_temps", "Staging", "staged_folder", "is_no_space_error", "no_space_error",
           "check_free_space", "request_stop", "clear_stop", "stop_requested", "check_stop", "hold_run_path",
           "remove_unless_held"]

#: signals received by the running command and not yet acted on (set by the CLI's handlers): once one
#: is recorded, no output is replaced any more, even if the KeyboardInterrupt it raised was swallowed
#: on the way (e.g. inside a finalizer or a worker thread)
_STOP: list[int] = []


def request_stop(signum: int) -> None:
    """Record that the process received ``signum`` (SIGINT/SIGTERM): no output is committed after this."""
    _STOP.append(int(signum))


def clear_stop() -> None:
    """Forget recorded signals (at the start of a command)."""
    _STOP.clear()


def stop_requested() -> int | None:
    """The first signal recorded by :func:`request_stop`, or None."""
    return _STOP[0] if _STOP else None


def check_stop() -> None:
    """Raise KeyboardInterrupt if a stop was requested (called before any output is replaced).

    >>> clear_stop(); check_stop()  # nothing recorded: returns
    >>> request_stop(2)
    >>> try:
    ...     check_stop()
    ... except KeyboardInterrupt:
    ...     print("stopped")
    stopped
    >>> clear_stop()
    """
    if _STOP:
        raise KeyboardInterrupt(f"signal {_STOP[0]} received: outputs not replaced")


def temp_path_for(final_path: PathLike, tag: str = "") -> Path:
    """Return a unique temporary path in the directory of ``final_path``.

    The name keeps the final suffix (``.gpkg``, ``.tif``...) so format drivers that
    choose the format from the extension still work, and starts with a dot so the
    file is hidden while it is being written. ``tag`` goes before its random part
    (``.NAME.tmp-TAGxxxxxxxxxxxx.SUFFIX``), e.g. the run's ``PID@HOST-`` so a later run can
    tell a killed run's file from a running one's.
    """
    final = Path(final_path)
    return final.with_name(f".{final.name}.tmp-{tag}{uuid.uuid4().hex[:12]}{final.suffix}")


def _fsync_file(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - e.g. special files
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - filesystems without fsync
        pass
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # pragma: no cover - Windows cannot open directories
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


# --- a run's temporary paths: locked while the run lives -----------------------------------

def _try_lock(fd: int) -> bool | None:
    """``flock(fd, LOCK_EX | LOCK_NB)``: True taken, False held through another open file (a running
    process's, in any PID namespace of this machine), None when the filesystem refuses such locks."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - no flock on this platform
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError:  # e.g. NFS: no lock on a folder opened for reading (EBADF), or ENOLCK
        return None
    return True


def _open_to_lock(path: Path) -> int:
    if path.is_dir():
        return os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        return os.open(path, os.O_RDWR)  # NFS locks a file only if it is open for writing
    except PermissionError:
        return os.open(path, os.O_RDONLY)


def _same_file(fd: int, path: Path) -> bool:
    try:
        s = os.stat(path)
    except FileNotFoundError:
        return False
    f = os.fstat(fd)
    return (s.st_dev, s.st_ino) == (f.st_dev, f.st_ino)


def hold_run_path(path: PathLike, *, create: bool = False) -> int | None:
    """Lock ``path``, a temporary file or folder this run made (``create``: make the file), for as long as
    the returned descriptor stays open: close it once the path is removed or renamed (None: a folder this
    platform cannot open, not locked).

    The kernel drops the lock when the process ends, however it ends (SIGKILL, out of memory), so
    :func:`remove_unless_held` spares a running process's path whatever its host name or PID namespace
    says. Raises FileNotFoundError when a cleaner removed the path first (make another).
    """
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDWR | os.O_CREAT, 0o644) if create else _open_to_lock(p)
    except FileNotFoundError:
        raise
    except OSError:  # pragma: no cover - e.g. Windows opens no folder
        if create:
            raise
        return None
    try:
        if _try_lock(fd) is False or not _same_file(fd, p):  # a cleaner holds it, or removed it
            raise FileNotFoundError(errno.ENOENT, "removed while it was being made", str(p))
    except BaseException:
        os.close(fd)
        raise
    return fd


def remove_unless_held(path: PathLike, remove: Callable[[Path], None] | None = None, *,
                       lock_required: bool = False) -> bool:
    """Remove ``path``, a temporary file or folder whose name says its run ended, unless a process holds
    it (:func:`hold_run_path`); True when removed. ``remove`` removes it (default: file or folder tree).

    A name can be wrong about its run: the process id of another PID namespace (a container) with the same
    host name looks ended. Where the filesystem has no such locks (some network filesystems) the name decides,
    unless ``lock_required`` (the name says nothing: then only a lock taken removes it).
    """
    p = Path(path)
    try:
        fd = _open_to_lock(p)
    except OSError:  # gone already, or not ours to open
        return False
    try:
        taken = _try_lock(fd)
        if taken is False or (taken is None and lock_required):
            return False
        (_remove if remove is None else remove)(p)
        return True
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(final_path: PathLike, *, fsync: bool = True, parents: bool = True, tag: str = "",
                lock: bool = False) -> Iterator[Path]:
    """Yield a temporary path; on success move it to ``final_path`` atomically.

    Parameters
    ----------
    final_path
        Where the file should end up. Missing parent directories are created.
    fsync
        Flush the file (and then its directory) to disk before/after the rename.
    parents
        Create missing parent directories (False: a missing one is an error, e.g. a
        temporary folder a finished run has removed must not be made again).
    tag
        Put in the temporary name (:func:`temp_path_for`).
    lock
        Make the temporary file empty and hold its lock (:func:`hold_run_path`) until it is renamed or
        removed, so a cleaner never takes it for a killed run's (the writer overwrites it; an empty file
        counts as nothing written).

    Yields
    ------
    Path
        A unique, not yet existing path (with ``lock``: an empty file) in the same directory (same
        filesystem, so :func:`os.replace` is atomic on POSIX) with the same suffix as ``final_path``.

    Raises
    ------
    OrokitError
        If the body finished without creating the temporary file.

    Notes
    -----
    If the body raises, the temporary file (or directory) is removed, the exception
    propagates and an existing file at ``final_path`` is left untouched. A directory
    written at the temporary path replaces ``final_path`` only if ``final_path`` does
    not exist or is an empty directory (``os.replace`` semantics).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_path(d / "out.txt") as tmp:
    ...     _ = tmp.write_text("done")
    >>> (d / "out.txt").read_text()
    'done'
    """
    final = Path(final_path)
    if parents:
        final.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_path_for(final, tag)
    held = None
    try:
        for attempt in range(100 if lock else 0):
            try:
                held = hold_run_path(tmp, create=True)
                break
            except FileNotFoundError:  # again if a cleaner removed it before it was locked
                if not tmp.parent.is_dir() or attempt == 99:
                    raise
        yield tmp
        if not tmp.exists() or (held is not None and tmp.stat().st_size == 0):
            raise OrokitError(
                f"nothing was written for {final}: the writer did not create the temporary file {tmp.name}"
            )
        if fsync and tmp.is_file():
            _fsync_file(tmp)
        check_stop()
        os.replace(tmp, final)
        if fsync:
            _fsync_dir(final.parent)
        logger.debug("wrote %s", final)
    except BaseException:
        _remove(tmp)
        raise
    finally:
        if held is not None:
            os.close(held)


@contextlib.contextmanager
def atomic_open(final_path: PathLike, mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """Open a temporary file for writing; rename it to ``final_path`` on success.

    ``mode`` must be a write mode (``"w"``, ``"wb"``, ``"x"``...); other keyword
    arguments go to :func:`open` (e.g. ``encoding="utf-8"``, ``newline=""``).
    """
    if not any(c in mode for c in "wx"):
        raise ValueError(f"atomic_open needs a write mode ('w' or 'wb'), got mode={mode!r}")
    with atomic_path(final_path) as tmp:
        with open(tmp, mode, **kwargs) as fh:
            yield fh
            fh.flush()


def write_text_atomic(final_path: PathLike, text: str, *, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``final_path`` atomically and return the path."""
    with atomic_open(final_path, "w", encoding=encoding, newline="\n") as fh:
        fh.write(text)
    return Path(final_path)


def write_bytes_atomic(final_path: PathLike, data: bytes) -> Path:
    """Write ``data`` to ``final_path`` atomically and return the path."""
    with atomic_open(final_path, "wb") as fh:
        fh.write(data)
    return Path(final_path)


# --- locks --------------------------------------------------------------------------------

#: locks held by this process: lock file -> (fd, depth); a command that holds the lock of
#: its output may call library writers that take it again
_HELD: dict[Path, list[int]] = {}


def lock_path_for(target: PathLike) -> Path:
    """The lock file of an output (file or folder): hidden, beside it, ``.NAME.lock``."""
    t = Path(os.path.abspath(target))
    if not t.name:  # the filesystem root: its lock lies inside it
        return t / ".orokit.lock"
    return t.with_name(f".{t.name}.lock")


def _holder(lock: Path) -> str:
    try:
        text = lock.read_text(encoding="utf-8", errors="replace").strip()
    except OSError:
        return ""
    return f" ({text})" if text else ""


def _acquire(target: Path, wait_s: float = 0.0) -> Path:
    import fcntl
    import time

    lock = lock_path_for(target)
    held = _HELD.get(lock)
    if held is not None:
        held[1] += 1
        return lock
    deadline = time.monotonic() + wait_s
    while True:
        try:
            lock.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            if is_no_space_error(exc) or exc.errno not in (errno.EROFS, errno.EACCES, errno.EPERM):
                raise
            raise OutputError(
                f"cannot write {target}: {exc.strerror.lower() if exc.strerror else exc} in {lock.parent}; write "
                "to a folder you can write to", path=target
            ) from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            if time.monotonic() < deadline:
                time.sleep(0.05)
                continue
            raise OutputError(
                f"{target} is being written by another orokit process{_holder(lock)}; wait for it to finish, "
                f"or write to another output (if no orokit process is running, remove {lock})"
            ) from None
        try:  # the previous holder may have removed the file between our open and flock
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    import sys

    _HELD[lock] = [fd, 1]
    try:  # who holds it, for another run's message; on a full disk the lock holds without it
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()}: {' '.join(sys.argv[:3])}".encode())
    except OSError:
        pass
    return lock


def _release(lock: Path) -> None:
    held = _HELD.get(lock)
    if held is None:
        return
    held[1] -= 1
    if held[1] > 0:
        return
    del _HELD[lock]
    with contextlib.suppress(FileNotFoundError):
        lock.unlink()  # while still holding it: a waiting process re-checks the inode
    os.close(held[0])


@contextlib.contextmanager
def output_lock(*targets: PathLike | None, wait_s: float = 0.0) -> Iterator[None]:
    """Hold the lock of every output in ``targets`` (``None`` entries are skipped).

    ``wait_s``: how long to wait for another holder (default: fail at once).

    The lock is an exclusive ``flock`` on a hidden file beside each output
    (``.NAME.lock``), so it is released by the kernel even when the process is killed;
    the file is removed when the lock is released. Re-entrant within one process.

    Raises
    ------
    OutputError
        If another process holds the lock of one of them (nothing is waited for).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with output_lock(d / "out"):
    ...     (d / ".out.lock").exists()
    True
    >>> (d / ".out.lock").exists()
    False
    """
    taken: list[Path] = []
    try:
        for t in sorted({Path(os.path.abspath(t)) for t in targets if t is not None}):
            taken.append(_acquire(t, wait_s))
        yield
    finally:
        for lock in reversed(taken):
            _release(lock)


def remove_stale_temps(target: PathLike, *, names: tuple[str, ...] | None = None) -> list[Path]:
    """Remove the temporary files/folders an interrupted run left for ``target``.

    Call it only while holding :func:`output_lock` of ``target``. Removes hidden
    ``.NAME.tmp-*`` beside ``target`` and, if ``target`` is a folder, the hidden
    ``.FILE.tmp-*`` of the files inside it (only of ``names`` when given).
    """
    t = Path(target)
    found = list(t.parent.glob(f".{t.name}.tmp-*")) if t.parent.is_dir() else []
    if t.is_dir():
        inside = t.glob(".*.tmp-*")
        if names is not None:
            inside = (p for p in inside if any(p.name.startswith(f".{n}.tmp-") for n in names))
        found.extend(inside)
    for p in found:
        logger.info("removing %s, left by an interrupted run", p)
        _remove(p)
    return found


# --- staged output sets -------------------------------------------------------------------

class Staging:
    """New outputs written to temporary paths, moved to their final names together.

    :meth:`file` gives a temporary path for one output file, :meth:`folder` a hidden
    temporary folder for a folder output. Nothing under a final name changes until
    :meth:`commit`, which only renames (so it needs no disk space): the folder's
    ``marker`` is removed first and moved in last, and the ``stale`` files of the old
    output are removed. :meth:`abort` removes everything that was staged.
    """

    def __init__(self) -> None:
        self._files: list[tuple[Path, Path]] = []
        self._folders: list[tuple[Path, Path, str | None, tuple[str, ...]]] = []
        self.committed = False

    def file(self, final: PathLike) -> Path:
        """A temporary path (same folder and suffix) whose content becomes ``final``."""
        final_p = Path(final)
        final_p.parent.mkdir(parents=True, exist_ok=True)
        tmp = temp_path_for(final_p)
        self._files.append((tmp, final_p))
        return tmp

    def folder(self, final: PathLike, *, marker: str | None = None, stale: tuple[str, ...] = ()) -> Path:
        """A hidden, empty folder beside ``final``; its files replace those in ``final``."""
        final_p = Path(os.path.abspath(final))
        final_p.parent.mkdir(parents=True, exist_ok=True)
        tmp = final_p.with_name(f".{final_p.name}.tmp-{uuid.uuid4().hex[:12]}")
        tmp.mkdir()
        self._folders.append((tmp, final_p, marker, stale))
        return tmp

    def commit(self) -> None:
        """Move every staged output to its final name."""
        check_stop()
        for tmp, final, marker, stale in self._folders:
            if final.exists() and not final.is_dir():
                raise OutputError(f"{final} is a file, not a folder; remove it or choose another output folder")
            final.mkdir(parents=True, exist_ok=True)
            new = sorted(p.name for p in tmp.iterdir())
            if marker is not None:  # first: from here on the folder reads as incomplete
                with contextlib.suppress(FileNotFoundError):
                    (final / marker).unlink()
                if marker in new:  # ... until the marker is moved in, last
                    new.remove(marker)
                    new.append(marker)
            for name in stale:
                if name not in new:
                    with contextlib.suppress(FileNotFoundError):
                        (final / name).unlink()
            for name in new:
                _fsync_file(tmp / name)
                os.replace(tmp / name, final / name)
            _fsync_dir(final)
            tmp.rmdir()
        for tmp, final in self._files:
            if tmp.exists():
                _fsync_file(tmp)
                os.replace(tmp, final)
                _fsync_dir(final.parent)
        self.committed = True

    def abort(self) -> None:
        """Remove whatever was staged and not committed."""
        for tmp, *_ in self._folders:
            _remove(tmp)
        for tmp, _ in self._files:
            _remove(tmp)


@contextlib.contextmanager
def staged_folder(final: PathLike, *, marker: str | None = None, stale: tuple[str, ...] = (),
                  names: tuple[str, ...] | None = None) -> Iterator[Path]:
    """Lock the folder ``final``, yield a hidden folder beside it, then move its files in.

    Stale temporary files of ``names`` (see :func:`remove_stale_temps`) are removed first.
    On any failure the staged files are removed and ``final`` is left as it was; a full
    disk raises :class:`~orokit.errors.OutputError` ``no space left on <final>``.
    """
    with output_lock(final):
        remove_stale_temps(final, names=names)
        stage = Staging()
        try:
            yield stage.folder(final, marker=marker, stale=stale)
            stage.commit()
        except Exception as exc:
            stage.abort()
            if is_no_space_error(exc) and not isinstance(exc, OutputError):
                raise no_space_error(final, exc) from exc
            raise
        except BaseException:
            stage.abort()
            raise


# --- disk space ---------------------------------------------------------------------------

#: how GDAL and SQLite (a GeoPackage: SQLITE_FULL) word a full disk
_NO_SPACE = ("no space left on device", "disk quota exceeded", "free disk space available", "database or disk is full")


def is_no_space_error(exc: BaseException) -> bool:
    """True if ``exc`` (or its cause) says the disk is full (ENOSPC/EDQUOT or GDAL's text)."""
    seen = 0
    e: BaseException | None = exc
    while e is not None and seen < 5:
        if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        if any(s in str(e).lower() for s in _NO_SPACE):
            return True
        e = e.__cause__ or e.__context__
        seen += 1
    return False


def no_space_error(where: PathLike, exc: BaseException | None = None) -> OutputError:
    """The one message for a full disk: ``no space left on <path>``."""
    detail = f" ({exc})" if exc is not None and str(exc) else ""
    return OutputError(
        f"no space left on {where}{detail}; the previous outputs were kept unchanged. "
        "Free some space (or write elsewhere) and run again."
    )


def check_free_space(target: PathLike, need_bytes: float, *, what: str = "the output") -> None:
    """Refuse (``no space left on <folder>``) when the folder of ``target`` has less free
    space than ``need_bytes``."""
    folder = Path(os.path.abspath(target)).parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    free = shutil.disk_usage(folder).free
    if free < need_bytes:
        raise OutputError(
            f"no space left on {folder}: {what} needs about {_megabytes(need_bytes)}, "
            f"{_megabytes(free)} are free. Free some space (or write elsewhere) and run again."
        )


def _megabytes(n: float) -> str:
    """``n`` bytes in MB, one decimal below 10 MB (0.74 MB needed and 0.6 MB free both read "1 MB" before).

    >>> _megabytes(740_000), _megabytes(1000), _megabytes(123_456_789)
    ('0.7 MB', '0.0 MB', '123 MB')
    """
    return f"{n / 1e6:.1f} MB" if n < 10e6 else f"{n / 1e6:.0f} MB"
