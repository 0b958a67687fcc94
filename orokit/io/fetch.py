"""Fetch and verify manifest files: cache directory, mirror, sha256 checks.

- Cache: ``$OROKIT_DATA_DIR`` or ``pooch.os_cache("orokit")``; each file lives at its
  manifest ``path`` under it.
- Source: a local mirror when ``$OROKIT_DATA_MIRROR`` is set (a directory laid out
  like the manifest paths, e.g. ``../shared/data``), else the file's URL (pooch
  downloader).
- Every new copy is written to a temporary file beside its final name, its sha256
  is checked, and only then is it renamed: a wrong hash is a :class:`DataError`
  naming the file and both hashes, and an interrupted copy or download leaves
  nothing under the final name (an older good copy stays in place).
- A lock per cache entry (filelock) lets parallel processes (``pytest -n 2``,
  ``make -j2``) fetch the same file safely.
"""
from __future__ import annotations

import logging
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from orokit._typing import PathLike
from orokit.io.manifest import DataFile, Manifest, load_manifest
from orokit.errors import DataError
from orokit.io.atomic import atomic_path
from orokit.io.hashing import sha256_file

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

logger = logging.getLogger(__name__)

__all__ = [
    "data_dir", "mirror_dir", "sha256_file", "fetch_file", "fetch", "verify", "FileStatus",
    "dataset_path", "open_dataset_dem",
]

_CHUNK = 1 << 20


def data_dir() -> Path:
    """The cache directory: ``$OROKIT_DATA_DIR`` or the OS cache for "orokit"."""
    env = os.environ.get("OROKIT_DATA_DIR")
    if env:
        return Path(env).expanduser().resolve()
    import pooch

    return Path(pooch.os_cache("orokit"))


def portable_path(path: PathLike | None) -> str:
    """``path`` without this machine's absolute prefix, for files that are committed.

    A file of the data cache or mirror becomes its manifest path (``dems/gobi.png``), a
    file under the working directory its relative path; anything else is kept.

    Examples
    --------
    >>> portable_path(Path.cwd() / "reports" / "x.json")
    'reports/x.json'
    >>> portable_path("relative/name.tif")
    'relative/name.tif'
    """
    if path is None or str(path) == "":
        return ""
    p = Path(path)
    if not p.is_absolute():
        return p.as_posix()
    for base in (data_dir(), mirror_dir(), Path.cwd()):
        if base is None:
            continue
        try:
            return p.resolve().relative_to(Path(base).resolve()).as_posix()
        except ValueError:
            continue
    return p.as_posix()


def mirror_dir() -> Path | None:
    """The local mirror from ``$OROKIT_DATA_MIRROR`` (resolved), or None."""
    env = os.environ.get("OROKIT_DATA_MIRROR")
    return Path(env).expanduser().resolve() if env else None


def _copy(src: Path, dst: Path) -> None:
    with open(src, "rb") as fin, open(dst, "wb") as fout:
        shutil.copyfileobj(fin, fout, _CHUNK)


def _download(url: str, dst: Path, *, retries: int = 3) -> None:
    import pooch

    from pooch.downloaders import choose_downloader

    downloader = choose_downloader(url, progressbar=False)
    if isinstance(downloader, pooch.HTTPDownloader):
        downloader = pooch.HTTPDownloader(progressbar=False, timeout=60)
    last: Exception | None = None
    for attempt in range(retries):
        try:
            downloader(url, str(dst), None)
            return
        except Exception as exc:  # network errors come from requests/ftplib
            last = exc
            logger.warning("download of %s failed (attempt %d/%d): %s", url, attempt + 1, retries, exc)
            if attempt + 1 < retries:
                time.sleep(2**attempt)
    raise DataError(
        f"cannot download {url}: {last}. Check the network, or set OROKIT_DATA_MIRROR to a local copy "
        "of the data (a directory laid out like the manifest paths)."
    ) from last


def fetch_file(
    entry: DataFile,
    *,
    cache_dir: PathLike | None = None,
    mirror: PathLike | None | Literal[False] = None,
    force: bool = False,
) -> Path:
    """Make sure one manifest file is in the cache with the right hash; return its path.

    Parameters
    ----------
    entry
        The manifest file entry.
    cache_dir
        Cache root (default :func:`data_dir`).
    mirror
        Mirror root; None uses ``$OROKIT_DATA_MIRROR``, False forces the URL.
    force
        Fetch again even if a cached copy has the right hash.

    Raises
    ------
    DataError
        The mirror lacks the file, the download fails, or the new copy's sha256
        differs from the manifest's (message names the file and both hashes).
    """
    from filelock import FileLock, Timeout

    root = Path(cache_dir) if cache_dir is not None else data_dir()
    mroot = mirror_dir() if mirror is None else (Path(mirror).resolve() if mirror else None)
    dest = root / entry.path
    dest.parent.mkdir(parents=True, exist_ok=True)

    def cached_ok() -> bool:
        if not dest.is_file():
            return False
        actual = sha256_file(dest)
        if actual == entry.sha256:
            return True
        logger.warning("cached %s has sha256 %s, expected %s: fetching it again", dest, actual, entry.sha256)
        return False

    if not force and cached_ok():
        return dest
    lock = FileLock(str(dest.parent / f".{dest.name}.lock"), timeout=900)
    try:
        with lock:
            if not force and cached_ok():  # another process finished meanwhile
                return dest
            origin = _install(entry, dest, mroot)
    except Timeout as exc:
        raise DataError(f"timed out waiting for the lock on {dest}; is another orokit fetch stuck?") from exc
    logger.info("fetched %s from %s", entry.path, origin)
    return dest


def _install(entry: DataFile, dest: Path, mroot: Path | None) -> str:
    with atomic_path(dest) as tmp:
        if mroot is not None:
            src = mroot / entry.path
            if not src.is_file():
                raise DataError(
                    f"{entry.path} is not in the data mirror {mroot} (OROKIT_DATA_MIRROR); expected {src}. "
                    "Unset OROKIT_DATA_MIRROR to download from the URL, or fix the mirror."
                )
            origin = str(src)
            _copy(src, tmp)
        else:
            origin = entry.url
            _download(entry.url, tmp)
        actual = sha256_file(tmp)
        if actual != entry.sha256:
            raise DataError(
                f"sha256 mismatch for {entry.path} (from {origin}): expected {entry.sha256}, got {actual}. "
                "The file was not installed; the source is corrupt or changed, or the manifest is wrong."
            )
    return origin


def fetch(
    names: list[str] | None = None,
    *,
    manifest: Manifest | None = None,
    cache_dir: PathLike | None = None,
    force: bool = False,
    progress: bool = False,
) -> dict[str, list[Path]]:
    """Fetch every file of the named datasets (all when ``names`` is empty).

    Returns a mapping dataset name -> local paths of its files (manifest order).
    """
    man = manifest or load_manifest()
    datasets = man.select(names)
    files = man.unique_files([d.name for d in datasets])
    local: dict[str, Path] = {}
    it = files
    if progress:
        from tqdm import tqdm

        it = tqdm(files, desc="fetch data", unit="file")
    for f in it:
        local[f.path] = fetch_file(f, cache_dir=cache_dir, force=force)
    logger.info("%d files of %d dataset(s) ready in %s", len(files), len(datasets), cache_dir or data_dir())
    return {d.name: [local[f.path] for f in d.files] for d in datasets}


@dataclass(frozen=True)
class FileStatus:
    """Result of checking one file: ``status`` is ``ok``, ``missing`` or ``mismatch``."""

    dataset: str
    path: Path
    expected: str
    actual: str | None
    status: str


def verify(
    names: list[str] | None = None,
    *,
    manifest: Manifest | None = None,
    root: PathLike | None = None,
) -> list[FileStatus]:
    """Check the sha256 of every file of the named datasets under ``root``.

    ``root`` defaults to the cache directory; pass a mirror directory to check it.
    Nothing is downloaded or changed.
    """
    man = manifest or load_manifest()
    base = Path(root) if root is not None else data_dir()
    out: list[FileStatus] = []
    seen: set[str] = set()
    for ds in man.select(names):
        for f in ds.files:
            if f.path in seen:
                continue
            seen.add(f.path)
            p = base / f.path
            if not p.is_file():
                out.append(FileStatus(ds.name, p, f.sha256, None, "missing"))
                continue
            actual = sha256_file(p)
            out.append(FileStatus(ds.name, p, f.sha256, actual, "ok" if actual == f.sha256 else "mismatch"))
    return out


def dataset_path(name: str, *, role: str | None = None, manifest: Manifest | None = None) -> Path:
    """Fetch (if needed) and return the local path of a dataset's file.

    ``name`` is a dataset name (its primary file, or the file with ``role``), a
    manifest file path (``dems/alaska.txt``) or a unique file name.
    """
    man = manifest or load_manifest()
    ds, f = man.find_file(name)
    if role is not None and name in man:
        candidates = ds.files_with_role(role)
        if not candidates:
            raise DataError(f"dataset {name!r} has no file with role {role!r}; roles: {sorted({x.role for x in ds.files})}.")
        f = candidates[0]
    return fetch_file(f)


def open_dataset_dem(name: str, chunks: object = None, *, manifest: Manifest | None = None) -> xr.DataArray:
    """Fetch a DEM of the manifest and read it with its units and cell size.

    PNG DEMs (no georeference) get the manifest's elevation units and cell size and
    a local metric grid; georeferenced DEMs keep their CRS. ``attrs`` gain
    ``dataset``, ``region`` and ``title``.
    """
    from orokit.io.dem import read_dem

    man = manifest or load_manifest()
    ds = man[name]
    if ds.kind != "dem":
        raise DataError(f"dataset {name!r} is a {ds.kind!r} dataset, not a DEM; DEMs: {', '.join(d.name for d in man.dems())}.")
    path = fetch_file(ds.primary)
    kwargs: dict[str, object] = {"z_units": ds.z_units, "chunks": chunks}
    if ds.local_grid:
        kwargs["cell_size_m"] = ds.cell_size_m
    dem = read_dem(path, **kwargs)  # type: ignore[arg-type]
    dem.attrs.update({"dataset": ds.name, "region": ds.region or "", "title": ds.title})
    return dem
