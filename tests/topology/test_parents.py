"""Line and prominence parents of ``DivideTree.parents`` on hypothesis-drawn trees.

Properties from the definitions (issue 16) and agreement with an independent
brute-force walk (``helpers.parent_oracle``), including ties of peak and saddle elevations,
monkey saddles (one saddle serving several ridges) and forests.
"""
from __future__ import annotations

import numpy as np
import pytest
from helpers.parent_oracle import brute_parents, tree_path
from hypothesis import example, given, settings
from hypothesis import strategies as st

from orokit.topology.divide_tree import DivideTree


@st.composite
def trees(draw, max_peaks=24):
    n = draw(st.integers(1, max_peaks))
    z = np.array(draw(st.lists(st.integers(0, 12), min_size=n, max_size=n)), float)
    saddles, edges = [], []
    for i in range(1, n):
        j = draw(st.integers(0, i - 1))
        if draw(st.integers(0, 9)) == 0:
            continue  # a forest: this peak starts another landmass
        low = min(z[i], z[j])
        shared = [s for s, h in enumerate(saddles) if h <= low]
        if shared and draw(st.booleans()) and draw(st.booleans()):
            s = draw(st.sampled_from(shared))  # a saddle serving several ridges
        else:
            saddles.append(float(draw(st.integers(-3, int(low)))))
            s = len(saddles) - 1
        a, b = (i, j) if draw(st.booleans()) else (j, i)
        edges.append((a, b, s))
    perm = draw(st.permutations(range(len(edges)))) if edges else []
    edges = np.array([edges[k] for k in perm], np.int64).reshape(-1, 3)
    peaks = np.column_stack([np.arange(n), np.zeros(n), z])
    sad = np.column_stack([np.arange(len(saddles)), np.ones(len(saddles)), saddles]).reshape(-1, 3)
    return DivideTree.from_arrays(peaks, sad, edges)


def _higher(z, i, j):
    return z[i] > z[j] or (z[i] == z[j] and i < j)


def _check(tree: DivideTree) -> None:
    table = tree.prominence_table()
    got = tree.parents(table)
    z = tree.peaks["elevation"].to_numpy(float)
    e = tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64)
    sz = tree.saddles["elevation"].to_numpy(float)
    prom = table["prominence"].to_numpy(float)
    key = table["key_saddle"].to_numpy()
    big = np.where(key < 0, np.inf, prom)
    lp, pp = got["line_parent"].to_numpy(), got["prominence_parent"].to_numpy()
    for p in range(tree.n_peaks):
        if key[p] < 0:  # landmass high point
            assert lp[p] == -1 and pp[p] == -1
            continue
        assert lp[p] >= 0 and pp[p] >= 0
        assert _higher(z, lp[p], p), "the line parent is higher"
        def more_prominent(q):
            return big[q] > prom[p] or (big[q] == prom[p] and _higher(z, q, p))

        assert more_prominent(pp[p]), "the prominence parent is more prominent"
        for parent, closer_ok in ((lp[p], lambda q: not _higher(z, q, p)), (pp[p], lambda q: not more_prominent(q))):
            nodes, ridges = tree_path(e, tree.n_peaks, p, parent)
            # on the key-saddle side: the path crosses P's key saddle, and nowhere lower
            assert key[p] in e[ridges, 2]
            assert sz[e[ridges, 2]].min() == sz[key[p]]
            # nothing closer on the way qualifies
            assert all(closer_ok(q) for q in nodes[1:-1])
    blp, bpp, bprom, _ = brute_parents(z, sz, e)
    np.testing.assert_allclose(np.where(np.isinf(bprom), z, bprom), prom)
    np.testing.assert_array_equal(lp, blp)
    np.testing.assert_array_equal(pp, bpp)


@settings(max_examples=400, deadline=None)
@given(tree=trees())
@example(tree=DivideTree.from_arrays([[0, 0, 5]], np.zeros((0, 3)), np.zeros((0, 3))))
def test_parents_match_the_definitions(tree):
    _check(tree)


def test_walk_goes_through_a_lower_peak_and_a_less_prominent_one():
    # 100 -50- 90 -80- 120 -110- 130 -60- 200: line parent of 100 is 120 (through 90),
    # prominence parent 130 (120 has prominence 10, 130 has 70 > 50); 90 (prominence 10)
    # has 120 (10, but higher) as both parents
    tree = DivideTree.from_arrays(
        [[0, 0, 100], [1, 0, 90], [2, 0, 120], [3, 0, 130], [4, 0, 200]],
        [[0, 1, 50], [1, 1, 80], [2, 1, 110], [3, 1, 60]],
        [[0, 1, 0], [1, 2, 1], [2, 3, 2], [2, 4, 3]],
    )
    got = tree.parents()
    assert got["line_parent"].tolist() == [2, 2, 3, 4, -1]
    assert got["prominence_parent"].tolist() == [3, 2, 3, 4, -1]
    _check(tree)


def test_equal_elevations_lower_id_is_higher():
    tree = DivideTree.from_arrays([[0, 0, 10], [1, 0, 10]], [[0, 1, 5]], [[1, 0, 0]])
    got = tree.parents()
    assert got["line_parent"].tolist() == [-1, 0]  # equal prominence too: the higher one wins
    assert got["prominence_parent"].tolist() == [-1, 0]


FT = 0.3048
REAL_DEMS = [
    "alaska", "andes-aconcagua", "andes-chile", "appalachians", "gobi", "highlands",
    "himalaya-annapurna", "himalaya-everest", "karakoram", "norway", "pyrenees", "rockies", "sahara",
]


@pytest.mark.realdata
@pytest.mark.slow
@pytest.mark.parametrize("name", REAL_DEMS)
def test_real_dem_parents_match_a_brute_force_walk(real_data, name):
    """At 100 ft, the parent columns of the peaks table equal the brute-force walk on
    the analysis' Divide Tree for every peak, and point at peaks of the table."""
    import orokit
    from orokit.io.dem import read_dem

    dem = read_dem(real_data(f"dems/{name}.png"), z_units="ft", cell_size_m=30.87 if name == "pyrenees" else 92.61)
    result = orokit.analyze(dem, min_prominence_m=100 * FT, isolation=False)
    peaks, tree = result.peaks, result.tree
    assert len(peaks) > 100
    e = tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64)
    lp, pp, prom, _ = brute_parents(tree.peaks["elevation"], tree.saddles["elevation"], e)
    np.testing.assert_allclose(np.where(np.isinf(prom), peaks["elevation"], prom), peaks["prominence"], atol=1e-6)
    np.testing.assert_array_equal(peaks["line_parent"].to_numpy(), lp)
    np.testing.assert_array_equal(peaks["prominence_parent"].to_numpy(), pp)
    rows, cols = peaks["row"].to_numpy(), peaks["col"].to_numpy()
    for what, ids in (("line_parent", lp), ("prominence_parent", pp)):
        has = ids >= 0
        np.testing.assert_array_equal(peaks[f"{what}_row"].to_numpy()[has], rows[ids[has]])
        np.testing.assert_array_equal(peaks[f"{what}_col"].to_numpy()[has], cols[ids[has]])
        assert (peaks[f"{what}_row"].to_numpy()[~has] == -1).all()
    # landmass high points have none; every other peak has both
    root = peaks["island_parent"].to_numpy() == -1
    assert ((lp == -1) == root).all() and ((pp == -1) == root).all()


def test_chunked_engine_parents_are_the_walk_on_its_own_tree(make_dem):
    """--chunks gives the same peaks, prominences and island parents; its line and
    prominence parents are the exact walk on the chunked engine's own Divide Tree."""
    import orokit

    rng = np.random.default_rng(7)
    z = rng.normal(size=(120, 150)).cumsum(0).cumsum(1) + 25 * rng.normal(size=(120, 150))
    dem = make_dem(z.astype(np.float32))
    a = orokit.analyze(dem, min_prominence_m=20.0, isolation=False)
    b = orokit.analyze(dem, min_prominence_m=20.0, isolation=False, chunks=40)
    for col in ("row", "col", "prominence", "island_parent", "saddle_row", "saddle_col"):
        assert a.peaks[col].tolist() == b.peaks[col].tolist()
    for result in (a, b):
        tree = result.tree
        e = tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64)
        lp, pp, _, _ = brute_parents(tree.peaks["elevation"], tree.saddles["elevation"], e)
        np.testing.assert_array_equal(result.peaks["line_parent"].to_numpy(), lp)
        np.testing.assert_array_equal(result.peaks["prominence_parent"].to_numpy(), pp)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 5), st.sampled_from([0.0, 1.0, 2.0]))
def test_tables_parents_from_the_engine_prominences_are_the_trees_own(seed, levels, eps):
    """``build_result`` gives ``parents`` the engine's prominences and roots instead of a sweep of
    the pruned tree: on tie-heavy grids (plateaus, equal saddles, voids) they are the tree's own,
    bit for bit, and the parent columns are the brute-force walk on the tree."""
    import orokit
    from helpers.dems import build_dem

    rng = np.random.default_rng(seed)
    h, w = rng.integers(3, 16, size=2)
    z = rng.integers(0, levels, size=(h, w)).astype(np.float32)
    z[rng.random((h, w)) < 0.08] = np.nan
    if np.isnan(z).all():
        return
    result = orokit.analyze(build_dem(z), min_prominence_m=eps, isolation=False)
    tree, peaks = result.tree, result.peaks
    own = tree.prominence_table()
    np.testing.assert_array_equal(own["prominence"].to_numpy(), peaks["prominence"].to_numpy())
    np.testing.assert_array_equal(own["key_saddle"].to_numpy() < 0, peaks["island_parent"].to_numpy() < 0)
    mine = tree.parents(own)
    np.testing.assert_array_equal(mine["line_parent"].to_numpy(), peaks["line_parent"].to_numpy())
    np.testing.assert_array_equal(mine["prominence_parent"].to_numpy(), peaks["prominence_parent"].to_numpy())
    if len(peaks):
        e = tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy(np.int64)
        lp, pp, _, _ = brute_parents(tree.peaks["elevation"], tree.saddles["elevation"], e)
        np.testing.assert_array_equal(peaks["line_parent"].to_numpy(), lp)
        np.testing.assert_array_equal(peaks["prominence_parent"].to_numpy(), pp)
