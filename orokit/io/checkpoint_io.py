"""Checkpoint folders of the chunked engine: one ``.npz`` of arrays per chunk.

``checkpoint.json`` records the run the folder belongs to (input, chunks, threshold);
a folder of another run is refused. Chunk files are written atomically, so a file
that exists is complete and a rerun reuses it; the temporary file of a chunk that a
killed run was writing holds that run's process (``.chunk_I_J.npz.tmp-PID@HOST-...``), is
locked by its writer until renamed, and is removed when the folder is opened again (no process holding it).
"""
from __future__ import annotations

import json
import logging
import re
from pathlib import Path
from typing import Any, cast

import numpy as np

from orokit._typing import PathLike
from orokit.errors import TilingError
from orokit.io.atomic import atomic_path
from orokit.io.spill_io import may_remove, run_tag

logger = logging.getLogger(__name__)

__all__ = ["open_checkpoint", "chunk_path", "write_chunk", "read_chunk", "discard_chunk"]

#: a temporary file of the folder's own (``atomic_path``'s name for a chunk or checkpoint.json): the rest after ``.tmp-``
_TEMP = re.compile(r"\.(?:chunk_\d+_\d+\.npz|checkpoint\.json)\.tmp-(.+)")


def open_checkpoint(folder: PathLike, fingerprint: dict[str, Any]) -> Path:
    """Create ``folder`` (or check that it belongs to the run described by ``fingerprint``).

    The temporary files that runs which have ended left in it (a chunk being written when the
    process was killed) are removed; a running process's are left.

    Raises
    ------
    TilingError
        The folder holds the checkpoint of another run.
    """
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    meta = root / "checkpoint.json"
    if meta.exists():
        try:
            old = json.loads(meta.read_text())
        except (OSError, ValueError) as exc:
            raise TilingError(f"{meta} is unreadable ({exc}); delete the checkpoint folder {root} and rerun") from None
        if old != fingerprint:
            differ = sorted(k for k in set(old) | set(fingerprint) if old.get(k) != fingerprint.get(k)) \
                if isinstance(old, dict) else ["format"]
            raise TilingError(
                f"checkpoint folder {root} belongs to another run (different input, chunks or threshold: "
                f"{', '.join(differ)} differ); use a new folder or delete it"
            )
    else:
        with atomic_path(meta, tag=run_tag(), lock=True) as tmp:
            tmp.write_text(json.dumps(fingerprint, indent=1), encoding="utf-8", newline="\n")
    _remove_stale_temps(root)
    return root


def _remove_stale_temps(root: Path) -> None:
    """Remove the folder's temporary files whose run has ended (:func:`~orokit.io.spill_io.may_remove`: no
    process holds them)."""
    for path in sorted(root.iterdir()):
        match = _TEMP.fullmatch(path.name)
        if match and path.is_file() and may_remove(path, match.group(1).rpartition("-")[0]):
            logger.info("removed %s, left by a run that was killed", path)


def chunk_path(root: PathLike, i: int, j: int) -> Path:
    """File of chunk (i, j) in a checkpoint folder."""
    return Path(root) / f"chunk_{i:05d}_{j:05d}.npz"


def write_chunk(path: PathLike, arrays: dict[str, np.ndarray]) -> None:
    """Write the arrays of one chunk atomically (uncompressed npz)."""
    with atomic_path(path, tag=run_tag(), lock=True) as tmp:  # a killed run's temporary file is known as its own
        with open(tmp, "wb") as fh:
            np.savez(fh, **cast("dict[str, Any]", arrays))  # not allow_pickle: only arrays


def read_chunk(path: PathLike) -> dict[str, np.ndarray]:
    """The arrays of one chunk file.

    Raises
    ------
    TilingError
        The file is truncated, empty or not an npz of arrays (it is never unpickled).
    """
    try:
        # the file is opened here, so it is closed even when np.load fails on a truncated archive
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as data:
            if not hasattr(data, "files"):
                raise ValueError("not an npz archive")
            return {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise
    except Exception as exc:  # noqa: BLE001 - BadZipFile, EOFError, ValueError, OSError, zlib errors...
        raise TilingError(f"checkpoint chunk {path} is corrupt ({type(exc).__name__}: {exc})") from None


def discard_chunk(path: PathLike, reason: BaseException) -> None:
    """Remove a chunk file that cannot be used, with a warning; the engine recomputes it."""
    import warnings

    from orokit.errors import OrokitWarning

    why = str(reason) if isinstance(reason, TilingError) else f"checkpoint chunk {path} is unusable ({reason!r})"
    warnings.warn(f"{why}; recomputing that chunk", OrokitWarning, stacklevel=3)
    Path(path).unlink(missing_ok=True)
