"""Comparing two analysis folders written by ``write_analysis``."""
from __future__ import annotations

from pathlib import Path

TABLE_FILES = ("peaks.csv", "peaks.parquet", "saddles.parquet", "analysis.json")


def assert_same_table_files(a: Path, b: Path) -> None:
    """The table files and analysis.json of ``a`` and ``b`` have the same bytes."""
    for name in TABLE_FILES:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def assert_same_analysis_files(a: Path, b: Path) -> None:
    """The same bytes of every table file and equal GeoPackage layers (peaks, saddles, ridges)."""
    import geopandas as gpd

    assert_same_table_files(a, b)
    for layer in ("peaks", "saddles", "ridges"):
        la = gpd.read_file(a / "dividetree.gpkg", layer=layer)
        assert la.equals(gpd.read_file(b / "dividetree.gpkg", layer=layer)), layer
