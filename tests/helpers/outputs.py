"""Comparing two analysis folders written by ``write_analysis``."""
from __future__ import annotations

from pathlib import Path

TABLE_FILES = ("peaks.csv", "peaks.parquet", "saddles.parquet", "analysis.json")


def assert_same_table_files(a: Path, b: Path, names: tuple[str, ...] = TABLE_FILES) -> None:
    """The table files and analysis.json of ``a`` and ``b`` have the same bytes."""
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def assert_same_geopackages(a: Path, b: Path) -> None:
    """Two GeoPackages read back alike: the same layers (in order), each with equal features, attributes,
    column types and CRS, and the same ``orokit_metadata`` table."""
    import geopandas as gpd
    import pyogrio

    layers = [tuple(layer) for layer in pyogrio.list_layers(a)]
    assert layers == [tuple(layer) for layer in pyogrio.list_layers(b)]
    for name, geometry_type in layers:
        if geometry_type is None:  # a table without geometry
            la, lb = pyogrio.read_dataframe(a, layer=name), pyogrio.read_dataframe(b, layer=name)
            assert la.equals(lb) and list(la.dtypes) == list(lb.dtypes), name
            continue
        la, lb = gpd.read_file(a, layer=name), gpd.read_file(b, layer=name)
        assert la.equals(lb) and list(la.dtypes) == list(lb.dtypes), name
        assert la.crs == lb.crs, name


def assert_same_analysis_files(a: Path, b: Path, names: tuple[str, ...] = TABLE_FILES) -> None:
    """The same bytes of every table file (``names``) and GeoPackages that read back alike."""
    assert_same_table_files(a, b, names)
    assert_same_geopackages(a / "dividetree.gpkg", b / "dividetree.gpkg")
