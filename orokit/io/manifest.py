"""The datasets manifest: what real data the pipeline uses and how to check it.

The manifest is one YAML file, ``datasets_manifest/datasets.yaml`` at the top of the
repository (override with the environment variable ``OROKIT_MANIFEST``). Each
dataset has a name, a kind (``dem``, ``regions``), a region label, a format,
elevation units, cell size, CRS (or ``"local grid"``), licence, citation, and a list
of files, each with a relative ``path``, a source ``url``, its ``sha256`` and size.
"""
from __future__ import annotations

import os
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

from orokit._typing import PathLike
from orokit.errors import DataError

__all__ = ["DataFile", "Dataset", "Manifest", "load_manifest", "default_manifest_path"]

_SHA256 = re.compile(r"^[0-9a-f]{64}$")
_REQUIRED = ("name", "kind", "format", "licence", "citation", "files")
_FILE_REQUIRED = ("path", "url", "sha256")


@dataclass(frozen=True)
class DataFile:
    """One file of a dataset."""

    path: str  #: location relative to the cache directory and to a mirror
    url: str  #: public source URL
    sha256: str  #: expected lowercase hex digest
    size: int | None = None  #: expected size in bytes (informative)
    role: str = "data"  #: dem, divide_tree, licence, shape, kml...
    region: str | None = None  #: region label, for per-region files

    @property
    def filename(self) -> str:
        """Base name of the file."""
        return PurePosixPath(self.path).name


@dataclass(frozen=True)
class Dataset:
    """A dataset entry of the manifest."""

    name: str
    kind: str
    format: str
    licence: str
    citation: str
    files: tuple[DataFile, ...]
    title: str = ""
    region: str | None = None
    z_units: str | None = None
    cell_size_m: float | None = None
    cell_size_arcsec: float | None = None
    crs: str | None = None
    shape: tuple[int, int] | None = None
    nodata: float | None = None
    sea_level_zero: bool | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def local_grid(self) -> bool:
        """True when the data has no real CRS and is read on a local metric grid."""
        return (self.crs or "").strip().lower() == "local grid"

    @property
    def primary(self) -> DataFile:
        """The main file (role ``dem`` if present, else the first file)."""
        for f in self.files:
            if f.role == "dem":
                return f
        return self.files[0]

    def files_with_role(self, role: str) -> list[DataFile]:
        """Files of this dataset that have the given role."""
        return [f for f in self.files if f.role == role]


@dataclass(frozen=True)
class Manifest:
    """All datasets of a manifest file, by name (in file order)."""

    datasets: dict[str, Dataset]
    path: Path | None = None

    def __iter__(self) -> Iterator[Dataset]:
        return iter(self.datasets.values())

    def __len__(self) -> int:
        return len(self.datasets)

    def __contains__(self, name: object) -> bool:
        return name in self.datasets

    def __getitem__(self, name: str) -> Dataset:
        try:
            return self.datasets[name]
        except KeyError:
            raise DataError(
                f"unknown dataset {name!r}; the manifest ({self.path}) has: {', '.join(self.datasets)}."
            ) from None

    @property
    def names(self) -> list[str]:
        """Dataset names in manifest order."""
        return list(self.datasets)

    def select(self, names: Iterable[str] | None = None) -> list[Dataset]:
        """Datasets by name (all when ``names`` is None or empty); unknown names raise."""
        names = list(names or [])
        return [self[n] for n in names] if names else list(self)

    def dems(self) -> list[Dataset]:
        """Datasets of kind ``dem``."""
        return [d for d in self if d.kind == "dem"]

    def unique_files(self, names: Iterable[str] | None = None) -> list[DataFile]:
        """Files of the selected datasets, each path once (shared licence files...)."""
        seen: dict[str, DataFile] = {}
        for ds in self.select(names):
            for f in ds.files:
                seen.setdefault(f.path, f)
        return list(seen.values())

    def find_file(self, key: str) -> tuple[Dataset, DataFile]:
        """Resolve a dataset name (its primary file), a file path or a unique file name."""
        if key in self.datasets:
            ds = self.datasets[key]
            return ds, ds.primary
        matches = [(ds, f) for ds in self for f in ds.files if key in (f.path, f.filename)]
        if not matches:
            raise DataError(
                f"{key!r} is neither a dataset name nor a file of the manifest ({self.path}); "
                f"datasets: {', '.join(self.datasets)}."
            )
        paths = {f.path for _, f in matches}
        if len(paths) > 1:
            raise DataError(f"{key!r} matches several files ({', '.join(sorted(paths))}); give the full path.")
        return matches[0]


def default_manifest_path() -> Path:
    """``$OROKIT_MANIFEST`` or ``datasets_manifest/datasets.yaml`` of the repository."""
    env = os.environ.get("OROKIT_MANIFEST")
    if env:
        return Path(env).expanduser()
    return Path(__file__).resolve().parents[2] / "datasets_manifest" / "datasets.yaml"


def _file_entry(raw: Any, where: str) -> DataFile:
    if not isinstance(raw, dict):
        raise DataError(f"{where}: a file entry must be a mapping, got {raw!r}.")
    missing = [k for k in _FILE_REQUIRED if not raw.get(k)]
    if missing:
        raise DataError(f"{where}: file entry {raw.get('path', raw)!r} lacks {', '.join(missing)}.")
    sha = str(raw["sha256"]).lower()
    if not _SHA256.match(sha):
        raise DataError(f"{where}: file {raw['path']!r} has sha256 {raw['sha256']!r}, not 64 hex digits.")
    rel = PurePosixPath(str(raw["path"]))
    if rel.is_absolute() or ".." in rel.parts:
        raise DataError(f"{where}: file path {raw['path']!r} must be relative, without '..'.")
    return DataFile(
        path=str(rel),
        url=str(raw["url"]),
        sha256=sha,
        size=None if raw.get("size") is None else int(raw["size"]),
        role=str(raw.get("role", "data")),
        region=raw.get("region"),
    )


def _dataset_entry(raw: Any, where: str) -> Dataset:
    if not isinstance(raw, dict):
        raise DataError(f"{where}: a dataset entry must be a mapping, got {type(raw).__name__}.")
    name = raw.get("name", "?")
    missing = [k for k in _REQUIRED if raw.get(k) in (None, "", [])]
    if missing:
        raise DataError(f"{where}: dataset {name!r} lacks {', '.join(missing)}.")
    if raw["kind"] == "dem":
        for key in ("z_units", "crs"):
            if not raw.get(key):
                raise DataError(f"{where}: DEM dataset {name!r} lacks {key} (required for every DEM).")
        if str(raw["crs"]).lower() == "local grid" and not raw.get("cell_size_m"):
            raise DataError(f"{where}: DEM dataset {name!r} is on a local grid and needs cell_size_m.")
    known = {
        "name", "kind", "title", "region", "format", "z_units", "cell_size_m", "cell_size_arcsec", "crs",
        "shape", "nodata", "sea_level_zero", "licence", "citation", "files",
    }
    files = tuple(_file_entry(f, f"{where}, dataset {name!r}") for f in raw["files"])
    shape = raw.get("shape")
    return Dataset(
        name=str(name),
        kind=str(raw["kind"]),
        format=str(raw["format"]),
        licence=str(raw["licence"]),
        citation=str(raw["citation"]),
        files=files,
        title=str(raw.get("title") or name),
        region=raw.get("region"),
        z_units=raw.get("z_units"),
        cell_size_m=None if raw.get("cell_size_m") is None else float(raw["cell_size_m"]),
        cell_size_arcsec=None if raw.get("cell_size_arcsec") is None else float(raw["cell_size_arcsec"]),
        crs=raw.get("crs"),
        shape=None if shape is None else (int(shape[0]), int(shape[1])),
        nodata=raw.get("nodata"),
        sea_level_zero=raw.get("sea_level_zero"),
        extra={k: v for k, v in raw.items() if k not in known},
    )


def load_manifest(path: PathLike | None = None) -> Manifest:
    """Load and validate the datasets manifest.

    Parameters
    ----------
    path
        YAML file; default :func:`default_manifest_path`.

    Raises
    ------
    DataError
        Missing or unparsable file, missing fields, bad sha256, duplicate names.
    """
    import yaml

    p = Path(path) if path is not None else default_manifest_path()
    if not p.is_file():
        raise DataError(
            f"datasets manifest not found at {p}; set OROKIT_MANIFEST to the datasets.yaml file "
            "(it lives in datasets_manifest/ of the orokit repository)."
        )
    try:
        raw = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise DataError(f"cannot parse the datasets manifest {p}: {exc}") from exc
    if not isinstance(raw, dict) or not isinstance(raw.get("datasets"), list):
        raise DataError(f"datasets manifest {p} must be a mapping with a 'datasets' list.")
    if raw.get("version") != 1:
        raise DataError(f"datasets manifest {p} has version {raw.get('version')!r}; this orokit reads version 1.")
    datasets: dict[str, Dataset] = {}
    for i, entry in enumerate(raw["datasets"]):
        ds = _dataset_entry(entry, f"{p} entry {i}")
        if ds.name in datasets:
            raise DataError(f"{p}: dataset name {ds.name!r} appears twice.")
        datasets[ds.name] = ds
    # a path shared by several datasets (licence files) must describe the same bytes
    by_path: dict[str, str] = {}
    for ds in datasets.values():
        for f in ds.files:
            if by_path.setdefault(f.path, f.sha256) != f.sha256:
                raise DataError(f"{p}: file {f.path!r} is listed with two different sha256 values.")
    return Manifest(datasets=datasets, path=p)
