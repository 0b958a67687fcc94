"""Atomic file output: write to a temporary file beside the target, then rename.

Every orokit writer goes through :func:`atomic_path` (or the small wrappers below), so
an interrupted or failed write never leaves a half-written file under the final name
and an older file at that name stays intact until the new one is complete.
"""
from __future__ import annotations

import contextlib
import logging
import os
import shutil
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from orokit._typing import PathLike
from orokit.errors import OrokitError

logger = logging.getLogger(__name__)

__all__ = ["atomic_path", "atomic_open", "write_text_atomic", "write_bytes_atomic", "temp_path_for"]


def temp_path_for(final_path: PathLike) -> Path:
    """Return a unique temporary path in the directory of ``final_path``.

    The name keeps the final suffix (``.gpkg``, ``.tif``...) so format drivers that
    choose the format from the extension still work, and starts with a dot so the
    file is hidden while it is being written.
    """
    final = Path(final_path)
    return final.with_name(f".{final.name}.tmp-{uuid.uuid4().hex[:12]}{final.suffix}")


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


@contextlib.contextmanager
def atomic_path(final_path: PathLike, *, fsync: bool = True) -> Iterator[Path]:
    """Yield a temporary path; on success move it to ``final_path`` atomically.

    Parameters
    ----------
    final_path
        Where the file should end up. Missing parent directories are created.
    fsync
        Flush the file (and then its directory) to disk before/after the rename.

    Yields
    ------
    Path
        A unique, not yet existing path in the same directory (same filesystem, so
        :func:`os.replace` is atomic on POSIX) with the same suffix as ``final_path``.

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
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_path_for(final)
    try:
        yield tmp
        if not tmp.exists():
            raise OrokitError(
                f"nothing was written for {final}: the writer did not create the temporary file {tmp.name}"
            )
        if fsync and tmp.is_file():
            _fsync_file(tmp)
        os.replace(tmp, final)
        if fsync:
            _fsync_dir(final.parent)
        logger.debug("wrote %s", final)
    except BaseException:
        _remove(tmp)
        raise


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
