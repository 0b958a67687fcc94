"""River beds no steeper than the hillslopes around them (issue 11, session 19: ``river_bed_slope_ratio``,
off by default): where a high tributary's bed met a deep trunk's it stepped by hundreds of metres in one edge."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.errors import InputError
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation
from orokit.raster.rivers import bounded_beds
from orokit.raster.skeleton import build_skeleton

from helpers.trees import assert_keeps_small_tree, small_tree


def _relaxed(receiver, length, h, slope):
    """Brute force: lower ``h[v]`` to ``h[receiver] + slope x length`` edge by edge until nothing moves."""
    h = h.copy()
    moved = True
    while moved:
        moved = False
        for v in range(h.size):
            r = receiver[v]
            if r >= 0 and h[v] > h[r] + slope[v] * length[v] + 1e-12:
                h[v] = h[r] + slope[v] * length[v]
                moved = True
    return h


@pytest.mark.parametrize("seed", range(5))
def test_bounded_beds_against_brute_force(seed):
    """Random forests (receivers numbered before their donors), random beds and slopes: the one upstream pass
    gives the largest beds below the start with no edge steeper than its slope (the relaxation's fixed point)."""
    rng = np.random.default_rng(seed)
    n = 300
    receiver = np.array([-1 if v == 0 or rng.random() < 0.05 else int(rng.integers(0, v)) for v in range(n)])
    length = np.where(receiver >= 0, rng.uniform(10.0, 200.0, n), 0.0)
    h = rng.uniform(0.0, 2000.0, n)
    slope = rng.uniform(0.1, 1.0, n)
    got = bounded_beds(receiver, length, h, slope)
    np.testing.assert_allclose(got, _relaxed(receiver, length, h, slope), rtol=0, atol=1e-9)
    has = receiver >= 0
    assert (got <= h).all() and (got[has] <= got[receiver[has]] + slope[has] * length[has] + 1e-9).all()
    with pytest.raises(ValueError, match="max_slope"):
        bounded_beds(receiver, length, h, np.full(n, np.nan))


def _network(**kw):
    # constant cones (no relief scaling, no steeper cones below steep ridges, no gentle crest tails of lone
    # peaks) and no saddle floor: the rule is exactly ratio x 0.6 m/m on every edge
    params = RenderParams(lam=200.0, flank_slope=0.6, flank_ratio=0.0, flank_slope_relief_m=None,
                          ridge_tail_flank_slope=None, saddle_floor_ratio=None, **kw)
    return build_skeleton(small_tree(), extent=(0.0, 0.0, 8000.0, 8000.0), params=params, rng=3).river_network


def test_toy_tree_beds_have_no_step_steeper_than_the_hillslopes():
    """The small tree's beds: plain, some edge falls more steeply than the cones (0.6 m/m: a step where a
    tributary at its cap meets a deeper river); with the ratio 1 (0.5) none falls more than 0.6 (0.3) m/m, the
    receivers are the same, no bed rises, the beds still fall downstream, and the steps are gone, not the rivers:
    only beds that stood above the rule are lowered."""
    assert RenderParams().river_bed_slope_ratio is None
    plain = _network()
    r, L, h = plain.receiver, plain.length, plain.elevation
    has = r >= 0
    rise = h[has] - h[r[has]]
    assert (rise > 0.6 * L[has] + 1.0).sum() >= 3  # the steps
    for ratio in (1.0, 0.5):
        net = _network(river_bed_slope_ratio=ratio)
        np.testing.assert_array_equal(net.receiver, r)
        g = net.elevation
        assert (g <= h + 1e-9).all() and (g < h - 1.0).any()
        assert (g[has] - g[r[has]] <= ratio * 0.6 * L[has] + 1e-6).all()
        assert (g[has] >= g[r[has]] - 1e-9)[rise >= 0].all()  # beds that fell downstream still do
        np.testing.assert_allclose(g, bounded_beds(r, L, h, np.full(h.size, ratio * 0.6)), atol=1e-9)


def test_render_with_bounded_beds_keeps_the_orometry():
    """The small tree rendered with the defaults and the ratio 1: every peak recovered within 100 m, none extra,
    the hand-written prominences kept."""
    dem = render_elevation(small_tree(), cell_size_m=50.0, erosion=False,
                           params=RenderParams(lam=200.0, river_bed_slope_ratio=1.0), rng=7)
    assert_keeps_small_tree(dem)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_river_bed_slope_ratio_refuses_non_positive(bad):
    with pytest.raises(InputError, match="river_bed_slope_ratio"):
        RenderParams(river_bed_slope_ratio=bad)
