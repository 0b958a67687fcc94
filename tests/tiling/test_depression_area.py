"""The chunked area below the spill level equals the in-memory flooding
(orokit.topology.depressions.spill_areas) on tie-heavy grids with NaN holes."""
from __future__ import annotations

import dask.array as da
import numpy as np
from helpers.orometry_oracles import grids, make_dem
from hypothesis import given, settings
from hypothesis import strategies as st

import orokit
from orokit.tiling.depression_area import tiled_spill_areas
from orokit.topology.depressions import spill_areas


def _pits(g, eps):
    """Kept peaks of the engine grid g (the pits of -g) with their key saddle values."""
    p = orokit.analyze(make_dem(g), min_prominence_m=eps, isolation=False).peaks
    spill = np.where(p["island_parent"].to_numpy() < 0, np.nan, p["saddle_elevation"].to_numpy())
    return p["row"].to_numpy(), p["col"].to_numpy(), p["elevation"].to_numpy(), spill


@settings(max_examples=80, deadline=None)
@given(z=grids(14), rows=st.integers(1, 6), cols=st.integers(1, 6), eps=st.sampled_from([0.0, 1.0, 5.0]),
       seed=st.integers(0, 2**16))
def test_chunked_equals_in_memory(z, rows, cols, eps, seed):
    g = np.asarray(z, np.float64)
    row_area = np.random.default_rng(seed).uniform(50, 150, g.shape[0])  # lon/lat-like: one area per row
    r, c, v, s = _pits(z, eps)
    want = spill_areas(g, r, c, row_area)
    got = tiled_spill_areas(da.from_array(g, chunks=(rows, cols)), r, c, v, s, row_area)
    assert np.array_equal(np.isnan(want), np.isnan(got))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)  # sums in another order
    if np.array_equal(g.astype(np.float32), g):  # a float32 raster is swept as float32 (same order, same levels)
        got32 = tiled_spill_areas(da.from_array(g.astype(np.float32), chunks=(rows, cols)), r, c, v, s, row_area)
        assert np.array_equal(np.isnan(want), np.isnan(got32))
        np.testing.assert_allclose(got32, want, rtol=1e-12, atol=0)


def test_nested_lakes_by_hand():
    """A lake holding a smaller one, split across six chunks; the 0 m pit is the deepest (no spill)."""
    g = -np.array([[9, 9, 9, 9, 9, 9, 9],
                   [9, 1, 3, 6, 4, 2, 9],
                   [9, 3, 3, 6, 4, 4, 9],
                   [9, 7, 7, 7, 7, 7, 9],
                   [9, 9, 9, 0, 9, 9, 9]], np.float64)
    r, c, v, s = _pits(g.astype(np.float32), 0.0)
    got = tiled_spill_areas(da.from_array(g, chunks=(2, 3)), r, c, v, s, np.ones(5))
    by_cell = {(int(a), int(b)): x for a, b, x in zip(r, c, got)}
    assert by_cell[1, 1] == 10.0  # h < 7: rows 1-2 inside the rim, the 2 m pit's basin included
    assert by_cell[1, 5] == 4.0  # h < 6: cells 2, 4, 4, 4
    assert np.isnan(by_cell[4, 3])
    assert len(by_cell) == 3
