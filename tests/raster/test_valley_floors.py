"""Valley floors and cone depth options of the skeleton (issue 11, session 13): ``floor_slope``,
``valley_floor_slope`` and ``flank_depth_saddle_ratio`` (all off by default)."""
from __future__ import annotations

import numpy as np
import pytest

import orokit
from orokit.errors import InputError
from orokit.raster.interpolate import sample_elevation
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation
from orokit.raster.skeleton import build_skeleton
from orokit.validate.roundtrip import compare_peaks

from helpers.trees import small_tree

RIDGE, RIVER = np.array([[0.0, 0.0]]), np.array([[1000.0, 0.0]])


def _h(p, **kw):
    return sample_elevation(np.asarray(p, float), RIDGE, np.array([1000.0]), RIVER, np.array([0.0]),
                            np.array([200.0]), **kw)[0]


def test_valley_floor_slope_tilts_the_floor_and_the_flank_starts_at_its_edge():
    """Hand-computed: a river at x 1000 m (bed 0, floor half-width 200 m), a ridge at 0 (1000 m)."""
    p = [[950.0, 0.0], [850.0, 0.0], [400.0, 0.0]]
    np.testing.assert_allclose(_h(p), [0.0, 0.0, 1000.0 * (1 - 400.0 / 800.0)])  # flat floor, the paper's line
    # the floor rises at 0.1 from the bed: 5 and 15 m; the flank runs from the floor's edge (20 m) to the ridge
    np.testing.assert_allclose(_h(p, valley_floor_slope=0.1), [5.0, 15.0, 1000.0 - (1000.0 - 20.0) * 400.0 / 800.0])
    np.testing.assert_array_equal(_h(p, valley_floor_slope=0.0), _h(p))


def test_floor_slope_sets_the_ramp_where_the_cones_have_fallen():
    """Where the cone (1000 - 2 d) lies below it, the ground rises from the floor's edge at ``floor_slope``:
    0.05 by default (as before the option), 0.1 twice as high, never above the linear profile."""
    p = [[500.0, 0.0], [700.0, 0.0]]
    cone = dict(ridge_slope=np.array([2.0]))
    np.testing.assert_allclose(_h(p, **cone), [0.05 * 300.0, 0.05 * 100.0])
    np.testing.assert_allclose(_h(p, floor_slope=0.1, **cone), [30.0, 10.0])
    np.testing.assert_allclose(_h(p, floor_slope=10.0, **cone), _h(p))
    assert RenderParams().floor_slope == 0.05


def _skeleton(**kw):
    return build_skeleton(small_tree(), extent=(0.0, 0.0, 8000.0, 8000.0), params=RenderParams(lam=200.0, **kw),
                          rng=3)


def test_options_off_by_default_keep_the_skeleton_and_on_only_raise_it():
    """Explicit off values of these options give the default TIN; a steeper
    ``floor_slope`` or a tilted floor only raises samples; shallower cones (``flank_depth_saddle_ratio``)
    raise the beds' cap, so no bed is lower (the bed is monotone in the cap) and some are higher."""
    d = RenderParams()
    assert (d.valley_floor_slope, d.flank_depth_saddle_ratio) == (0.0, None)
    base = _skeleton()
    off = _skeleton(floor_slope=0.05, valley_floor_slope=0.0, flank_depth_saddle_ratio=None)
    np.testing.assert_array_equal(base.tin.z, off.tin.z)
    for kw in ({"floor_slope": 0.3}, {"valley_floor_slope": 0.2}):
        on = _skeleton(**kw)
        np.testing.assert_array_equal(on.river_network.elevation, base.river_network.elevation)
        assert on.tin.z.shape == base.tin.z.shape
        assert (on.tin.z >= base.tin.z - 1e-9).all() and (on.tin.z > base.tin.z + 1.0).any(), kw
    shallow = _skeleton(flank_depth_saddle_ratio=0.0)
    np.testing.assert_array_equal(shallow.river_network.receiver, base.river_network.receiver)
    assert (shallow.river_network.elevation >= base.river_network.elevation - 1e-9).all()
    assert (shallow.river_network.elevation > base.river_network.elevation + 1.0).any()


@pytest.mark.parametrize("name", ["floor_slope", "valley_floor_slope", "flank_depth_saddle_ratio"])
def test_negative_values_are_refused(name):
    with pytest.raises(InputError, match=name):
        RenderParams(**{name: -0.1})
    with pytest.raises(InputError, match="flank_depth_saddle_k"):
        RenderParams(flank_depth_saddle_k=0)


def test_cone_floor_depth_is_bounded_by_the_saddle_drop():
    """``_cone_floor`` per piece: ``saddle - ratio * min(peak - saddle, drop)`` (hand-computed, one piece
    peak 1000 m -> saddle 600 m, refined into points that all come from it)."""
    from orokit.raster.refine import densify, refine_segments
    from orokit.raster.rivers import ridge_segments
    from orokit.raster.skeleton import _cone_floor

    p = np.array([[0.0, 0.0, 1000.0], [2000.0, 0.0, 900.0]])
    s = np.array([[1000.0, 0.0, 600.0]])
    e = np.array([[0, 1, 0]])
    pieces = ridge_segments(p, s, e)
    nodes = np.concatenate([p, s])
    lines = refine_segments(nodes[:, :2], nodes[:, 2], np.column_stack([pieces.node0, pieces.node1]), lam=200.0,
                            jitter=0.0, rng=0)
    _, _, _, orig = densify(lines, 50.0, value="slope", origin=True)
    full = _cone_floor(lines, orig, pieces, nodes[:, 2], 1.0)
    assert full is not None and set(np.round(full, 6).tolist()) == {200.0, 300.0}  # 600 - 400, 600 - 300
    capped = _cone_floor(lines, orig, pieces, nodes[:, 2], 1.0, np.array([50.0, 350.0]))
    assert capped is not None and set(np.round(capped, 6).tolist()) == {550.0, 300.0}  # min(400, 50), min(300, 350)


def test_render_with_the_options_keeps_the_orometry():
    """The small tree rendered with all three on: every peak recovered, none extra."""
    tree = small_tree()
    params = RenderParams(lam=200.0, floor_slope=0.15, valley_floor_slope=0.15, flank_depth_saddle_ratio=1.0)
    dem = render_elevation(tree, cell_size_m=50.0, erosion=False, params=params, rng=7)
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0


def test_graded_beds_fall_evenly_between_anchors_never_above_the_staircase():
    """``river_graded``: on the small tree's network the beds are never above the plain sweep's, fall
    downstream by at least the sweep's drop, keep the nodes at their bound (the anchors) where nothing
    upstream lowers them, and some flats of the staircase are gone (a bed lower by > 1 m)."""
    from orokit.raster.rivers import graded_beds

    assert RenderParams().river_graded is False
    for floor in (1.0, None):  # with the saddle floor and without it (the floor may raise beds into closed depressions)
        plain = _skeleton(saddle_floor_ratio=floor).river_network
        graded = _skeleton(saddle_floor_ratio=floor, river_graded=True).river_network
        np.testing.assert_array_equal(plain.receiver, graded.receiver)
        h, g, r = plain.elevation, graded.elevation, plain.receiver
        assert (g <= h + 1e-9).all() and (g < h - 1.0).any()
    has = r >= 0
    has[has] = g[r[has]] > g.min() + 1e-9  # beds clamped at the base elevation (outlets) fall less
    assert (g[has] >= g[r[has]] + 0.01 * plain.length[has] - 1e-6).all()  # the last loop: no floor
    # a straight chain: source at its bound 100 m, then 3 sweep-bound nodes, an anchor at 40, outlet at 0
    rec = np.array([-1, 0, 1, 2, 3, 4])
    ln = np.array([0.0, 100.0, 100.0, 100.0, 100.0, 100.0])
    start = np.array([0.0, 40.0, 500.0, 500.0, 500.0, 100.0])
    swept = np.array([0.0, 40.0, 97.0, 98.0, 99.0, 100.0])
    np.testing.assert_allclose(graded_beds(rec, ln, 0.01 * ln, start, swept), [0.0, 40.0, 55.0, 70.0, 85.0, 100.0])


def test_render_with_graded_beds_keeps_the_orometry():
    tree = small_tree()
    dem = render_elevation(tree, cell_size_m=50.0, erosion=False, params=RenderParams(lam=200.0, river_graded=True),
                           rng=7)
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0


def test_river_base_slope_lifts_the_beds_pinned_at_the_base_level():
    """``river_base_slope``: on, no bed is lower than the plain sweep's (the sweep is monotone in its start),
    fewer beds lie at the base elevation (the lowest bed), the beds still fall downstream by at least
    ``river_slope`` per metre where not clamped, and a steeper lift raises at least as much; the saddle bound
    (``river_base_saddle_k``) only lowers the lifted beds, never below the plain sweep's."""
    assert (RenderParams().river_base_slope, RenderParams().river_base_saddle_k) == (0.01, 16)  # session 14
    off = {"river_base_slope": None, "river_base_saddle_k": None}
    plain = _skeleton(**off).river_network
    h = plain.elevation
    base = h.min()
    at_base = int(np.sum(h <= base + 1e-6))
    assert at_base > plain.outlet.sum()  # the small tree's long rivers run at the base level (the flats)
    last = h
    for s in (0.01, 0.05):
        net = _skeleton(**{**off, "river_base_slope": s}).river_network
        np.testing.assert_array_equal(plain.receiver, net.receiver)
        g, r = net.elevation, net.receiver
        assert (g >= last - 1e-9).all() and (g > last + 1.0).any()
        assert int(np.sum(g <= base + 1e-6)) < at_base
        has = r >= 0
        has[has] = g[r[has]] > base + 1e-9
        assert (g[has] >= g[r[has]] + 0.01 * net.length[has] - 1e-6).all()
        last = g
        capped = _skeleton(river_base_slope=s, river_base_saddle_k=4).river_network.elevation
        assert (capped >= h - 1e-9).all() and (capped <= g + 1e-9).all() and (capped < g - 1.0).any()
    for name in ("river_base_slope", "river_base_saddle_k"):
        with pytest.raises(InputError, match=name):
            RenderParams(**{name: -1})


def test_render_with_river_base_slope_keeps_the_orometry():
    tree = small_tree()
    dem = render_elevation(tree, cell_size_m=50.0, erosion=False,
                           params=RenderParams(lam=200.0, river_base_slope=0.02, river_base_saddle_k=16), rng=7)
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0


def test_border_beyond_slope_falls_past_the_river_toward_the_border():
    """Hand-computed: ridge at x 0 (1000 m), river at x 1000 (bed 0, floor half-width 200 m). Past the river
    (x > 1000) the paper's line climbs again toward 1/2 of the ridge; with ``beyond_slope`` a point there nearer
    the border than the ridge falls from the bed at that slope; points before the river, or nearer the ridge
    than the border, keep the paper's line."""
    p = [[1600.0, 0.0], [2000.0, 0.0], [400.0, 0.0]]
    plain = _h(p)
    assert plain[0] > 100.0 and plain[1] > plain[0]  # the climb past the river
    near_border = np.array([100.0, 10.0, 100.0])
    np.testing.assert_allclose(_h(p, border_distance=near_border, beyond_slope=0.05),
                               [-0.05 * 400.0, -0.05 * 800.0, plain[2]])
    far = np.array([5000.0, 5000.0, 100.0])  # farther from the border than from the ridge: unchanged
    np.testing.assert_array_equal(_h(p, border_distance=far, beyond_slope=0.05), plain)
    np.testing.assert_array_equal(_h(p, border_distance=near_border), plain)  # no slope: off
    with pytest.raises(ValueError, match="beyond_slope"):
        _h(p, border_distance=near_border, beyond_slope=-0.1)
    with pytest.raises(InputError, match="border_beyond_slope"):
        RenderParams(border_beyond_slope=-0.1)


def test_border_beyond_slope_off_by_default_and_on_only_lowers_samples():
    assert RenderParams().border_beyond_slope is None
    base = _skeleton()
    np.testing.assert_array_equal(base.tin.z, _skeleton(border_beyond_slope=None).tin.z)
    on = _skeleton(border_beyond_slope=0.05)
    np.testing.assert_array_equal(on.river_network.elevation, base.river_network.elevation)
    assert on.tin.z.shape == base.tin.z.shape
    assert (on.tin.z <= base.tin.z + 1e-9).all() and (on.tin.z < base.tin.z - 1.0).any()


def test_render_with_border_beyond_slope_keeps_the_orometry():
    tree = small_tree()
    dem = render_elevation(tree, cell_size_m=50.0, erosion=False,
                           params=RenderParams(lam=200.0, border_beyond_slope=0.05), rng=7)
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0
