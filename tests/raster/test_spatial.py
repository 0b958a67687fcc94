"""KD-tree queries in Z order (orokit.raster.spatial) give cKDTree.query's arrays, ties included."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from orokit.raster import spatial
from orokit.raster.spatial import morton_order, query


def _points(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, 90_000.0, (n, 2))
    # ties: duplicated points and a lattice, where several tree points are equally far from a query
    xy[: n // 10] = xy[n // 10: 2 * (n // 10)]
    g = np.arange(0.0, 2000.0, 50.0)
    lat = np.column_stack([np.repeat(g, g.size), np.tile(g, g.size)])
    return np.concatenate([xy, lat])


@pytest.mark.parametrize("k", [1, 3, 16])
@pytest.mark.parametrize("workers", [1, -1])
def test_query_equals_ckdtree(k, workers):
    tree_xy = _points(20_000, 0)
    tree = cKDTree(tree_xy)
    # the lattice's points are also asked: equal distances to several lattice and duplicated tree points
    asked = np.concatenate([_points(30_000, 1), tree_xy[::7] + 25.0])
    assert asked.shape[0] >= spatial.MIN_ORDERED and tree.n >= spatial.MIN_TREE
    want_d, want_i = tree.query(asked, k=k, workers=workers)
    got_d, got_i = query(tree, asked, k=k, workers=workers)
    assert got_d.shape == want_d.shape and got_i.shape == want_i.shape
    assert got_i.dtype == want_i.dtype
    assert np.array_equal(got_d, want_d) and np.array_equal(got_i, want_i)
    # the order helped: the Z-order is not the callers' order
    assert not np.array_equal(morton_order(asked), np.arange(asked.shape[0]))


def test_query_small_and_non_finite_fall_back():
    tree = cKDTree(_points(1000, 2))
    small = _points(100, 3)
    want = tree.query(small, k=2, workers=-1)
    got = query(tree, small, k=2)
    assert all(np.array_equal(w, g) for w, g in zip(want, got))
    # a non-finite point: cKDTree's own error, as without the order
    bad = np.concatenate([_points(6000, 4), [[np.nan, 1.0]]])
    with pytest.raises(ValueError) as want_err:
        tree.query(bad, k=2, workers=-1)
    with pytest.raises(ValueError) as got_err:
        query(tree, bad, k=2)
    assert str(got_err.value) == str(want_err.value)


def test_morton_order_is_a_local_permutation():
    xy = _points(5000, 5)
    o = morton_order(xy)
    assert np.array_equal(np.sort(o), np.arange(xy.shape[0]))
    # consecutive points along the curve are much nearer each other than in the given (random) order
    step = np.hypot(*np.diff(xy[o], axis=0).T)
    given = np.hypot(*np.diff(xy, axis=0).T)
    assert np.median(step) < 0.1 * np.median(given)
