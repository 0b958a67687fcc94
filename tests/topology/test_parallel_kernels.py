"""The in-memory engine's parallel kernels equal the sequential (tiled-engine) kernels,
and results do not depend on the number of threads."""
from __future__ import annotations

import numba
import numpy as np
import pytest

from orokit.topology import _kernels, engine


def _sequential(z):
    ptr, _, border = _kernels.steepest_ascent(np.pad(z, 1, constant_values=np.nan))
    label, max_cell = _kernels.label_basins(ptr)
    n = max_cell.size
    ea, eb, ec = _kernels.basin_passes(z, label, n)
    return (label, max_cell, _kernels.basin_border_max(z, label, border, n), _kernels.basin_min(z, label, n),
            sorted(zip(ea.tolist(), eb.tolist(), ec.tolist())))


def _grids():
    rng = np.random.default_rng(13)
    for t in range(60):
        h = int(rng.integers(1, 300 if t % 4 == 0 else 40))
        w = int(rng.integers(1, 40))
        z = rng.integers(0, int(rng.integers(1, 6)), (h, w)).astype(np.float32 if t % 2 else np.float64)
        if t % 3 == 0:
            z[rng.random(z.shape) < 0.2] = np.nan
        if not np.isnan(z).all():
            yield z


@pytest.mark.parametrize("label_dtype", [np.int32, np.int64])
def test_parallel_ascent_equals_sequential(label_dtype):
    n_tall = 0
    for z in _grids():
        label, max_cell, bmax, nmin, edges = _sequential(z)
        lab = np.empty(z.size, label_dtype)
        got_max = _kernels.ascent_labels(z, lab)
        np.testing.assert_array_equal(lab, label)
        np.testing.assert_array_equal(got_max, max_cell)
        n_tall += z.shape[0] >= 128
    assert n_tall >= 5  # several grids are split into row stripes


def test_strip_graph_equals_sequential():
    """``saddle_graph``'s row strips (terminals, exits resolved through the strips' first and last
    rows, the pairs across each strip's last row) give the sequential kernels' graph for any count."""
    n_split = 0
    for z in _grids():
        _, max_cell, bmax, nmin, edges = _sequential(z)
        for strips in (1, 2, 3, 5, 7, z.shape[0]):
            g = engine.saddle_graph(z, strips=strips)
            np.testing.assert_array_equal(g["node_key"], max_cell)
            np.testing.assert_array_equal(g["node_bmax"], bmax)
            np.testing.assert_array_equal(g["node_nmin"], nmin)
            assert sorted(zip(g["ea"].tolist(), g["eb"].tolist(), g["ekey"].tolist())) == edges
            n_split += len(engine.strip_bounds(z.shape, strips)) > 1
    assert n_split >= 100


def _fields(core):
    return {k: v for k, v in vars(core).items()}


def test_orometry_does_not_depend_on_threads():
    rng = np.random.default_rng(5)
    z = rng.integers(0, 40, (400, 150)).astype(np.float64)
    z[rng.random(z.shape) < 0.05] = np.nan
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = _fields(engine.orometry(z, min_prominence_m=3.0))
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = _fields(engine.orometry(z, min_prominence_m=3.0))
    finally:
        numba.set_num_threads(before)
    assert one.keys() == many.keys()
    for k in one:
        np.testing.assert_array_equal(np.asarray(one[k]), np.asarray(many[k]), err_msg=k)
    assert one["peak_cell"].size > 50


@pytest.mark.parametrize("cell_dtype", [np.int32, np.int64])
def test_pass_table_growth_keeps_every_pair_and_its_highest_pass(cell_dtype):
    """The open-addressing pass table (int32 pass cells beside int32 labels) keeps, through its
    growth, each basin pair's highest cell in the total order (elevation, then raster order)."""
    rng = np.random.default_rng(3)
    zf = rng.integers(0, 5, 500).astype(np.float32)
    keys = np.full(8, -1, np.int64)
    vals = np.empty(8, cell_dtype)
    best: dict[int, int] = {}
    count = 0
    for cell in rng.permutation(500):
        key = int(rng.integers(0, 40)) * 1000 + 7
        count += _kernels._insert(keys, vals, key, cell, zf)
        if key not in best or (zf[cell], -cell) > (zf[best[key]], -best[key]):
            best[key] = int(cell)
        if 2 * count > keys.size:
            keys, vals = _kernels._grow_pass_table(keys, vals, zf)
            assert vals.dtype == cell_dtype
    assert keys.size >= 64  # it grew
    got = {int(k): int(v) for k, v in zip(keys, vals) if k != -1}
    assert got == best and count == len(best)


def _basin_pairs_reference(a, b, c, zf, touched, n_max):
    """The strips' join before its kernel (numpy): the first of each candidate pair in a lexsort."""
    keep = a != b
    lo, hi, c = np.minimum(a, b)[keep], np.maximum(a, b)[keep], c[keep]
    cand = np.flatnonzero(touched[lo] | touched[hi])
    key = lo[cand] * np.int64(max(n_max, 1)) + hi[cand]
    order = np.lexsort((c[cand], -zf[c[cand]], key))
    key = key[order]
    dup = np.zeros(lo.size, bool)
    dup[cand[order[1:][key[1:] == key[:-1]]]] = True
    return lo[~dup], hi[~dup], c[~dup]


@pytest.mark.parametrize("seed", range(6))
def test_basin_pairs_keep_each_candidate_pairs_highest_pass_in_input_order(seed):
    """Equal pairs, equal passes (one cell found twice), equal elevations at other cells, NaN passes,
    unresolved basins (-1) and non-candidates kept twice: the kernel keeps the reference's edges, in its order."""
    from orokit.topology import _strip_kernels

    rng = np.random.default_rng(seed)
    n_max, n = int(rng.integers(1, 30)), int(rng.integers(0, 400))
    a = rng.integers(-1, n_max, n).astype(np.int64)
    b = rng.integers(-1, n_max, n).astype(np.int64)
    zf = rng.integers(0, 4, 60).astype(np.float32)
    zf[rng.random(60) < 0.1] = np.nan
    c = rng.integers(0, 60, n).astype(np.int64)
    touched = rng.random(n_max + 1) < 0.6
    touched[-1] = False
    want = _basin_pairs_reference(a, b, c, zf, touched, n_max)
    got = _strip_kernels.basin_pairs(a.copy(), b.copy(), c.copy(), zf, touched, n_max)
    for g, w in zip(got, want):
        assert g.dtype == np.int64
        np.testing.assert_array_equal(g, w)
    assert want[0].size < (a != b).sum() or n < 50  # some pairs were dropped as lower passes


def test_terminal_extremes_equal_ufunc_at():
    from orokit.topology import _strip_kernels

    rng = np.random.default_rng(3)
    term = rng.integers(-1, 20, 500).astype(np.int64)
    tmax, tmin = rng.normal(size=500), rng.normal(size=500)
    bmax, nmin = np.full(20, -np.inf), np.full(20, np.inf)
    _strip_kernels.terminal_extremes(bmax, nmin, term, tmax, tmin)
    want_max, want_min = np.full(20, -np.inf), np.full(20, np.inf)
    has = term >= 0
    np.maximum.at(want_max, term[has], tmax[has])
    np.minimum.at(want_min, term[has], tmin[has])
    np.testing.assert_array_equal(bmax, want_max)
    np.testing.assert_array_equal(nmin, want_min)


def test_default_strips_are_a_multiple_of_the_threads(monkeypatch):
    """Strips of equal work end together: 29 strips on two threads left the last one running alone."""
    for threads in (1, 2, 3, 4):
        monkeypatch.setattr(engine, "_threads", lambda: threads)
        for shape in ((7776, 7776), (3888, 3888), (100, 50), (5000, 3001)):
            k = len(engine.strip_bounds(shape))
            assert k % threads == 0 and k >= 2 * threads, (threads, shape, k)
            assert k * engine.STRIP_CELLS >= shape[0] * shape[1]
