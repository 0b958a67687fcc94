"""Michel 2015 backend: exact sub-plate velocities, merging rules, folds as translations, drainage."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.errors import InputError
from orokit.generators import michel as M
from orokit.generators import render_terrain
from orokit.generators.base import tree_rivers
from orokit.raster.rasterize import make_grid

from helpers.trees import small_tree


def _peaks(n, seed, size=8000.0):
    return np.random.default_rng(seed).uniform(0.05 * size, 0.95 * size, (n, 2))


def test_sub_plate_velocities_are_exact():
    grid = make_grid((0.0, 0.0, 4000.0, 3000.0), 100.0)
    pk = _peaks(7, 0, 3000.0)
    plates = M.sub_plates(pk, grid)
    x, y = grid.centres()
    for k in range(7):  # brute force: the cells nearest to peak k, their centre of mass
        cells = [(xi, yi) for yi in y for xi in x
                 if np.argmin(np.hypot(pk[:, 0] - xi, pk[:, 1] - yi)) == k]
        c = np.mean(cells, axis=0)
        np.testing.assert_allclose(plates.velocity[k], pk[k] - c, atol=1e-9)
        assert plates.area[k] == pytest.approx(len(cells) * 100.0**2)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("t1, t2", [(0.9, 0.0), (0.5, 0.05), (0.0, 0.2)])
def test_after_merging_no_pair_above_t1_and_no_plate_below_t2(seed, t1, t2):
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    merged = M.merge_plates(M.sub_plates(_peaks(40, seed), grid), t1=t1, t2=t2)
    u = M._unit(merged.velocity)
    for a, b in M._adjacent_pairs(merged.label):
        assert float(u[a] @ u[b]) <= t1 + 1e-12
    nb: dict[int, set[int]] = {}
    for a, b in M._adjacent_pairs(merged.label):
        nb.setdefault(a, set()).add(b)
        nb.setdefault(b, set()).add(a)
    for a, ns in nb.items():
        assert merged.area[a] / max(merged.area[c] for c in ns) >= t2
    # areas add up, and each merged velocity is the area-weighted mean of its sub-plates
    sub = M.sub_plates(_peaks(40, seed), grid)
    assert merged.area.sum() == pytest.approx(sub.area.sum())
    for p in range(merged.n):
        members = np.unique(sub.label[merged.label == p])
        w = sub.area[members]
        np.testing.assert_allclose(merged.velocity[p], (w[:, None] * sub.velocity[members]).sum(0) / w.sum(),
                                   atol=1e-6)


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_a_smaller_t1_never_gives_more_plates(seed):
    # without the area rule (t2 = 0): with it, absorbing small plates can cascade differently
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    sub = M.sub_plates(_peaks(60, seed), grid)
    counts = [M.merge_plates(sub, t1=t1, t2=0.0).n for t1 in (0.99, 0.9, 0.7, 0.5, 0.2, 0.0, -0.5)]
    assert counts == sorted(counts, reverse=True) and counts[0] > counts[-1]


def test_far_from_plate_boundaries_folds_are_a_translation_of_the_fbm():
    res = 50.0
    grid = make_grid((0.0, 0.0, 4000.0, 2000.0), res)  # 40 x 80 cells
    label = np.zeros((grid.ny, grid.nx), np.int64)
    label[:, 40:] = 1
    plates = M.Plates(label, np.array([1.0, 1.0]), np.array([[3 * res, 0.0], [-2 * res, 1 * res]]))
    vel = M.velocity_map(plates, res, blur_m=2 * res)  # sigma 2 cells, truncated at 8
    pad = 6
    noise = M.fbm((grid.ny + 2 * pad, grid.nx + 2 * pad), 3.0, np.random.default_rng(0))
    f = M.fold_map(noise, pad, vel, res)
    # left plate (cols < 31): shifted 3 cells east; right plate (cols > 49): 2 west, 1 north
    np.testing.assert_allclose(f[:, :31], noise[pad:pad + grid.ny, pad + 3:pad + 3 + 31], atol=1e-6)
    np.testing.assert_allclose(f[:, 50:], noise[pad - 1:pad - 1 + grid.ny, pad - 2 + 50:pad - 2 + grid.nx], atol=1e-6)
    # near the boundary the velocity varies: there the folds are not a translation
    assert not np.allclose(f[:, 38:42], noise[pad:pad + grid.ny, pad + 3 + 38:pad + 3 + 42], atol=1e-3)


def test_watershed_drains_every_cell():
    tree = small_tree()
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    g, river = M.watershed_map(tree_rivers(tree, grid), grid, river_slope=0.005, hill_slope=0.05)
    assert river.sum() > 50 and np.isfinite(g).all()
    pad = np.pad(g, 1, constant_values=np.inf)
    lower = np.zeros(g.shape, bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                lower |= pad[1 + di:1 + di + g.shape[0], 1 + dj:1 + dj + g.shape[1]] < g
    interior = np.zeros(g.shape, bool)
    interior[1:-1, 1:-1] = True
    assert lower[interior].all()  # every interior cell has a strictly lower neighbour: water reaches the border
    assert g[~interior].min() == pytest.approx(g.min())


@pytest.mark.parametrize("bad", [{"t1": 1.5}, {"t2": 1.0}, {"blur_m": 0.0}, {"k_min": 1.0}, {"fbm_beta": 6.0},
                                 {"river_slope": 0.2, "hill_slope": 0.1}])
def test_out_of_range_parameters_are_refused(bad):
    with pytest.raises(InputError):
        M.MichelParams(**bad)


def test_render_scales_to_the_tree_relief():
    tree = small_tree()
    dem = render_terrain(tree, generator="michel", cell_size_m=100.0, params={"erosion": False}, seed=2)
    z = dem.values
    assert np.isfinite(z).all() and z.max() <= 1500.0 + 1e-3
    assert z.max() - z.min() > 300.0
