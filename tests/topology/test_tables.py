"""The peak/saddle table schema (orokit.topology.tables): one definition, checked everywhere."""
from __future__ import annotations

import numpy as np
import pytest

import orokit
from orokit.errors import SchemaError
from orokit.topology.tables import NONE_ID, PEAK_COLUMNS, PEAK_SCHEMA, validate_peak_table, validate_saddle_table

from helpers.outputs import assert_same_analysis_files


@pytest.fixture(scope="module")
def result():
    return orokit.analyze(_dem(), min_prominence_m=5.0)


def _dem():
    """The grid of the ``result`` fixture: random integers with a hole of NaN, 30 m cells, UTM 33N."""
    import rioxarray  # noqa: F401 - registers .rio
    import xarray as xr

    rng = np.random.default_rng(3)
    z = rng.integers(0, 40, (30, 40)).astype(np.float32)
    z[5:8, 5:9] = np.nan
    dem = xr.DataArray(z, dims=("y", "x"), coords={"y": 30.0 * np.arange(30)[::-1] + 15, "x": 30.0 * np.arange(40) + 15})
    return dem.rio.write_crs("EPSG:32633")


def test_analysis_tables_follow_the_schema(result):
    p = result.peaks
    validate_peak_table(p)
    validate_saddle_table(result.saddles)
    assert list(p.columns[: len(PEAK_COLUMNS)]) == PEAK_COLUMNS
    for c in PEAK_SCHEMA:
        assert str(p[c.name].dtype) == c.dtype, c.name
    roots = p["island_parent"] == NONE_ID
    assert roots.any() and (p.loc[roots, "saddle_row"] == NONE_ID).all()
    assert p.loc[roots, "saddle_elevation"].isna().all()


def test_validation_names_the_problem(result):
    p = result.peaks
    with pytest.raises(SchemaError, match=r"x\.parquet: the peaks table lacks columns \['dominance'\]"):
        validate_peak_table(p.drop(columns="dominance"), source="x.parquet")
    bad = p.copy()
    bad["row"] = bad["row"].astype(float)
    with pytest.raises(SchemaError, match=r"row \(float64, expected int64\)"):
        validate_peak_table(bad)
    bad = p.copy()
    bad.loc[bad.index[0], "island_parent"] = -5
    with pytest.raises(SchemaError, match="below the 'none' value -1"):
        validate_peak_table(bad)
    with pytest.raises(SchemaError, match="indexed by 'peak_id'"):
        validate_peak_table(p.reset_index(drop=True))
    with pytest.raises(SchemaError, match="must be a"):
        validate_peak_table(p.to_numpy())


def test_synthesized_peaks_table_uses_the_same_none(result):
    from orokit.synthesis.tree import peaks_table

    table = peaks_table(result.tree)
    validate_peak_table(table)
    for c in ("row", "col", "saddle_row", "saddle_col", "island_parent_row", "island_parent_col", "line_parent_row",
              "line_parent_col", "prominence_parent_row", "prominence_parent_col", "isolation_row", "isolation_col"):
        assert (table[c] == NONE_ID).all(), c
    # the tree alone gives the raster analysis' prominences and parents
    assert np.array_equal(table["prominence"].to_numpy(), result.peaks["prominence"].to_numpy())
    assert np.array_equal(table["island_parent"].to_numpy(), result.peaks["island_parent"].to_numpy())


def test_written_tables_are_validated_on_read(result, tmp_path):
    from orokit.analysis import read_analysis, write_analysis

    write_analysis(result, tmp_path / "a")
    back = read_analysis(tmp_path / "a")
    assert back.peaks.drop(columns="geometry").equals(result.peaks.drop(columns="geometry"))
    import geopandas as gpd

    broken = gpd.read_parquet(tmp_path / "a" / "peaks.parquet").drop(columns="isolation_exact")
    broken.to_parquet(tmp_path / "a" / "peaks.parquet")
    with pytest.raises(SchemaError, match="peaks.parquet: the peaks table lacks columns"):
        read_analysis(tmp_path / "a")


def test_analysis_folders_of_older_versions_read_under_the_current_keys(result, tmp_path):
    """analysis.json written before the naming rules (``min_prominence``, ``cell_size``) still reads."""
    import json

    from orokit.analysis import read_analysis, write_analysis

    write_analysis(result, tmp_path / "a")
    meta_path = tmp_path / "a" / "analysis.json"
    meta = json.loads(meta_path.read_text())
    assert meta["min_prominence_m"] == 5.0 and meta["cell_size_m"] == [30.0, 30.0]
    assert "min_prominence" not in meta and "cell_size" not in meta
    meta["min_prominence"] = meta.pop("min_prominence_m")
    meta["cell_size"] = meta.pop("cell_size_m")
    meta_path.write_text(json.dumps(meta))
    back = read_analysis(tmp_path / "a")
    assert back.attrs["min_prominence_m"] == 5.0 and back.attrs["cell_size_m"] == [30.0, 30.0]
    assert "min_prominence" not in back.attrs and "cell_size" not in back.attrs
    assert back.tree.n_peaks == result.tree.n_peaks


def test_tables_written_in_batches_equal_one_batch(result, tmp_path, monkeypatch):
    """peaks.csv and the GeoPackage layers are written in row batches: same content as in one batch."""
    import geopandas as gpd

    import orokit.io.divide_tree_gpkg as gp
    from orokit.analysis import write_analysis

    n = len(result.peaks)
    assert n > 7 and len(result.saddles) > 7
    write_analysis(result, tmp_path / "one")
    monkeypatch.setattr(gp, "WRITE_BATCH_ROWS", 3)  # several batches and a last partial one
    write_analysis(result, tmp_path / "many")
    one, many = tmp_path / "one", tmp_path / "many"
    assert (one / "peaks.csv").read_bytes() == (many / "peaks.csv").read_bytes()
    import pyarrow.parquet as pq

    for name in ("peaks.parquet", "saddles.parquet"):
        a, b = gpd.read_parquet(one / name), gpd.read_parquet(many / name)
        assert a.equals(b) and a.crs == b.crs, name
        assert pq.read_schema(one / name).metadata == pq.read_schema(many / name).metadata, name
        assert pq.ParquetFile(many / name).metadata.num_row_groups == -(-len(a) // 3)
    for layer in ("peaks", "saddles", "ridges"):
        a = gpd.read_file(one / "dividetree.gpkg", layer=layer)
        b = gpd.read_file(many / "dividetree.gpkg", layer=layer)
        assert len(b) == (n if layer == "peaks" else len(b))
        assert a.equals(b), layer
    assert gpd.read_file(many / "dividetree.gpkg", layer="peaks")["peak_id"].tolist() == list(range(n))


def test_geoparquet_files_are_those_of_geopandas(result, tmp_path):
    """peaks/saddles.parquet (written by batches, points made per batch) are byte for byte
    ``GeoDataFrame.to_parquet``'s files, from the GeoDataFrames and from plain tables."""
    from orokit.io.analysis_io import _write_parquet

    for name, table in (("peaks", result.peaks), ("saddles", result.saddles)):
        table.to_parquet(tmp_path / f"{name}_geopandas.parquet")
        _write_parquet(table, tmp_path / f"{name}_orokit.parquet")
        plain = table.drop(columns="geometry")
        assert type(plain).__name__ == "DataFrame"
        _write_parquet(plain, tmp_path / f"{name}_plain.parquet", result.crs)
        want = (tmp_path / f"{name}_geopandas.parquet").read_bytes()
        assert (tmp_path / f"{name}_orokit.parquet").read_bytes() == want, name
        assert (tmp_path / f"{name}_plain.parquet").read_bytes() == want, name


def test_tables_without_geometry_write_the_same_files(result, tmp_path):
    """``analyze(geometry=False)`` (what the CLI runs): plain DataFrames, the same files."""
    import geopandas as gpd

    from orokit.analysis import write_analysis

    lean = orokit.analyze(_dem(), min_prominence_m=5.0, geometry=False)
    assert not isinstance(lean.peaks, gpd.GeoDataFrame) and not isinstance(lean.saddles, gpd.GeoDataFrame)
    assert lean.peaks.equals(result.peaks.drop(columns="geometry"))
    assert lean.saddles.equals(result.saddles.drop(columns="geometry"))
    lean.attrs = dict(result.attrs)  # the same metadata (timings differ between runs)
    write_analysis(lean, tmp_path / "lean")
    write_analysis(result, tmp_path / "geo")
    assert_same_analysis_files(tmp_path / "lean", tmp_path / "geo")


@pytest.mark.parametrize("batch", [None, 3])
def test_tables_made_by_blocks_write_the_same_files(result, tmp_path, monkeypatch, batch):
    """``analyze(blocks=True)`` (what the CLI runs): the peaks table's rows are made by blocks when
    written; the same rows as the whole table, the same bytes of every table file and the same
    GeoPackage layers, with one block and with blocks of 3 rows (several, the last one partial)."""
    import orokit.io.divide_tree_gpkg as gp
    from orokit.analysis import write_analysis
    from orokit.topology.tables import TableBlocks

    lean = orokit.analyze(_dem(), min_prominence_m=5.0, geometry=False, blocks=True)
    assert isinstance(lean.peaks, TableBlocks)
    whole = result.peaks.drop(columns="geometry")
    n = len(whole)
    assert len(lean.peaks) == n > 7
    assert lean.peaks.to_frame().equals(whole)
    assert lean.peaks.block(2, 9).equals(whole.iloc[2:9])
    assert lean.peaks.block(n - 2, n + 5).equals(whole.iloc[n - 2:])
    for c in ("prominence", "lon", "x", "isolation_exact"):
        assert lean.peaks[c].equals(whole[c]), c
    if batch:
        monkeypatch.setattr(gp, "WRITE_BATCH_ROWS", batch)
    lean.attrs = dict(result.attrs)  # the same metadata (timings differ between runs)
    write_analysis(lean, tmp_path / "blocks")
    write_analysis(result, tmp_path / "frames")
    assert_same_analysis_files(tmp_path / "blocks", tmp_path / "frames")


def test_blocks_make_the_places_from_the_cells(result):
    """``analyze(blocks=True)``: the saddles table and the tree's frames are TableBlocks whose places
    (row, col, x, y, elevation) are made from the cells when read: equal, bit for bit, to the frames'
    whole columns, whole, by blocks and gathered at any rows (the ridges' ends)."""
    from orokit.topology.tables import CellPlaces, TableBlocks

    lean = orokit.analyze(_dem(), min_prominence_m=5.0, geometry=False, blocks=True)
    want_s = result.saddles.drop(columns="geometry")
    assert isinstance(lean.saddles, TableBlocks) and lean.saddles.to_frame().equals(want_s)
    assert lean.saddles.block(3, 8).equals(want_s.iloc[3:8])
    rng = np.random.default_rng(0)
    for got, want in ((lean.tree.peaks, result.tree.peaks), (lean.tree.saddles, result.tree.saddles)):
        assert isinstance(got, TableBlocks) and list(got.columns) == list(want.columns) == list(CellPlaces.NAMES)
        assert len(got) == len(want) > 7
        at = rng.integers(0, len(want), 50)
        for c in CellPlaces.NAMES:
            w = want[c].to_numpy()
            assert got[c].to_numpy().tobytes() == w.tobytes(), c
            assert got.take(c, at).tobytes() == w[at].tobytes(), c
    assert lean.tree.edges.equals(result.tree.edges)
    lean.tree.validate()  # the tree's checks read the TableBlocks' elevations


def test_csv_written_by_blocks_is_one_csv_of_the_whole_table(result, tmp_path):
    """peaks.csv by blocks of rows: the bytes of Arrow's one ``write_csv`` of the whole table."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    from orokit.io.analysis_io import _write_csv

    p = result.peaks
    columns = [c for c in p.columns if c != "geometry"]
    whole = pa.Table.from_arrays([pa.Array.from_pandas(p.index), *(pa.Array.from_pandas(p[c]) for c in columns)],
                                 names=["peak_id", *columns])
    pacsv.write_csv(whole, str(tmp_path / "whole.csv"))
    _write_csv(p, tmp_path / "blocks.csv", batch_rows=4)
    assert (tmp_path / "blocks.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()


def test_table_blocks_take_whole_extra_columns(result):
    """Columns set on a TableBlocks (the DEM-error bounds) come after the others in every block."""
    import xarray as xr

    rng = np.random.default_rng(3)
    z = rng.integers(0, 40, (30, 40)).astype(np.float32)
    dem = xr.DataArray(z, dims=("y", "x"), coords={"y": 30.0 * np.arange(30)[::-1] + 15, "x": 30.0 * np.arange(40) + 15})
    a = orokit.analyze(dem, min_prominence_m=5.0, dem_error_m=1.0)
    b = orokit.analyze(dem, min_prominence_m=5.0, dem_error_m=1.0, geometry=False, blocks=True)
    assert list(b.peaks.columns)[-2:] == ["prominence_low", "prominence_high"]
    assert b.peaks.to_frame().equals(a.peaks.drop(columns="geometry"))
    assert b.peaks.block(1, 4).equals(a.peaks.drop(columns="geometry").iloc[1:4])
    with pytest.raises(ValueError, match="needs"):
        b.peaks["bad"] = np.zeros(len(b.peaks) + 1)


def test_table_parents_are_those_of_the_result_tree(result):
    """``build_result`` finds the parents before the places exist (on the elevations and ridges alone):
    the same as the finished Divide Tree's own ``parents()``."""
    want = result.tree.parents()
    for c in ("line_parent", "prominence_parent"):
        assert np.array_equal(result.peaks[c].to_numpy(), want[c].to_numpy()), c
    assert (want["line_parent"] >= 0).any()


def test_table_blocks_do_not_keep_the_engine_output_alive(result):
    """The peak blocks hold the engine's columns they read, not its ``Orometry`` (whose ridge arrays
    and cells, ~24 bytes per peak, are not needed once the tables exist), and still make the rows."""
    import gc
    import weakref

    from affine import Affine
    from pyproj import CRS

    from orokit.topology import engine

    z = _dem().values
    core = engine.orometry(z, min_prominence_m=5.0)
    ref = weakref.ref(core)
    lean = engine.build_result(core, transform=Affine(30.0, 0.0, 0.0, 0.0, -30.0, 900.0), crs=CRS.from_epsg(32633),
                               isolation=None, geometry=False, blocks=True)
    del core
    gc.collect()
    assert ref() is None
    whole = lean.peaks.to_frame()
    assert len(whole) > 7
    np.testing.assert_array_equal(whole["prominence"].to_numpy(), result.peaks["prominence"].to_numpy())


@pytest.mark.parametrize("batch", [None, 3])
def test_tables_whose_own_columns_wait_in_a_store_write_the_same_files(result, tmp_path, monkeypatch, batch):
    """``build_result(blocks=True, store=...)`` (the chunked ``orokit analyze``): the peak table's own
    columns (engine, parents, isolation) go to a column store and each block reads its rows back; the
    same rows and the same files as the frames, and the engine output keeps none of those columns."""
    import orokit.io.divide_tree_gpkg as gp
    from orokit.analysis import write_analysis
    from orokit.io.spill_io import SpilledColumns
    from orokit.metrics.isolation import KernelMetric, finish_isolation, nearest_higher
    from orokit.topology import engine

    dem = _dem()
    z = np.ascontiguousarray(dem.values)
    transform, crs = dem.rio.transform(), dem.rio.crs
    core = engine.orometry(z, min_prominence_m=5.0)
    metric = KernelMetric.from_grid(transform, crs)
    rows, cols = core.peak_row.astype(np.int64), core.peak_col.astype(np.int64)
    best, cand, edge = nearest_higher(z, rows, cols, metric)
    iso = finish_isolation(metric, rows, cols, best, cand, z.shape[1], edge)
    store = SpilledColumns(parent=tmp_path / "spill")
    for name, dtype in engine.ISOLATION_ARRAYS:
        store.put(name, iso[name].to_numpy(dtype))
    import gc
    import weakref

    moved = {f: weakref.ref(getattr(core, f)) for f in engine.SPILLED_OROMETRY}
    lean = engine.build_result(core, transform=transform, crs=crs, isolation=None, geometry=False, blocks=True,
                               store=store)
    gc.collect()
    for f in engine.SPILLED_OROMETRY:
        assert getattr(core, f).size == 0, f  # moved to the store
        assert moved[f]() is None, f  # freed (an empty view [:0] would keep the whole column alive)
    assert len(store) == 4 + len(engine.SPILLED_OROMETRY) + 3 and "line_parent" in store and "saddle_cell" in store
    whole = result.peaks.drop(columns="geometry")
    n = len(whole)
    assert lean.peaks.to_frame().equals(whole)
    assert lean.peaks.block(n - 2, n + 5).equals(whole.iloc[n - 2:])
    assert lean.peaks["isolation"].notna().sum() > 5
    if batch:
        monkeypatch.setattr(gp, "WRITE_BATCH_ROWS", batch)
    lean.attrs = dict(result.attrs)
    write_analysis(lean, tmp_path / "store")
    write_analysis(result, tmp_path / "frames")
    assert_same_analysis_files(tmp_path / "store", tmp_path / "frames")
    folder = store.folder
    del store, lean
    import gc

    gc.collect()
    assert not folder.exists()  # removed with the result that read from it
