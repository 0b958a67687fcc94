"""Editing operations keep Divide Trees valid and prominence consistent (property tests)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from orokit.errors import DivideTreeError
from orokit.synthesis import edit
from orokit.topology.divide_tree import DivideTree


def random_tree(seed: int, n: int) -> DivideTree:
    """A random valid Divide Tree: random points, random spanning tree, saddles below both peaks."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 10_000, (n, 2))
    z = rng.integers(100, 140, n).astype(float)  # few distinct values: ties are common
    a = np.arange(1, n)
    b = np.array([rng.integers(0, i) for i in range(1, n)], dtype=np.int64)
    sz = np.minimum(z[a], z[b]) - rng.integers(0, 30, n - 1)
    sxy = (xy[a] + xy[b]) / 2
    return DivideTree.from_arrays(np.column_stack([xy, z]), np.column_stack([sxy, sz]),
                                  np.column_stack([a, b, np.arange(n - 1)]))


def check(tree: DivideTree) -> None:
    tree.validate()
    if "prominence" in tree.peaks.columns:
        fresh = tree.prominence_table()
        assert np.allclose(tree.peaks["prominence"], fresh["prominence"])
        assert (tree.peaks["island_parent"].to_numpy() == fresh["island_parent"].to_numpy()).all()
    table = tree.prominence_table()
    has = table["key_saddle"].to_numpy() >= 0
    assert (table["prominence"].to_numpy()[has] >= 0).all()


ops = st.lists(
    st.tuples(st.sampled_from(["add", "move", "delete", "saddle", "ridge+", "ridge-"]),
              st.integers(0, 10**6), st.floats(0, 1), st.floats(0, 1)),
    min_size=1, max_size=8,
)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10**6), n=st.integers(2, 12), steps=ops)
def test_random_edit_sequences_keep_invariants(seed, n, steps):
    tree = edit.refresh_orometry(random_tree(seed, n))
    for op, k, u, v in steps:
        if tree.n_peaks < 2:
            break
        p = k % tree.n_peaks
        if op == "add":
            tree = edit.add_peak(tree, 10_000 * u, 10_000 * v, 90.0 + 60 * u)
        elif op == "move":
            tree = edit.move_peak(tree, p, x=10_000 * u, elevation=80.0 + 60 * v)
        elif op == "delete":
            tree = edit.delete_peak(tree, p)
        elif op == "saddle" and len(tree.edges):
            r = k % len(tree.edges)
            a, b = int(tree.edges["peak_a"].iloc[r]), int(tree.edges["peak_b"].iloc[r])
            top = min(tree.peaks["elevation"].iloc[a], tree.peaks["elevation"].iloc[b])
            tree = edit.move_saddle(tree, int(tree.edges["saddle"].iloc[r]), elevation=top * u)
        elif op == "ridge+":
            q = (p + 1 + k // 7 % (tree.n_peaks - 1)) % tree.n_peaks
            top = min(tree.peaks["elevation"].iloc[p], tree.peaks["elevation"].iloc[q])
            n_edges = len(tree.edges)
            tree = edit.add_ridge(tree, p, q, (0.0, 0.0, top * u))
            assert len(tree.edges) in (n_edges, n_edges + 1)
        elif op == "ridge-" and len(tree.edges):
            tree = edit.delete_ridge(tree, k % len(tree.edges))
        check(tree)


def test_add_ridge_closing_a_cycle_drops_the_lowest_saddle():
    # 0 -- s(50) -- 1 -- s(70) -- 2; adding 0 -- 2 at 60 drops the 50 m saddle
    t = DivideTree.from_arrays([[0, 0, 100], [1, 0, 90], [2, 0, 95]], [[0.5, 0, 50], [1.5, 0, 70]],
                               [[0, 1, 0], [1, 2, 1]])
    out = edit.add_ridge(t, 0, 2, (1.0, 1.0, 60.0))
    assert sorted(out.saddles["elevation"]) == [60.0, 70.0]
    assert out.prominence_table()["prominence"].tolist() == [100.0, 20.0, 35.0]
    # a ridge lower than every saddle of the cycle is dropped again
    same = edit.add_ridge(t, 0, 2, (1.0, 1.0, 10.0))
    assert same.equals(t)


def test_delete_peak_keeps_other_prominences():
    t = DivideTree.from_arrays([[0, 0, 100], [1, 0, 60], [2, 0, 95], [3, 0, 80]],
                               [[0.5, 0, 50], [1.5, 0, 55], [2.5, 0, 40]], [[0, 1, 0], [1, 2, 1], [2, 3, 2]])
    before = t.prominence_table()["prominence"].to_numpy()
    out = edit.delete_peak(t, 1)
    after = out.prominence_table()["prominence"].to_numpy()
    assert np.allclose(after, before[[0, 2, 3]])


def test_bad_edits_raise():
    t = random_tree(1, 4)
    with pytest.raises(DivideTreeError, match="out of range"):
        edit.delete_peak(t, 10)
    with pytest.raises(DivideTreeError, match="above a peak"):
        edit.add_peak(t, 0.0, 0.0, 50.0, connect_to=0, saddle=(0.0, 0.0, 60.0))
    s = int(t.edges["saddle"].iloc[0])
    with pytest.raises(DivideTreeError, match="cannot rise"):
        edit.move_saddle(t, s, elevation=1e6)
    with pytest.raises(DivideTreeError, match="two different peaks"):
        edit.add_ridge(t, 1, 1, (0, 0, 0))
    with pytest.raises(DivideTreeError, match="lower_saddles"):
        edit.move_peak(t, int(t.edges["peak_a"].iloc[0]), elevation=0.0, lower_saddles=False)


def test_paste_fragment_replaces_the_area(small_type):
    from orokit.synthesis.tree import synthesize_divide_tree

    base = synthesize_divide_tree(small_type, size_m=20_000, rng=1)
    frag = random_tree(5, 6)
    out = edit.paste_fragment(base, frag, offset=(2000.0, 2000.0))
    out.validate()
    assert out.n_peaks <= base.n_peaks + frag.n_peaks
    fx = frag.peaks["x"].to_numpy() + 2000.0
    for x in fx:
        assert np.isclose(out.peaks["x"].to_numpy(), x).any()
