"""Checkpoint folders of the chunked engine: one ``.npz`` of arrays per chunk.

``checkpoint.json`` records the run the folder belongs to (input, chunks, threshold);
a folder of another run is refused. Chunk files are written atomically, so a file
that exists is complete and a rerun reuses it.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, cast

import numpy as np

from orokit._typing import PathLike
from orokit.errors import TilingError
from orokit.io.atomic import atomic_path, write_text_atomic

__all__ = ["open_checkpoint", "chunk_path", "write_chunk", "read_chunk", "discard_chunk"]


def open_checkpoint(folder: PathLike, fingerprint: dict[str, Any]) -> Path:
    """Create ``folder`` (or check that it belongs to the run described by ``fingerprint``).

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
            raise TilingError(
                f"checkpoint folder {root} belongs to another run (different input, chunks or threshold); "
                "use a new folder or delete it"
            )
    else:
        write_text_atomic(meta, json.dumps(fingerprint, indent=1))
    return root


def chunk_path(root: PathLike, i: int, j: int) -> Path:
    """File of chunk (i, j) in a checkpoint folder."""
    return Path(root) / f"chunk_{i:05d}_{j:05d}.npz"


def write_chunk(path: PathLike, arrays: dict[str, np.ndarray]) -> None:
    """Write the arrays of one chunk atomically (uncompressed npz)."""
    with atomic_path(path) as tmp:
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
