"""Belhadj 2007 backend: skeleton kept bit for bit, MDI fills exactly the ancestors, MDI+MD vs MD."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.generators import _belhadj_kernels as K
from orokit.generators import belhadj as B
from orokit.generators import render_terrain
from orokit.generators.base import tree_rivers
from orokit.raster.rasterize import make_grid

from helpers.trees import small_tree

SUBDIVISIONS = ("triangle-edge", "diamond-square")


def reference_parents(n: int, mode: str) -> dict[tuple[int, int], set[tuple[int, int]]]:
    """Parents of every cell of a (2^k+1)^2 grid, from the subdivision written out level by level."""
    parents: dict[tuple[int, int], set[tuple[int, int]]] = {}
    L = n - 1
    while L >= 2:
        h = L // 2
        for i in range(0, n, L):          # corners of the level-L squares are i, j multiples of L
            for j in range(0, n, L):
                if i + L < n and j + L < n:
                    c = (i + h, j + h)
                    if mode == "diamond-square":
                        parents[c] = {(i, j), (i + L, j), (i, j + L), (i + L, j + L)}
                    else:
                        parents[c] = {(i, j), (i + L, j + L)}
                    for e, ends in (((i, j + h), [(i, j), (i, j + L)]), ((i + h, j), [(i, j), (i + L, j)]),
                                    ((i + L, j + h), [(i + L, j), (i + L, j + L)]),
                                    ((i + h, j + L), [(i, j + L), (i + L, j + L)])):
                        if mode == "triangle-edge":
                            parents[e] = set(ends)
                        else:  # square step: the 2-4 cells at distance h (corners and centres)
                            r, q = e
                            parents[e] = {(r + dr, q + dq) for dr, dq in ((-h, 0), (h, 0), (0, -h), (0, h))
                                          if 0 <= r + dr < n and 0 <= q + dq < n}
        L //= 2
    return parents


@pytest.mark.parametrize("mode", SUBDIVISIONS)
def test_parent_lists_match_the_subdivision(mode):
    n = 17
    ref = reference_parents(n, mode)
    start, pi, pj = K.parent_lists(n, B.MODE[mode])
    assert len(ref) == n * n - 4  # every cell but the 4 corners is created once
    for (i, j), ps in ref.items():
        a, b = start[i * n + j], start[i * n + j + 1]
        assert set(zip(pi[a:b].tolist(), pj[a:b].tolist())) == ps, (i, j)


@pytest.mark.parametrize("mode", SUBDIVISIONS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mdi_fills_exactly_the_ancestors_of_known_cells(mode, seed):
    rng = np.random.default_rng(seed)
    n = 33
    known = rng.random((n, n)) < 0.01
    known[rng.integers(n), :] |= rng.random(n) < 0.5  # a broken line, like a ridge
    ref = reference_parents(n, mode)
    # brute force: every cell reachable from a known cell by one or more parent steps
    anc: set[tuple[int, int]] = set()
    stack = [tuple(c) for c in np.argwhere(known).tolist()]
    while stack:
        c = stack.pop()
        for p in ref.get(c, ()):
            if p not in anc:
                anc.add(p)
                stack.append(p)
    expect = np.zeros((n, n), bool)
    for p in anc:
        expect[p] = True
    expect &= ~known
    z = np.where(known, rng.normal(500, 100, (n, n)), 0.0)
    st = known.astype(np.uint8)
    u = rng.uniform(-1, 1, (n, n)).astype(np.float32)
    filled = K.mdi(z, st, u, 1.0, 1.0, B.MODE[mode])
    np.testing.assert_array_equal(st == K.MDI, expect)
    assert filled == expect.sum() > 0


def test_mdi_value_is_children_mean_plus_scaled_distance():
    # one known child: its parents get its elevation + scale * d * u
    n = 5
    z = np.zeros((n, n))
    st = np.zeros((n, n), np.uint8)
    z[1, 2], st[1, 2] = 100.0, K.KNOWN  # created at h=1 (vertical edge in triangle-edge: parents (0,2),(2,2))
    u = np.full((n, n), 0.5, np.float32)
    K.mdi(z, st, u, 4.0, 1.0, B.MODE["triangle-edge"])
    assert z[0, 2] == pytest.approx(100.0 + 4.0 * 1.0 * 0.5)
    assert z[2, 2] == pytest.approx(100.0 + 4.0 * 1.0 * 0.5)
    assert st[0, 2] == st[2, 2] == K.MDI


@pytest.fixture(scope="module")
def tree_raster():
    tree = small_tree()
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 50.0)
    rivers = tree_rivers(tree, grid)
    z, st = B.tree_skeleton(tree, rivers, grid)
    return tree, grid, rivers, z, st


@pytest.mark.parametrize("mode", SUBDIVISIONS)
def test_skeleton_cells_are_bit_identical(tree_raster, mode):
    tree, grid, rivers, z, st = tree_raster
    out, st2 = B.interpolate(z, st, params=B.BelhadjParams(subdivision=mode), rng=np.random.default_rng(3))
    known = st == K.KNOWN
    assert known.sum() > 200
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out[known].view(np.uint32), z[known].view(np.uint32))
    assert ((st2 == K.MDI) | (st2 == K.MD) | known).all()
    # peaks and saddles sit in their cells at their exact (float32) elevation
    for frame in (tree.peaks, tree.saddles):
        row, col, ok = grid.cell_of(frame[["x", "y"]].to_numpy())
        assert ok.all()
        np.testing.assert_array_equal(out[row, col], frame["elevation"].to_numpy().astype(np.float32))
    # ridge cells run linearly from peak (1500) to saddle (1100): on the A-B ridge at x = 3025 m
    row, col, _ = grid.cell_of(np.array([[3025.0, 2102.5]]))
    assert st[row[0], col[0]] == K.KNOWN and 1100.0 < out[row[0], col[0]] < 1500.0


def test_river_cells_come_from_the_river_beds(tree_raster):
    tree, grid, rivers, z, st = tree_raster
    _, st_no = B.tree_skeleton(tree, None, grid)
    river = (st == K.KNOWN) & (st_no == K.NULL)
    assert river.sum() > 50
    assert z[river].max() <= rivers.elevation.max() + 1e-3
    assert z[river].min() >= rivers.elevation.min() - 1e-3


def _edge_gradient(out: np.ndarray, known: np.ndarray) -> float:
    """Mean |step| between a skeleton cell and its 4-neighbours that are not skeleton."""
    steps = []
    for axis in (0, 1):
        a, b = known, np.roll(known, -1, axis)
        d = np.abs(out - np.roll(out, -1, axis))
        edge = a ^ b
        if axis == 0:
            edge[-1, :] = False
        else:
            edge[:, -1] = False
        steps.append(d[edge])
    return float(np.concatenate(steps).mean())


@pytest.mark.parametrize("mode", SUBDIVISIONS)
def test_mdi_then_md_leaves_smaller_skeleton_edge_gradients_than_md(tree_raster, mode):
    _, _, _, z, st = tree_raster
    known = st == K.KNOWN
    g = {}
    for use_mdi in (True, False):
        vals = []
        for seed in range(3):
            p = B.BelhadjParams(subdivision=mode, mdi=use_mdi)
            out, _ = B.interpolate(z, st, params=p, rng=np.random.default_rng(seed))
            vals.append(_edge_gradient(out, known))
        g[use_mdi] = float(np.mean(vals))
    assert g[True] < 0.5 * g[False], g


def test_same_seed_same_raster_and_different_seed_differs():
    tree = small_tree()
    a = render_terrain(tree, generator="belhadj", cell_size_m=100.0, seed=11)
    b = render_terrain(tree, generator="belhadj", cell_size_m=100.0, seed=11)
    c = render_terrain(tree, generator="belhadj", cell_size_m=100.0, seed=12)
    assert a.values.tobytes() == b.values.tobytes()
    assert a.values.tobytes() != c.values.tobytes()
    assert a.attrs["seed"] == 11 and a.attrs["generator"] == "belhadj"


def test_padding_keeps_the_grid_and_crops():
    tree = small_tree()
    dem = render_terrain(tree, generator="belhadj", cell_size_m=100.0, extent=(0.0, 0.0, 8000.0, 6000.0), seed=1)
    assert dem.shape == (60, 80)
    assert np.isfinite(dem.values).all()
    assert dem.rio.transform().a == 100.0


@pytest.mark.parametrize("bad", [{"hurst": 0.0}, {"hurst": 3.0}, {"displacement_m_per_cell": -1.0},
                                 {"subdivision": "square-square"}, {"skeleton": "particles"}])
def test_out_of_range_parameters_are_refused(bad):
    from orokit.errors import InputError

    with pytest.raises(InputError):
        B.BelhadjParams(**bad)
