"""Spill files: arrays a run sets aside on disk until it needs them again.

A spill folder is a temporary folder of one run (removed when the run ends, also on
error), in ``parent`` when given (a checkpoint folder, or dask's ``temporary-directory``),
otherwise in ``TMPDIR``; each spill is an uncompressed ``.npz`` of arrays, written atomically, so a
file that exists is complete.
"""
from __future__ import annotations

import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, cast

import numpy as np

from orokit._typing import PathLike
from orokit.errors import OutputError
from orokit.io.atomic import atomic_path, is_no_space_error

__all__ = ["spill_folder", "write_spill", "read_spill"]


@contextmanager
def spill_folder(prefix: str = "orokit-spill-", parent: PathLike | None = None) -> Iterator[Path]:
    """A new temporary folder (in ``parent``, made if missing, else ``TMPDIR``) for the spills of
    one run, removed on exit."""
    if parent is not None:
        Path(parent).mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=prefix, dir=parent) as folder:
        yield Path(folder)


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
