"""Isolation settled inside one chunk (``chunk_isolation``) against the in-memory search."""
from __future__ import annotations

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from orokit.metrics.isolation import KernelMetric, isolation
from orokit.tiling.isolation import chunk_isolation

GRIDS = {
    "projected": (Affine(30.0, 0.0, 500000.0, 0.0, -30.0, 4000000.0), CRS.from_epsg(32633)),
    "geographic": (Affine(0.001, 0.0, 10.0, 0.0, -0.001, 46.0), CRS.from_epsg(4326)),
}


@pytest.mark.parametrize("grid", GRIDS)
def test_chunk_isolation_agrees_with_in_memory_and_keeps_only_used_candidates(grid):
    transform, crs = GRIDS[grid]
    rng = np.random.default_rng(3)
    z = np.round(rng.normal(size=(60, 70)).cumsum(axis=0) + rng.normal(size=(60, 70)), 1)
    H, W = z.shape
    r0, r1, c0, c1 = 20, 45, 15, 50
    core = np.ascontiguousarray(z[r0:r1, c0:c1])
    rr, cc = np.mgrid[r0:r1, c0:c1]
    keys = (rr * W + cc).ravel()
    metric = KernelMetric.from_grid(transform, crs)
    got = chunk_isolation(core, r0, c0, (H, W), keys, metric)
    assert got["key"].size > 100  # most cells find higher ground inside the chunk
    cand = got["cand"]
    # candidates fill each row from the left, and no column is unused (was ncand: 8 or 64 columns)
    assert 1 <= cand.shape[1] < metric.ncand
    assert (cand[:, -1] >= 0).any()
    valid = cand >= 0
    assert not (valid[:, 1:] & ~valid[:, :-1]).any()
    want = isolation(z, got["key"] // W, got["key"] % W, transform=transform, crs=crs)
    target = want["isolation_row"].to_numpy() * W + want["isolation_col"].to_numpy()
    assert (target >= 0).all()
    assert (cand == target[:, None]).any(axis=1).all()  # the in-memory answer is among the candidates
    if grid == "projected":
        np.testing.assert_allclose(got["best"], want["isolation"].to_numpy(), rtol=1e-12)


@pytest.mark.parametrize("grid", GRIDS)
def test_tiled_isolation_with_a_tiny_chunk_cache_and_small_batches_equals_in_memory(grid, monkeypatch):
    """Every chunk leaves the search's cache as soon as it is not in use (budget 1 byte):
    same table as the in-memory search; chunks are read again instead of kept. Cells next
    to the void whose higher ground is as far as the void are not exact (a NaN chunk at a
    distance equal to the target was skipped before)."""
    import dask.array as da

    from orokit.tiling import isolation as tiso

    transform, crs = GRIDS[grid]
    rng = np.random.default_rng(5)
    z = np.round(rng.normal(size=(90, 100)).cumsum(axis=0) + 3 * rng.normal(size=(90, 100)), 1)
    z[40:44, 10:30] = np.nan  # a void: the NaN pyramids are read back too
    H, W = z.shape
    peaks = np.flatnonzero(np.isfinite(z.ravel()))[::7]
    rows, cols = peaks // W, peaks % W
    want = isolation(z, rows, cols, transform=transform, crs=crs)
    data = da.from_array(z, chunks=(20, 25))
    loads = {}
    for budget in (tiso._CACHE_BYTES, 1):
        monkeypatch.setattr(tiso, "_CACHE_BYTES", budget)
        # with the tiny budget, batches of 64 peaks too (the bounds of a batch: 64 x 20 chunks)
        monkeypatch.setattr(tiso, "_BOUNDS_CELLS", 2**20 if budget > 1 else 1)
        real_init = tiso._BlockCache.__init__

        def init(self, *a, **k):
            real_init(self, *a, **k)
            loads[budget] = self

        monkeypatch.setattr(tiso._BlockCache, "__init__", init)
        got = tiso.tiled_isolation(data, rows, cols, z.ravel()[peaks], transform=transform, crs=crs,
                                   compute=lambda objs: [np.asarray(o.compute(scheduler="sync")) for o in objs])
        monkeypatch.setattr(tiso._BlockCache, "__init__", real_init)
        assert got.equals(want)
    assert loads[1].loads > loads[256 * 2**20].loads  # chunks were dropped and read again
    assert len(loads[1].entries) <= 9  # at most the chunks of one step stay


@pytest.mark.parametrize("grid", GRIDS)
def test_float32_chunks_are_searched_in_float32_without_copies(grid):
    """A float32 raster: the search pyramid of a chunk without NaN is the chunk itself, that of a
    chunk with NaN a float32 copy (was float64: twice the memory, so the cross-chunk cache held
    half as many chunks); the chunk and cross-chunk searches give the in-memory table."""
    import dask.array as da

    from orokit.tiling import isolation as tiso

    transform, crs = GRIDS[grid]
    rng = np.random.default_rng(11)
    z = (rng.normal(size=(80, 90)).cumsum(axis=1) + rng.normal(size=(80, 90))).astype(np.float32)
    z[50:53, 5:40] = np.nan
    block = np.ascontiguousarray(z[:20, :30])
    zz, *_ = tiso._search_pyramid(block, False)
    assert zz is block
    hole = np.ascontiguousarray(z[40:60, :30])
    zz, *_ = tiso._search_pyramid(hole, True)
    assert zz.dtype == np.float32 and np.isneginf(zz[np.isnan(hole)]).all() and np.isnan(hole).any()
    assert np.array_equal(zz[~np.isnan(hole)], hole[~np.isnan(hole)])
    H, W = z.shape
    peaks = np.flatnonzero(np.isfinite(z.ravel()))[::5]
    rows, cols = peaks // W, peaks % W
    want = isolation(z, rows, cols, transform=transform, crs=crs)
    metric = KernelMetric.from_grid(transform, crs)
    known = [chunk_isolation(np.ascontiguousarray(z[r:r + 20, c:c + 30]), r, c, (H, W),
                             peaks[(rows >= r) & (rows < r + 20) & (cols >= c) & (cols < c + 30)], metric)
             for r in range(0, H, 20) for c in range(0, W, 30)]
    known = {f: np.concatenate([k[f] for k in known]) if f != "cand" else None for f in ("key", "best", "nan", "cand")}
    width = 64
    known["cand"] = np.full((known["key"].size, width), -1, np.int64)
    i = 0
    for r in range(0, H, 20):
        for c in range(0, W, 30):
            sel = peaks[(rows >= r) & (rows < r + 20) & (cols >= c) & (cols < c + 30)]
            k = chunk_isolation(np.ascontiguousarray(z[r:r + 20, c:c + 30]), r, c, (H, W), sel, metric)
            known["cand"][i:i + k["key"].size, :k["cand"].shape[1]] = k["cand"]
            i += k["key"].size
    assert 0 < known["key"].size < peaks.size  # some settled in their chunk, some searched across chunks
    got = tiso.tiled_isolation(da.from_array(z, chunks=(20, 30)), rows, cols, z.ravel()[peaks].astype(np.float64),
                               transform=transform, crs=crs, known=known,
                               compute=lambda objs: [np.asarray(o.compute(scheduler="sync")) for o in objs])
    assert got.equals(want)


@pytest.mark.parametrize("grid", GRIDS)
def test_tiled_isolation_with_settled_peaks_finished_in_small_blocks_equals_in_memory(grid, monkeypatch):
    """Peaks settled in their chunks (``known``, released once read) and the others searched across
    chunks, the nearest candidate chosen in blocks of 7 peaks: the in-memory table."""
    import dask.array as da

    from orokit.tiling import isolation as tiso
    from orokit.tiling.engine import _merge_iso

    transform, crs = GRIDS[grid]
    rng = np.random.default_rng(8)
    z = np.round(rng.normal(size=(70, 80)).cumsum(axis=1) + 2 * rng.normal(size=(70, 80)), 1)
    z[30:33, 50:70] = np.nan
    H, W = z.shape
    peaks = np.flatnonzero(np.isfinite(z.ravel()))[::5]
    rows, cols = peaks // W, peaks % W
    want = isolation(z, rows, cols, transform=transform, crs=crs)
    metric = KernelMetric.from_grid(transform, crs)
    ch, cw = 25, 30
    parts = []
    for r0 in range(0, H, ch):
        for c0 in range(0, W, cw):
            core = np.ascontiguousarray(z[r0:r0 + ch, c0:c0 + cw])
            mine = peaks[(rows >= r0) & (rows < r0 + ch) & (cols >= c0) & (cols < c0 + cw)]
            parts.append(chunk_isolation(core, r0, c0, (H, W), mine, metric))
    known = _merge_iso(parts)
    n_known = known["key"].size
    assert 0 < n_known < peaks.size  # some settled in their chunk, some searched across chunks
    monkeypatch.setattr(tiso, "_FINISH_ROWS", 7)
    got = tiso.tiled_isolation(da.from_array(z, chunks=(ch, cw)), rows, cols, z.ravel()[peaks],
                               transform=transform, crs=crs, known=known, release_known=True,
                               compute=lambda objs: [np.asarray(o.compute(scheduler="sync")) for o in objs])
    assert known == {}
    assert got.equals(want)
    assert all(not p for p in parts)  # merged parts are emptied: the merge owns them


@pytest.mark.parametrize("grid", GRIDS)
def test_tiled_isolation_of_unordered_peaks_with_extra_settled_cells_equals_in_memory(grid):
    """Peaks not in raster order, float32 elevations, and settled isolation of more cells than the
    peaks (``known`` rows that are no peak here are left out): the in-memory table, row for row."""
    import dask.array as da

    from orokit.tiling import isolation as tiso
    from orokit.tiling.engine import _merge_iso

    transform, crs = GRIDS[grid]
    rng = np.random.default_rng(11)
    z = np.round(rng.normal(size=(60, 75)).cumsum(axis=0) + 2 * rng.normal(size=(60, 75)), 1).astype(np.float32)
    H, W = z.shape
    cells = np.flatnonzero(np.isfinite(z.ravel()))[::3]
    peaks = rng.permutation(cells[::2])  # every other settled cell is a peak, in no particular order
    rows, cols = peaks // W, peaks % W
    metric = KernelMetric.from_grid(transform, crs)
    ch, cw = 20, 25
    parts = []
    for r0 in range(0, H, ch):
        for c0 in range(0, W, cw):
            r, c = cells // W, cells % W
            mine = cells[(r >= r0) & (r < r0 + ch) & (c >= c0) & (c < c0 + cw)]
            parts.append(chunk_isolation(np.ascontiguousarray(z[r0:r0 + ch, c0:c0 + cw]), r0, c0, (H, W), mine,
                                         metric))
    known = _merge_iso(parts)
    assert np.isin(known["key"], peaks, invert=True).any() and np.isin(known["key"], peaks).any()
    got = tiso.tiled_isolation(da.from_array(z, chunks=(ch, cw)), rows, cols, z.ravel()[peaks],
                               transform=transform, crs=crs, known=known, release_known=True,
                               compute=lambda objs: [np.asarray(o.compute(scheduler="sync")) for o in objs])
    assert got.equals(isolation(z, rows, cols, transform=transform, crs=crs))


def test_cell_places_are_int32_rows_and_columns_made_by_blocks(monkeypatch):
    from orokit.tiling import isolation as tiso

    monkeypatch.setattr(tiso, "_FINISH_ROWS", 4)
    cell = np.array([0, 5, 17, 2**33 + 9, 123456789], np.int64)
    rows, cols = tiso.cell_places(cell, 2**20)
    assert rows.dtype == cols.dtype == np.int32
    assert rows.tolist() == (cell // 2**20).tolist() and cols.tolist() == (cell % 2**20).tolist()
    big_rows, _ = tiso.cell_places(np.array([2**62], np.int64), 3)
    assert big_rows.dtype == np.int64 and big_rows[0] == 2**62 // 3
    empty = tiso.cell_places(np.empty(0, np.int64), 7)
    assert empty[0].size == 0 and empty[0].dtype == np.int32
