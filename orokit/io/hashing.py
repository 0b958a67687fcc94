"""sha256 of files and bytes: the one digest orokit records (data manifest, models, raster tags)."""
from __future__ import annotations

import hashlib

from orokit._typing import PathLike

__all__ = ["sha256_file", "sha256_bytes"]

_BLOCK = 1 << 20


def sha256_file(path: PathLike) -> str:
    """Lowercase hex sha256 of a file, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(_BLOCK), b""):
            h.update(block)
    return h.hexdigest()


def sha256_bytes(data: bytes) -> str:
    """Lowercase hex sha256 of ``data``.

    >>> sha256_bytes(b"")
    'e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855'
    """
    return hashlib.sha256(data).hexdigest()
