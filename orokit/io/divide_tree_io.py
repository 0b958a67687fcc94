"""Divide Tree files: one reader for every format, by file name.

The formats live in :mod:`orokit.io.divide_tree_txt` (the reference TXT format of
Argudo et al. 2019) and :mod:`orokit.io.divide_tree_gpkg` (GeoPackage layers); their
readers and writers are re-exported here.
"""
from __future__ import annotations

from pathlib import Path

from orokit._typing import PathLike
from orokit.errors import InputError
from orokit.io.divide_tree_gpkg import read_divide_tree_gpkg, write_divide_tree_gpkg
from orokit.io.divide_tree_txt import METRES_PER_ARCSEC, read_divide_tree_txt, write_divide_tree_txt
from orokit.topology.divide_tree import DivideTree

__all__ = [
    "read_divide_tree",
    "read_divide_tree_txt",
    "write_divide_tree_txt",
    "write_divide_tree_gpkg",
    "read_divide_tree_gpkg",
    "METRES_PER_ARCSEC",
]


def read_divide_tree(path: PathLike, *, cell_size_m: float | None = None, z_units: str = "ft") -> DivideTree:
    """Read a Divide Tree from a ``.gpkg``, a reference ``.txt``, or a folder holding ``dividetree.gpkg``.

    ``cell_size_m`` (metres) and ``z_units`` apply to the TXT format only (see
    :func:`~orokit.io.divide_tree_txt.read_divide_tree_txt`).

    Raises
    ------
    InputError
        The path does not exist or its suffix is neither ``.gpkg`` nor ``.txt``.
    """
    p = Path(path)
    if p.is_dir():
        p = p / "dividetree.gpkg"
        if not p.is_file():
            raise InputError(f"{path} is a folder without dividetree.gpkg; pass a .gpkg or .txt Divide Tree file")
    suffix = p.suffix.lower()
    if suffix == ".txt":
        return read_divide_tree_txt(p, cell_size_m=cell_size_m, z_units=z_units)
    if suffix == ".gpkg":
        return read_divide_tree_gpkg(p)
    raise InputError(f"{p}: unknown Divide Tree format {suffix or '(no suffix)'!r}; "
                     "expected a .gpkg (orokit) or .txt (reference format) file, or an analysis/synthesis folder")
