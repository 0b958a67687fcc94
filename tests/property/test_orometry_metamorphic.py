"""Metamorphic properties of ``orokit.analyze`` and the Divide Tree it returns.

No oracle needed: symmetries of the grid, monotone maps of elevation, pruning and
the tree's own invariants.
"""
from __future__ import annotations

import numpy as np
import pytest
from helpers.orometry_oracles import distinct_grids, flat_domain_cells, grids, make_dem, n_domains
from hypothesis import given, settings
from hypothesis import strategies as st

import orokit

SYMMETRIES = {
    "fliplr": (np.fliplr, lambda r, c, h, w: (r, w - 1 - c)),
    "flipud": (np.flipud, lambda r, c, h, w: (h - 1 - r, c)),
    "rot180": (lambda a: np.rot90(a, 2), lambda r, c, h, w: (h - 1 - r, w - 1 - c)),
    "transpose": (np.transpose, lambda r, c, h, w: (c, r)),
    "rot90": (np.rot90, lambda r, c, h, w: (w - 1 - c, r)),
}


def _peaks(z, eps=0.0, **kw):
    return orokit.analyze(make_dem(np.ascontiguousarray(z)), min_prominence_m=eps, isolation=False, **kw).peaks


def _prom_multiset(peaks):
    return sorted(zip(peaks["elevation"].round(9), peaks["prominence"].round(9)))


@settings(max_examples=120, deadline=None)
@given(z=grids(10), sym=st.sampled_from(sorted(SYMMETRIES)), eps=st.sampled_from([0.0, 1.0, 5.0]))
def test_symmetries_keep_the_prominence_multiset(z, sym, eps):
    f, _ = SYMMETRIES[sym]
    assert _prom_multiset(_peaks(z, eps)) == _prom_multiset(_peaks(f(z), eps))


@settings(max_examples=80, deadline=None)
@given(z=distinct_grids(9), sym=st.sampled_from(sorted(SYMMETRIES)))
def test_symmetries_map_peaks_and_saddles_without_ties(z, sym):
    f, cell_map = SYMMETRIES[sym]
    h, w = z.shape
    a, b = _peaks(z), _peaks(f(z))
    mapped = {cell_map(r, c, h, w): (p, s) for r, c, p, s in
              zip(a["row"], a["col"], a["prominence"], a["saddle_elevation"].fillna(-1))}
    got = {(r, c): (p, s) for r, c, p, s in zip(b["row"], b["col"], b["prominence"], b["saddle_elevation"].fillna(-1))}
    assert got == mapped
    # without ties the key saddle cell is unique: it maps too
    sa = {cell_map(r, c, h, w): cell_map(sr, sc, h, w) for r, c, sr, sc in
          zip(a["row"], a["col"], a["saddle_row"], a["saddle_col"]) if sr >= 0}
    sb = {(r, c): (sr, sc) for r, c, sr, sc in zip(b["row"], b["col"], b["saddle_row"], b["saddle_col"]) if sr >= 0}
    assert sa == sb


@settings(max_examples=80, deadline=None)
@given(z=grids(10), c=st.integers(-50, 2000))
def test_adding_a_constant(z, c):
    a, b = _peaks(z), _peaks(z + np.float32(c))
    assert a["row"].tolist() == b["row"].tolist() and a["col"].tolist() == b["col"].tolist()
    root = a["island_parent"].to_numpy() == -1
    np.testing.assert_array_equal(b["island_parent"].to_numpy() == -1, root)
    for col in ("island_parent", "line_parent"):
        assert a[col].tolist() == b[col].tolist()
    np.testing.assert_allclose(b["prominence"].to_numpy()[~root], a["prominence"].to_numpy()[~root], atol=1e-3)
    np.testing.assert_allclose(b["prominence"].to_numpy()[root], a["prominence"].to_numpy()[root] + c, atol=1e-3)


@settings(max_examples=80, deadline=None)
@given(z=grids(10))
def test_feet_to_metres_scales_prominence(z):
    a = _peaks(z)
    b = _peaks((z.astype(np.float64) * 0.3048).astype(np.float32))
    assert a["row"].tolist() == b["row"].tolist() and a["col"].tolist() == b["col"].tolist()
    np.testing.assert_allclose(b["prominence"], a["prominence"] * 0.3048, rtol=1e-5, atol=1e-4)


@settings(max_examples=80, deadline=None)
@given(z=grids(10), data=st.data())
def test_strictly_increasing_map_keeps_cells(z, data):
    levels = np.unique(z[np.isfinite(z)])
    steps = data.draw(st.lists(st.floats(0.5, 400.0, width=32), min_size=levels.size, max_size=levels.size))
    new = np.cumsum(np.asarray(steps, np.float64)) - 100.0
    mapped = z.copy()
    for old, nv in zip(levels, new.astype(np.float32)):
        mapped[z == old] = nv
    cols = ["row", "col", "saddle_row", "saddle_col", "island_parent", "island_parent_row", "island_parent_col",
            "line_parent", "line_parent_row", "line_parent_col"]
    a, b = _peaks(z), _peaks(mapped)
    assert a[cols].to_numpy().tolist() == b[cols].to_numpy().tolist()


@settings(max_examples=100, deadline=None)
@given(z=grids(10), eps=st.sampled_from([0.5, 1.0, 2.0, 5.0, 20.0]))
def test_pruning_keeps_survivors(z, eps):
    full, pruned = _peaks(z, 0.0), _peaks(z, eps)
    key = ["row", "col"]
    # a domain's root is also kept when another peak of its domain is (its prominence,
    # = elevation, can be below eps when the saddles lie below zero): follow island parents
    rc = list(zip(full["row"], full["col"]))
    par = dict(zip(rc, zip(full["island_parent_row"], full["island_parent_col"])))

    def root(p):
        while par[p][0] >= 0:
            p = (int(par[p][0]), int(par[p][1]))
        return p

    big = full["prominence"].to_numpy() >= eps
    roots_needed = {root(p) for p, b in zip(rc, big) if b}
    kept = full[big | np.array([p in roots_needed for p in rc], bool)]
    cols = ["row", "col", "prominence", "saddle_row", "saddle_col", "saddle_elevation", "island_parent_row", "island_parent_col"]
    np.testing.assert_array_equal(
        kept.sort_values(key)[cols].to_numpy(float), pruned.sort_values(key)[cols].to_numpy(float)
    )


def _check_tree(z, eps):
    res = orokit.analyze(make_dem(z), min_prominence_m=eps, isolation=False)
    peaks, tree = res.peaks, res.tree
    tree.validate()  # ids, acyclic, saddles below both ends
    assert tree.n_peaks == len(peaks)
    np.testing.assert_array_equal(tree.peaks["elevation"].to_numpy(float), peaks["elevation"].to_numpy(float))
    table = tree.prominence_table()
    np.testing.assert_allclose(table["prominence"].to_numpy(), peaks["prominence"].to_numpy(), atol=1e-9)
    np.testing.assert_array_equal(table["island_parent"].to_numpy() == -1, peaks["island_parent"].to_numpy() == -1)
    # each non-root peak's key saddle is one of the tree's saddles
    if "row" in tree.saddles.columns:
        tree_saddles = set(zip(tree.saddles["row"].astype(int), tree.saddles["col"].astype(int)))
        for sr, sc in zip(peaks["saddle_row"], peaks["saddle_col"]):
            if sr >= 0:
                assert (int(sr), int(sc)) in tree_saddles
    return peaks, tree


@settings(max_examples=100, deadline=None)
@given(z=grids(10))
def test_tree_spans_each_domain_at_eps0(z):
    peaks, tree = _check_tree(z, 0.0)
    domains = n_domains(np.where(flat_domain_cells(z), np.nan, z))
    assert len(tree.edges) == tree.n_peaks - domains
    assert int((peaks["island_parent"] == -1).sum()) == domains


@settings(max_examples=60, deadline=None)
@given(z=grids(10), eps=st.sampled_from([1.0, 3.0, 10.0]))
def test_pruned_tree_invariants(z, eps):
    _check_tree(z, eps)


@pytest.mark.parametrize("eps", [0.0, 2.0])
def test_written_tree_reads_back(tmp_path, eps):
    from orokit.io.divide_tree_io import read_divide_tree_gpkg, write_divide_tree_gpkg

    z = np.array([[1, 5, 1, 1, 7], [1, 2, 1, 3, 1], [4, 1, 1, 1, 6]], np.float32)
    tree = orokit.analyze(make_dem(z), min_prominence_m=eps).tree
    back = read_divide_tree_gpkg(write_divide_tree_gpkg(tree, tmp_path / "t.gpkg"))
    assert back.equals(tree)
    assert back.crs is not None and back.crs.to_epsg() == 32633
