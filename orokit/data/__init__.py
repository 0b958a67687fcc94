"""Real datasets: the manifest, fetching into a cache (or from a mirror), verification.

A public facade: the files are read and written by :mod:`orokit.io.manifest` and :mod:`orokit.io.fetch`.

The manifest itself is ``datasets_manifest/datasets.yaml``.
"""
from __future__ import annotations

from orokit.io.fetch import (
    FileStatus,
    data_dir,
    dataset_path,
    fetch,
    fetch_file,
    mirror_dir,
    open_dataset_dem,
    portable_path,
    sha256_file,
    verify,
)
from orokit.io.manifest import DataFile, Dataset, Manifest, default_manifest_path, load_manifest

__all__ = [
    "DataFile", "Dataset", "Manifest", "FileStatus", "load_manifest", "default_manifest_path", "data_dir",
    "mirror_dir", "sha256_file", "fetch_file", "fetch", "verify", "dataset_path", "open_dataset_dem",
    "portable_path",
]
