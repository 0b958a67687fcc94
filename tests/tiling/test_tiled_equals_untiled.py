"""The chunked (dask) engine gives exactly the in-memory engine's tables."""
from __future__ import annotations

import dask.array as da
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import orokit
from orokit.analysis import write_analysis
from orokit.errors import TilingError
from orokit.tiling.summary import chunk_summary, finalize_summary, merge_summaries
from orokit.topology.engine import orometry

from helpers.outputs import assert_same_table_files
from helpers.ridges import orometry_ridges, ridge_set

FIELDS = ["peak_cell", "peak_z", "prominence", "key_saddle_cell", "parent", "prominence_exact"]


def _assert_same_tables(a, b):
    """Every column (line and prominence parents included) and the same pruned Divide Tree."""
    cols = [c for c in a.peaks.columns if c != "geometry"]
    assert {"island_parent", "line_parent", "prominence_parent"} <= set(cols)
    for c in cols:
        np.testing.assert_array_equal(a.peaks[c].to_numpy(), b.peaks[c].to_numpy(), err_msg=c)
    sc = [c for c in a.saddles.columns if c != "geometry"]
    for c in sc:
        np.testing.assert_array_equal(a.saddles[c].to_numpy(), b.saddles[c].to_numpy(), err_msg=c)
    assert a.tree.n_peaks == b.tree.n_peaks
    assert ridge_set(a.tree) == ridge_set(b.tree)
    np.testing.assert_array_equal(a.tree.prominence(), b.tree.prominence())


@st.composite
def grids(draw):
    h = draw(st.integers(1, 12))
    w = draw(st.integers(1, 12))
    levels = draw(st.integers(2, 6))
    z = np.array(draw(st.lists(st.integers(0, levels - 1), min_size=h * w, max_size=h * w)), float).reshape(h, w)
    holes = draw(st.lists(st.booleans(), min_size=h * w, max_size=h * w))
    if draw(st.booleans()):
        z[np.array(holes).reshape(h, w) & (np.arange(h * w).reshape(h, w) % 3 == 0)] = np.nan
    ch = draw(st.integers(1, h))
    cw = draw(st.integers(1, w))
    return z, ch, cw


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grids(), st.sampled_from([0.0, 0.0, 1.0, 2.0]), st.sampled_from(["unknown", "sea"]), st.booleans(),
       st.booleans(), st.booleans())
def test_chunk_summaries_merge_exactly(case, eps, outside, consume, reduce_root, narrow):
    """Summaries over any chunking (1-row chunks, chunks cutting plateaus) merge to the exact result,
    also when each merge frees its inputs (``consume``, as the engine's merge tasks do) and when the
    last merge hands its graph to the finalize uncontracted (``reduce_root=False``, as the engine's root).
    ``narrow``: a float32 raster of values not exact in binary (tenths), whose root the finalize takes with
    float32 node values: the prominences are still the float64 subtractions of the in-memory engine."""
    z, ch, cw = case
    assume(not np.isnan(z).all())
    if narrow:
        z = (z * 0.1).astype(np.float32)
        eps = eps * 0.1
    H, W = z.shape
    zp = np.pad(z, 1, constant_values=np.nan)
    rb, cb = list(range(0, H, ch)) + [H], list(range(0, W, cw)) + [W]
    tiles = {
        (i, j): chunk_summary(zp[rb[i]:rb[i + 1] + 2, cb[j]:cb[j + 1] + 2], rb[i], cb[j], (H, W), eps)
        for i in range(len(rb) - 1) for j in range(len(cb) - 1)
    }
    # merge in raster order (row strips first), unlike the engine's halving order
    nr, nc = len(rb) - 1, len(cb) - 1
    rows = []
    for i in range(nr):
        s = tiles[i, 0]
        for j in range(1, nc):
            last = nr == 1 and j == nc - 1
            s = merge_summaries(s, tiles[i, j], eps, consume=consume, reduce=reduce_root or not last)
        rows.append(s)
    s = rows[0]
    for k, r in enumerate(rows[1:]):
        s = merge_summaries(s, r, eps, consume=consume, reduce=reduce_root or k < nr - 2)
    if consume and len(rows) > 1:
        assert rows[0].consumed and rows[0].n_nodes == 0 and rows[-1].ea.size == 0
        with pytest.raises(TilingError, match="already merged"):
            merge_summaries(rows[0], s, eps)
    a = orometry(z, min_prominence_m=eps, outside=outside)
    b = finalize_summary(s, min_prominence_m=eps, outside=outside)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
        assert getattr(a, f).dtype == getattr(b, f).dtype, f
    assert a.n_maxima == b.n_maxima
    # the same pruned Divide Tree: every ridge joins the same two peaks through the same saddle
    assert orometry_ridges(a) == orometry_ridges(b)


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(grids(), st.sampled_from([0.0, 1.0]))
def test_dask_analyze_equals_in_memory(make_dem, case, eps):
    z, ch, cw = case
    assume(not np.isnan(z).all())
    dem = make_dem(z, res=(30.0, 20.0))
    a = orokit.analyze(dem, min_prominence_m=eps)
    b = orokit.analyze(dem.copy(data=da.from_array(z, chunks=(ch, cw))), min_prominence_m=eps, scheduler="synchronous")
    _assert_same_tables(a, b)


@pytest.mark.realdata
@pytest.mark.parametrize("eps", [0.0, 30.48])
def test_real_dem_in_many_chunks(real_data, eps):
    from orokit.io.dem import read_dem

    from orokit.data import open_dataset_dem

    real_data("norway")
    dem = open_dataset_dem("norway")
    a = orokit.analyze(dem, min_prominence_m=eps)
    b = orokit.analyze(dem, min_prominence_m=eps, chunks=(97, 130))
    assert b.attrs["engine"] == "tiled" and a.attrs["engine"] == "in-memory"
    assert len(a.peaks) > 100
    _assert_same_tables(a, b)


@pytest.mark.realdata
def test_geographic_geotiff_with_nodata_chunked(real_data):
    from orokit.io.dem import read_dem

    dem = read_dem(real_data("pysheds-dem"))
    a = orokit.analyze(dem, min_prominence_m=0)
    b = orokit.analyze(dem, min_prominence_m=0, chunks=64)
    _assert_same_tables(a, b)


@pytest.mark.realdata
def test_mosaic_of_geotiff_tiles_and_vrt(real_data, tmp_path):
    """Several DEMs written as separate GeoTIFF tiles + a VRT, with a void across a seam."""
    import rasterio
    from rasterio.transform import from_origin

    from orokit.io.dem import read_dem
    from orokit.io.mosaic import build_vrt

    from orokit.data import open_dataset_dem

    real_data("rockies"), real_data("alaska")
    z1 = open_dataset_dem("rockies").values
    z2 = open_dataset_dem("alaska").values
    big = np.block([[z1, z2], [z2[::-1], z1[:, ::-1]]])
    big[600:700, 500:800] = np.nan
    res = 92.61
    paths = []
    for i in range(0, big.shape[0], 500):
        for j in range(0, big.shape[1], 400):
            t = big[i:i + 500, j:j + 400]
            p = tmp_path / f"tile_{i}_{j}.tif"
            with rasterio.open(p, "w", driver="GTiff", width=t.shape[1], height=t.shape[0], count=1, dtype="float32",
                               crs="EPSG:32611", transform=from_origin(500000 + j * res, 4000000 - i * res, res, res),
                               nodata=-9999) as ds:
                ds.write(np.where(np.isnan(t), -9999, t).astype("float32"), 1)
            paths.append(p)
    vrt = build_vrt(paths, tmp_path / "mosaic.vrt")
    lazy = read_dem(vrt, chunks=300)
    assert lazy.chunks is not None
    eager = read_dem(tmp_path)  # a directory of tiles
    np.testing.assert_array_equal(np.isnan(eager.values), np.isnan(big))
    a = orokit.analyze(eager, min_prominence_m=30)
    b = orokit.analyze(lazy, min_prominence_m=30)
    _assert_same_tables(a, b)


def test_checkpoint_resume_and_mismatch(make_dem, tmp_path, monkeypatch):
    import orokit.tiling.engine as te
    from orokit.errors import TilingError

    rng = np.random.default_rng(3)
    z = rng.normal(size=(60, 70)).cumsum(0).cumsum(1)
    dem = make_dem(z)
    ck = tmp_path / "ck"
    a = orokit.analyze(dem, min_prominence_m=1.0, chunks=20, checkpoint=ck, scheduler="synchronous")
    files = sorted(ck.glob("chunk_*.npz"))
    assert len(files) == 12
    files[0].unlink()  # an interrupted run: one chunk missing
    calls = []
    real = te.chunk_summary
    monkeypatch.setattr(te, "chunk_summary", lambda *args, **kw: calls.append(args[1:3]) or real(*args, **kw))
    b = orokit.analyze(dem, min_prominence_m=1.0, chunks=20, checkpoint=ck, scheduler="synchronous")
    assert calls == [(0, 0)]  # only the missing chunk was recomputed
    _assert_same_tables(a, b)
    assert len(sorted(ck.glob("chunk_*.npz"))) == 12
    with pytest.raises(TilingError, match="another run"):
        orokit.analyze(dem, min_prominence_m=2.0, chunks=20, checkpoint=ck)


def test_large_rasters_are_planned_chunked(tmp_path, monkeypatch):
    """A raster too large for the free memory is analysed chunk by chunk automatically."""
    import rasterio
    from rasterio.transform import from_origin

    import orokit.analysis as an

    rng = np.random.default_rng(0)
    z = rng.normal(size=(300, 200)).cumsum(0).cumsum(1).astype("float32")
    p = tmp_path / "dem.tif"
    with rasterio.open(p, "w", driver="GTiff", width=200, height=300, count=1, dtype="float32", crs="EPSG:32633",
                       transform=from_origin(500000, 4000000, 30, 30)) as ds:
        ds.write(z, 1)
    assert an.plan_chunks(p) is None
    monkeypatch.setattr(an, "available_memory", lambda: 1_000_000)  # pretend 1 MB is free
    monkeypatch.setattr(an, "AUTO_CHUNK", 128)
    assert an.plan_chunks(p) == 128
    chunked = orokit.analyze(str(p), min_prominence_m=5)
    assert chunked.attrs["engine"] == "tiled"
    monkeypatch.undo()
    in_memory = orokit.analyze(str(p), min_prominence_m=5)
    assert in_memory.attrs["engine"] == "in-memory"
    _assert_same_tables(in_memory, chunked)


def test_concurrent_writers_are_refused(make_dem, tmp_path):
    import fcntl
    import os

    from orokit.errors import OutputError
    from orokit.io.atomic import lock_path_for

    r = orokit.analyze(make_dem(np.arange(30.0).reshape(5, 6) % 7), min_prominence_m=0)
    out = tmp_path / "out"
    fd = os.open(lock_path_for(out), os.O_RDWR | os.O_CREAT)  # held as by another process
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        with pytest.raises(OutputError, match="another orokit process"):
            write_analysis(r, out)
    finally:
        os.close(fd)
    write_analysis(r, out)
    assert (out / "analysis.json").exists()


@pytest.mark.realdata
def test_tiled_tables_made_by_blocks_write_the_in_memory_files(real_data, tmp_path, monkeypatch):
    """What ``orokit analyze --chunks`` writes (the peaks table made by blocks of rows from the
    tiled engine's arrays) is the in-memory engine's files: the same bytes of peaks.csv,
    peaks.parquet and saddles.parquet, the same GeoPackage layers; with several blocks."""
    import geopandas as gpd

    import orokit.io.divide_tree_gpkg as gp
    from orokit.data import open_dataset_dem

    real_data("norway")
    dem = open_dataset_dem("norway")
    a = orokit.analyze(dem, min_prominence_m=30.48)
    b = orokit.analyze(dem, min_prominence_m=30.48, chunks=(97, 130), geometry=False, blocks=True)
    assert b.attrs["engine"] == "tiled" and len(a.peaks) > 300
    monkeypatch.setattr(gp, "WRITE_BATCH_ROWS", 128)
    b.attrs = dict(a.attrs)  # the same metadata (engine, timings)
    write_analysis(a, tmp_path / "a")
    write_analysis(b, tmp_path / "b")
    assert_same_table_files(tmp_path / "a", tmp_path / "b")
    for layer in ("peaks", "saddles", "ridges"):
        la = gpd.read_file(tmp_path / "a" / "dividetree.gpkg", layer=layer)
        lb = gpd.read_file(tmp_path / "b" / "dividetree.gpkg", layer=layer)
        if layer == "ridges":  # the same ridges; the engines list and orient them differently
            def ridges(f):
                a, b = f["peak_a"].to_numpy(), f["peak_b"].to_numpy()
                return sorted(zip(np.minimum(a, b), np.maximum(a, b), f["saddle"], f["saddle_elevation"]))
            assert ridges(la) == ridges(lb)
        else:
            assert la.equals(lb), layer
