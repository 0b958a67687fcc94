"""Divide Tree files: read_divide_tree dispatch, and GeoPackage peaks layers with the orometry columns."""
from __future__ import annotations

import geopandas as gpd
import numpy as np
import pandas as pd
import pytest

import orokit
from orokit.analysis import write_analysis
from orokit.errors import InputError, SchemaError
from orokit.io.divide_tree_io import read_divide_tree, write_divide_tree_gpkg, write_divide_tree_txt
from orokit.topology.tables import OROMETRY_COLUMNS, PEAK_COLUMNS


@pytest.fixture(scope="module")
def result():
    import rioxarray  # noqa: F401 - registers .rio
    import xarray as xr

    rng = np.random.default_rng(11)
    z = rng.normal(0, 1, (40, 50)).cumsum(0).cumsum(1).astype(np.float32) + 500.0
    dem = xr.DataArray(z, dims=("y", "x"),
                       coords={"y": 30.0 * np.arange(40)[::-1] + 15, "x": 30.0 * np.arange(50) + 15})
    return orokit.analyze(dem.rio.write_crs("EPSG:32633"), min_prominence_m=2.0)


def _same_tree(a, b):
    pd.testing.assert_frame_equal(a.peaks.reset_index(drop=True), b.peaks.reset_index(drop=True), check_dtype=False)
    pd.testing.assert_frame_equal(a.saddles.reset_index(drop=True), b.saddles.reset_index(drop=True),
                                  check_dtype=False)
    assert np.array_equal(a.edges.to_numpy(), b.edges.to_numpy())


def test_analysis_gpkg_peaks_layer_carries_the_orometry(result, tmp_path):
    write_analysis(result, tmp_path / "a")
    layer = gpd.read_file(tmp_path / "a" / "dividetree.gpkg", layer="peaks")
    assert len(result.peaks) > 5 and len(layer) == len(result.peaks)
    assert set(PEAK_COLUMNS) <= set(layer.columns)
    parquet = gpd.read_parquet(tmp_path / "a" / "peaks.parquet")
    assert parquet.index.name == "peak_id"
    layer = layer.set_index("peak_id")
    for c in OROMETRY_COLUMNS:
        a, b = layer[c].to_numpy(), parquet[c].to_numpy()
        if a.dtype.kind == "f":
            assert np.array_equal(a, b, equal_nan=True), c
        else:
            assert np.array_equal(a.astype(b.dtype), b), c
    # the reader returns the tree without the derived columns
    back = read_divide_tree(tmp_path / "a")
    assert not set(OROMETRY_COLUMNS) & set(back.peaks.columns)
    _same_tree(back, result.tree)


def test_gpkg_peaks_table_must_match_the_tree(result, tmp_path):
    with pytest.raises(InputError, match="rows but the tree"):
        write_divide_tree_gpkg(result.tree, tmp_path / "t.gpkg", peaks=result.peaks.iloc[:-1])
    with pytest.raises(SchemaError):
        write_divide_tree_gpkg(result.tree, tmp_path / "t.gpkg", peaks=result.peaks.drop(columns="island_parent"))
    assert not (tmp_path / "t.gpkg").exists()


def test_user_column_named_like_an_orometry_column_survives(result, tmp_path):
    tree = result.tree
    peaks = tree.peaks.assign(prominence=np.arange(tree.n_peaks, dtype=float))
    tagged = type(tree)(peaks, tree.saddles, tree.edges, tree.crs, dict(tree.attrs))
    write_divide_tree_gpkg(tagged, tmp_path / "t.gpkg")
    assert np.array_equal(read_divide_tree(tmp_path / "t.gpkg").peaks["prominence"], peaks["prominence"])


def test_read_divide_tree_dispatch(result, tmp_path):
    tree = result.tree
    write_divide_tree_txt(tree, tmp_path / "t.txt", z_units="m", height=40, cell_size_m=30.0)
    back = read_divide_tree(tmp_path / "t.txt", cell_size_m=30.0, z_units="m")
    assert back.n_peaks == tree.n_peaks
    assert np.allclose(back.peaks["elevation"], tree.peaks["elevation"], atol=1e-6)
    with pytest.raises(InputError, match="unknown Divide Tree format '.csv'"):
        read_divide_tree(tmp_path / "t.csv")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="folder without dividetree.gpkg"):
        read_divide_tree(tmp_path / "empty")


def test_synthesis_files_carry_the_same_columns(result, tmp_path):
    from orokit.io.synthesis_io import write_synthesis
    from orokit.synthesis.tree import peaks_table

    tree = result.tree
    bare = type(tree)(tree.peaks[["x", "y", "elevation"]], tree.saddles[["x", "y", "elevation"]], tree.edges,
                      tree.crs, {})
    table = peaks_table(bare)
    write_synthesis(bare, tmp_path / "s", peaks=table)
    layer = gpd.read_file(tmp_path / "s" / "dividetree.gpkg", layer="peaks")
    csv = pd.read_csv(tmp_path / "s" / "peaks.csv", index_col="peak_id")
    assert set(OROMETRY_COLUMNS) <= set(layer.columns) and list(csv.columns[: len(PEAK_COLUMNS)]) == PEAK_COLUMNS
    assert np.array_equal(layer["prominence"].to_numpy(), result.peaks["prominence"].to_numpy())
    assert (layer["saddle_row"] == -1).all() and (csv["row"] == -1).all()
    assert list(read_divide_tree(tmp_path / "s").peaks.columns) == ["x", "y", "elevation"]
    with pytest.raises(SchemaError):
        write_synthesis(bare, tmp_path / "s2", peaks=table.drop(columns="dominance"))
