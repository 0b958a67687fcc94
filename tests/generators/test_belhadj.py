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


def test_ridge_gradient_is_the_summed_drop_over_the_summed_length():
    from orokit.generators.base import ridge_gradient, tree_arrays

    tree = small_tree()
    a = tree_arrays(tree)
    drop = length = 0.0
    for pa, pb, s in a.edges:  # brute force, ridge by ridge
        for p in (pa, pb):
            drop += a.peaks[p, 2] - a.saddles[s, 2]
            length += float(np.hypot(*(a.peaks[p, :2] - a.saddles[s, :2])))
    assert ridge_gradient(tree) == pytest.approx(drop / length)
    assert ridge_gradient(tree) > 0


@pytest.mark.parametrize("slope", [0.3, 1.0])
def test_ridge_cones_cap_the_beds_of_the_same_rivers(tree_raster, slope):
    from orokit.generators.base import ridge_cones, tree_arrays

    tree, grid, rivers, _, _ = tree_raster
    cap = ridge_cones(tree, slope, spacing_m=25.0, k_neighbours=10**6)
    # brute force: the highest cone over every ridge point (sampled finely)
    a = tree_arrays(tree)
    t = np.linspace(0.0, 1.0, 401)
    xy = rivers.xy
    cone = np.full(xy.shape[0], -np.inf)
    for pa, pb, s in a.edges:
        for p in (pa, pb):
            q = a.peaks[p] + t[:, None] * (a.saddles[s] - a.peaks[p])
            d = np.hypot(xy[:, None, 0] - q[None, :, 0], xy[:, None, 1] - q[None, :, 1])
            cone = np.maximum(cone, (q[None, :, 2] - slope * d).max(axis=1))
    np.testing.assert_allclose(cap(xy), cone, atol=25.0 * slope)  # 25 m samples against 401 per ridge
    low = tree_rivers(tree, grid, cap=cap)
    np.testing.assert_array_equal(low.receiver, rivers.receiver)
    np.testing.assert_array_equal(low.xy, rivers.xy)
    base = rivers.elevation.min()
    assert (low.elevation <= np.maximum(cap(xy) - 5.0, base) + 1e-6).all()
    assert (low.elevation < rivers.elevation - 1.0).any()
    has = low.receiver >= 0  # beds still fall downstream by at least 1 % (or sit on the base)
    drop = low.elevation[has] - low.elevation[low.receiver[has]]
    assert np.all((drop >= 0.01 * low.length[has] - 1e-6) | (low.elevation[low.receiver[has]] <= base + 1e-9))


def test_valley_slope_default_is_the_ratio_times_the_ridge_gradient(tree_raster):
    from orokit.generators.base import ridge_gradient

    tree, grid, rivers, _, _ = tree_raster
    _, s = B.valley_beds(tree, rivers, grid, B.BelhadjParams(valley_ratio=1.5))
    assert s == pytest.approx(1.5 * ridge_gradient(tree))
    given, s0 = B.valley_beds(tree, rivers, grid, B.BelhadjParams(valley_slope=0.0))
    assert s0 == 0.0 and given is rivers
    steep, s2 = B.valley_beds(tree, rivers, grid, B.BelhadjParams(valley_slope=1.0))
    assert s2 == 1.0 and steep.receiver.size == rivers.receiver.size
    dem = render_terrain(tree, generator="belhadj", grid=grid, seed=1, rivers=rivers)
    import json

    assert json.loads(dem.attrs["derived"])["valley_slope"] == pytest.approx(2.0 * ridge_gradient(tree))
    flat = render_terrain(tree, generator="belhadj", grid=grid, seed=1, rivers=rivers, params={"valley_slope": 0.0})
    assert not np.array_equal(dem.values, flat.values)


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


@pytest.mark.parametrize("cell", [50.0, 100.0])
def test_relief_displacement_is_a_share_of_the_relief_per_km(cell):
    """relief_displacement r: the same raster as displacement_m_per_cell = r x relief x cell (km)."""
    tree = small_tree()  # relief: 1500 m peak - 900 m lowest saddle = 600 m
    a = render_terrain(tree, generator="belhadj", cell_size_m=cell, seed=5, params={"relief_displacement": 0.05})
    b = render_terrain(tree, generator="belhadj", cell_size_m=cell, seed=5,
                       params={"displacement_m_per_cell": 0.05 * 600.0 * cell / 1000.0})
    assert a.values.tobytes() == b.values.tobytes()


def test_padding_keeps_the_grid_and_crops():
    tree = small_tree()
    dem = render_terrain(tree, generator="belhadj", cell_size_m=100.0, extent=(0.0, 0.0, 8000.0, 6000.0), seed=1)
    assert dem.shape == (60, 80)
    assert np.isfinite(dem.values).all()
    assert dem.rio.transform().a == 100.0


@pytest.mark.parametrize("bad", [{"hurst": 0.0}, {"hurst": 3.0}, {"displacement_m_per_cell": -1.0},
                                 {"relief_displacement": -0.1},
                                 {"subdivision": "square-square"}, {"skeleton": "voronoi"},
                                 {"ridge_pairs": 0}, {"ridge_hurst": 1.0}, {"friction": 1.0}, {"gravity": 0.0},
                                 {"river_particles": -1}, {"valley_slope": -0.1}, {"valley_slope": float("inf")},
                                 {"valley_ratio": 0.0}])
def test_out_of_range_parameters_are_refused(bad):
    from orokit.errors import InputError

    with pytest.raises(InputError):
        B.BelhadjParams(**bad)


# ----------------------------------------------------------------------------- particle skeleton (§2)
from orokit.generators import _belhadj_particles as P  # noqa: E402


def test_ridge_particle_altitude_is_a_gaussian_of_the_distance_walked():
    owner = np.full((200, 300), -1, np.int64)
    n_steps = 400
    rr, cc, alt = np.empty(4 * n_steps, np.int64), np.empty(4 * n_steps, np.int64), np.empty(4 * n_steps)
    sigma, y0, base = 150.0, 2000.0, 500.0
    owner[100, 20] = 0  # the start cell (particle_skeleton marks it)
    # straight path (no sideways fBm) heading east from (100.5, 20.5)
    n, why = P.ridge_route(owner, 0, 100.5, 20.5, 0.0, np.zeros(n_steps), 1.0, sigma, y0, base, 0.01, rr, cc, alt)
    assert why == P.STOP_BORDER and n > 250
    assert (rr[:n] == 100).all()
    # the altitude at the cell entered at distance s (cell edge: s = col - 20.5) is the Gaussian
    s = cc[:n] - 20.5
    np.testing.assert_allclose(alt[:n], base + (y0 - base) * np.exp(-0.5 * (s / sigma) ** 2), atol=1e-6)
    assert (np.diff(alt[:n]) < 0).all()
    # a second particle heading north-west stops before entering route 0
    n2, why2 = P.ridge_route(owner, 1, 150.5, 150.5, np.pi / 2, np.zeros(n_steps), 1.0, sigma, y0, base, 0.01,
                             rr, cc, alt)
    assert why2 == P.STOP_COLLISION and (rr[:n2] > 100).all()
    # a short sigma stops on the altitude floor
    owner[:] = -1
    n3, why3 = P.ridge_route(owner, 0, 100.5, 150.5, 0.0, np.zeros(n_steps), 1.0, 10.0, y0, base, 0.01, rr, cc, alt)
    assert why3 == P.STOP_ALTITUDE and alt[:n3].min() >= base + 0.01 * (y0 - base)


@pytest.fixture(scope="module")
def particles():
    grid = make_grid((0.0, 0.0, 12000.0, 9000.0), 50.0)
    p = B.BelhadjParams(skeleton="particles", ridge_pairs=6, river_particles=150)
    sk = B.particle_skeleton(grid, top=2500.0, base=300.0, params=p, rng=np.random.default_rng(4))
    return grid, p, sk


def test_ridge_pairs_leave_one_point_in_opposite_directions(particles):
    grid, p, sk = particles
    ridge = sk.ridge_owner >= 0
    assert ridge.sum() > 200
    assert set(np.unique(sk.ridge_owner[ridge])) <= set(range(p.ridge_pairs))
    # the first pair starts at the top altitude; every ridge cell is within [base, top]
    assert sk.z[ridge].max() == np.float32(2500.0)
    assert sk.z[ridge].min() >= 300.0
    # each route stopped for one of the paper's reasons
    assert set(sk.ridge_stop) <= {P.STOP_BORDER, P.STOP_ALTITUDE, P.STOP_COLLISION}


def test_only_rivers_that_exit_the_map_are_kept(particles):
    grid, p, sk = particles
    fate, joins, kept = sk.river_fate, sk.river_joins, sk.river_kept
    assert (fate == P.RIVER_EXIT).sum() > 0 and kept.sum() < kept.size  # some exit, some are dropped
    for q in range(kept.size):
        r, seen = q, 0
        while fate[r] == P.RIVER_JOINED and seen <= kept.size:
            r, seen = joins[r], seen + 1
        assert kept[q] == (fate[r] == P.RIVER_EXIT)
    assert not kept[fate == P.RIVER_STATIC].any()
    river = sk.river
    assert river.sum() > 50 and not (river & (sk.ridge_owner >= 0)).any()
    # beds lie on or below the blended ridges, never above the ridge top
    assert (sk.z[river] <= sk.blended[river] + 1e-3).all()
    # a river reaches the border
    border = np.zeros_like(river)
    border[[0, -1], :] = border[:, [0, -1]] = True
    assert (river & border).any()
    assert ((sk.state == K.KNOWN) == (river | (sk.ridge_owner >= 0))).all()


def test_particle_skeleton_render_keeps_it_and_repeats_with_the_seed():
    tree = small_tree()
    prm = ["skeleton=particles", "ridge_pairs=4", "river_particles=60"]
    a = render_terrain(tree, generator="belhadj", cell_size_m=100.0, params=prm, seed=2)
    b = render_terrain(tree, generator="belhadj", cell_size_m=100.0, params=prm, seed=2)
    assert a.values.tobytes() == b.values.tobytes()
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    sk = B.particle_skeleton(grid, top=1500.0, base=900.0, params=B.BelhadjParams(
        skeleton="particles", ridge_pairs=4, river_particles=60), rng=np.random.default_rng(2))
    known = sk.state == K.KNOWN
    np.testing.assert_array_equal(a.values[known].view(np.uint32), sk.z[known].view(np.uint32))
    assert np.isfinite(a.values).all()
