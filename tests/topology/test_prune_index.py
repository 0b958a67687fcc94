"""The prune's union-find state and output indices in the narrowest integer type: the same result."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.topology import _kernels


def _graph(seed: int, n: int = 400, extra: int = 300):
    rng = np.random.default_rng(seed)
    z = np.round(rng.normal(size=n) * 3, 0)  # ties on purpose
    key = rng.permutation(n).astype(np.int64)
    a = np.concatenate([np.arange(1, n), rng.integers(0, n, extra)])
    b = np.concatenate([rng.integers(0, np.arange(1, n)), rng.integers(0, n, extra)])
    ok = a != b
    a, b = a[ok], b[ok]
    ez = np.minimum(z[a], z[b]) - rng.integers(0, 3, a.size)
    ekey = rng.integers(0, n // 2, a.size)  # shared saddle cells: monkey saddles
    order = np.lexsort((ekey, -ez))
    keep = rng.random(n) < 0.3
    bmax = np.where(rng.random(n) < 0.2, z - 1, -np.inf)
    nmin = z - rng.integers(0, 5, n)
    return n, a[order], b[order], ez[order], ekey[order], keep, bmax, nmin, z, key


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("defer", [False, True])
def test_int32_indices_prune_as_int64(seed, defer):
    n, a, b, ez, ekey, keep, bmax, nmin, z, key = _graph(seed)
    assert _kernels.index_like(n, a.size).dtype == np.int32
    wide = _kernels.prune_edges(n, a, b, ez, ekey, keep, bmax.copy(), nmin.copy(), z, key, defer,
                                np.empty(0, np.int64))
    given_b, given_m = bmax.copy(), nmin.copy()
    narrow = _kernels.prune_edges(n, a, b, ez, ekey, keep, given_b, given_m, z, key, defer,
                                  _kernels.index_like(n, a.size))
    assert narrow[0].size > 10
    for i, (w, x) in enumerate(zip(wide, narrow)):
        np.testing.assert_array_equal(w, x, err_msg=str(i))
    assert narrow[0].dtype == narrow[1].dtype == narrow[2].dtype == np.int32
    if defer:  # the carried values are written over the arrays given
        np.testing.assert_array_equal(given_b, narrow[3])
        np.testing.assert_array_equal(given_m, narrow[4])
        assert not np.array_equal(given_b, bmax) or not np.array_equal(given_m, nmin)


def test_index_type_widens_at_two_to_the_31():
    assert _kernels.index_like(2**31 - 2).dtype == np.int32
    assert _kernels.index_like(10, 2**31).dtype == np.int64


@pytest.mark.parametrize("seed", range(6))
def test_int32_sweep_as_int64(seed):
    """kruskal_sweep_like with int32 state: the int64 sweep's forest, key edges, parents and flags."""
    n, a, b, ez, ekey, keep, bmax, nmin, z, key = _graph(seed)
    want = _kernels.kruskal_sweep(z, key, a, b, ez, ekey, bmax)
    got = _kernels.kruskal_sweep_like(z, key, a, b, ez, ekey, bmax, np.empty(0, np.int32))
    assert got[1].dtype == got[2].dtype == np.int32
    for w, g in zip(want, got):
        np.testing.assert_array_equal(g, w)


@pytest.mark.parametrize("seed", range(6))
def test_components_of_the_used_edges_and_flat_roots(seed):
    """forest_components_like over the edges ``use`` marks (int32) is forest_components of those edges,
    and flat_roots is the numpy formula it replaces (a domain's minimum, NaN propagated)."""
    n, a, b, ez, ekey, keep, bmax, nmin, z, key = _graph(seed)
    use = np.random.default_rng(seed).random(a.size) < 0.5
    want = _kernels.forest_components(n, a[use], b[use])
    got = _kernels.forest_components_like(n, a, b, use, np.empty(0, np.int32))
    assert got.dtype == np.int32
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(_kernels.forest_components_like(n, a, b, np.empty(0, bool), np.empty(0, np.int32)),
                                  _kernels.forest_components(n, a, b))
    is_root = want == np.arange(n)
    nmin = nmin.copy()
    nmin[np.random.default_rng(seed).random(n) < 0.01] = np.nan
    for lo in (nmin, nmin - 100, np.where(np.isnan(nmin), z, z + 1)):
        dmin = np.full(n, np.inf)
        with np.errstate(invalid="ignore"):
            np.minimum.at(dmin, want, lo)
            want_flat = is_root & (dmin[want] >= z)
        np.testing.assert_array_equal(_kernels.flat_roots(want, lo, z, is_root), want_flat)
