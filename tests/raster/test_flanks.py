"""Flank cones of the skeleton (issue 11, steep terrain): valleys cut at the critical hillslope
slope, as deep as the tree's own relief allows."""
from __future__ import annotations

import numpy as np
import pytest

from orokit.errors import InputError
from orokit.raster.params import RenderParams
from orokit.raster.rivers import local_relief
from orokit.raster.skeleton import build_skeleton, relief_slope

from helpers.trees import assert_keeps_tree, small_tree


def _skeleton(tree, **kw):
    return build_skeleton(tree, extent=(0.0, 0.0, 8000.0, 8000.0), params=RenderParams(lam=200.0, **kw), rng=3)


def test_default_cones_cut_deeper_valleys_than_gentle_cones():
    """The session-9 cones (``flank_slope`` 0.5, near the critical angle) put every river bed at or
    below where the session-8 cones (0.05) put it (same network; the bed is monotone in the cap),
    and far lower where the ridges are high; the samples follow."""
    tree = small_tree()
    assert RenderParams().flank_depth == 1.0
    gentle = _skeleton(tree, flank_slope=0.05, flank_slope_relief_m=None)
    steep = _skeleton(tree, flank_slope=0.5, flank_slope_relief_m=None)
    g, s = gentle.river_network.elevation, steep.river_network.elevation
    assert np.array_equal(gentle.river_network.receiver, steep.river_network.receiver)
    assert (s <= g + 1e-9).all()
    assert (s < g - 100.0).any()
    # the ground between ridges and rivers is lower on average (deeper valleys, not only beds)
    assert steep.tin.z.mean() < gentle.tin.z.mean() - 10.0



def test_relief_slope_follows_the_relief_up_to_the_critical_slope():
    """``relief_slope`` against its formula: the full slope from ``relief_m`` up, a power law below,
    never under ``min_slope``, monotone in the relief."""
    r = np.linspace(0.0, 3000.0, 61)
    for power in (0.5, 1.0, 2.0):
        got = relief_slope(r, 0.5, 1000.0, power=power, min_slope=0.1)
        want = np.maximum(0.1, 0.5 * np.minimum(r / 1000.0, 1.0) ** power)
        np.testing.assert_allclose(got, want)
        assert (np.diff(got) >= 0).all()
    assert (relief_slope(r, 0.5, 1000.0)[r >= 1000.0] == 0.5).all()
    # a minimum above the slope cannot raise the slope
    assert (relief_slope(r, 0.05, 1000.0, min_slope=0.2) == 0.05).all()
    with pytest.raises(ValueError):
        relief_slope(r, 0.5, 0.0)
    with pytest.raises(InputError):
        RenderParams(flank_slope_relief_m=0.0)
    with pytest.raises(InputError):
        RenderParams(flank_slope_gradient=-0.1)
    with pytest.raises(InputError):
        RenderParams(flank_slope_relief_m=500.0, flank_slope_gradient=0.2)
    # the default since session 10: the critical slope 0.6 from 1200 m of local relief up
    d = RenderParams()
    assert (d.flank_slope, d.flank_slope_relief_m, d.flank_slope_gradient) == (0.6, 1200.0, None)
    # since session 11: no cone gentler than 0.25, and the floor's ratio follows the same relief
    assert (d.flank_slope_min, d.saddle_floor_relief_m, d.saddle_floor_min_ratio) == (0.25, 800.0, 0.5)


@pytest.mark.parametrize("name, mid_scale", [("flank_slope_relief_m", 1200.0), ("flank_slope_gradient", 0.2)])
def test_relief_cones_lie_between_the_gentle_and_the_critical_cones(name, mid_scale):
    """With the cone slope following the tree's local relief or relief gradient, a scale
    far above the small tree's (600 m; over its ~5 km: ~0.1) gives the gentle cones of ``flank_slope_min``
    exactly, one far below it the default cones exactly; in between every river bed lies between the two
    (same network). The lone pieces' gentle crest tails (``ridge_tail_flank_slope``, default 0.1: the small tree's
    peaks stand > 3 km apart) are off: they would set the same cones in every variant."""
    tree = small_tree()
    off = {"flank_slope_relief_m": None, "ridge_tail_flank_slope": None}
    gentle = _skeleton(tree, flank_slope=0.05, **off)
    steep = _skeleton(tree, **off)
    low = _skeleton(tree, **{**off, name: 1e9}, flank_slope_min=0.05)
    high = _skeleton(tree, **{**off, name: 1e-9})
    np.testing.assert_array_equal(low.river_network.elevation, gentle.river_network.elevation)
    np.testing.assert_array_equal(low.tin.z, gentle.tin.z)
    np.testing.assert_array_equal(high.river_network.elevation, steep.river_network.elevation)
    np.testing.assert_array_equal(high.tin.z, steep.tin.z)
    mid = _skeleton(tree, **{**off, name: mid_scale})
    g, s, m = (k.river_network.elevation for k in (gentle, steep, mid))
    assert np.array_equal(mid.river_network.receiver, steep.river_network.receiver)
    assert (m <= g + 1e-9).all() and (m >= s - 1e-9).all()
    assert (m < g - 10.0).any() and (m > s + 10.0).any()


def test_local_relief_against_brute_force():
    rng = np.random.default_rng(5)
    peaks = np.column_stack([rng.uniform(0, 10_000, (30, 2)), rng.uniform(500, 900, 30)])
    saddles = np.column_stack([rng.uniform(0, 10_000, (25, 2)), rng.uniform(300, 500, 25)])
    q = rng.uniform(0, 10_000, (100, 2))
    for k in (1, 7):
        lo, hi, far = local_relief(q, peaks, saddles, k=k)
        ds = np.hypot(*(q[:, None, :] - saddles[None, :, :2]).transpose(2, 0, 1))
        dp = np.hypot(*(q[:, None, :] - peaks[None, :, :2]).transpose(2, 0, 1))
        np.testing.assert_allclose(lo, saddles[np.argsort(ds, axis=1)[:, :k], 2].min(axis=1))
        np.testing.assert_allclose(hi, peaks[np.argsort(dp, axis=1)[:, :k], 2].max(axis=1))
        np.testing.assert_allclose(far, np.sort(dp, axis=1)[:, k - 1])


def test_rounded_cone_apex_rounds_the_crest_and_keeps_the_orometry():
    """``flank_apex_m``: each cone lies s d^2 / 2 r0 below its ridge point within r0 and s (d - r0 / 2) beyond
    (continuous, at the sharp cone's slope there): never below the sharp cone, higher by exactly s r0 / 2 past r0
    (brute force over random cones); a render of the small tree keeps its peaks and prominences."""
    import orokit
    from orokit.raster.interpolate import flank_envelope
    from orokit.raster.render import render_elevation
    from orokit.validate.roundtrip import compare_peaks

    rng = np.random.default_rng(4)
    q = rng.uniform(0.0, 5000.0, (40, 2))
    z = rng.uniform(500.0, 1500.0, 40)
    s = rng.uniform(0.2, 1.0, 40)
    pts = rng.uniform(0.0, 5000.0, (500, 2))
    r0 = 300.0
    d = np.hypot(*(pts[:, None, :] - q[None, :, :]).transpose(2, 0, 1))
    f = np.where(d < r0, d * d / (2 * r0), d - r0 / 2)
    expect = np.max(z[None, :] - s[None, :] * f, axis=1)
    got = flank_envelope(pts, q, z, s, k_neighbours=40, apex_m=r0)
    np.testing.assert_allclose(got, expect, atol=1e-9)
    sharp = flank_envelope(pts, q, z, s, k_neighbours=40)
    assert (got >= sharp - 1e-9).all() and (got > sharp + 1.0).any()
    one = flank_envelope(np.array([[0.0, 100.0], [0.0, 1000.0]]), np.zeros((1, 2)), np.array([0.0]), np.array([0.6]),
                         apex_m=r0)
    np.testing.assert_allclose(one, [-0.6 * 100.0 ** 2 / (2 * r0), -0.6 * (1000.0 - r0 / 2)])
    zr = render_elevation(small_tree(), cell_size_m=50.0, erosion=False, params=RenderParams(flank_apex_m=r0), rng=7)
    res = orokit.analyze(zr, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(small_tree(), res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0
    np.testing.assert_allclose(comp.peaks["raster_prominence"].to_numpy(), [1500.0, 200.0, 200.0, 150.0, 100.0],
                               atol=1.0)
    for bad in (0.0, -5.0, float("nan")):
        with pytest.raises(InputError, match="flank_apex_m"):
            RenderParams(flank_apex_m=bad)


def test_rounded_hillslope_keeps_the_line_ends_and_has_the_cones_curvature():
    """``sample_elevation`` with per-ridge-point apex radii and ``crest_round``: radius 0 gives the paper's line
    exactly; a radius r0 gives ``h(q) - R f_r(d_T) / f_r(L)`` (``f_r`` = :func:`apex_distance` of radius r, R the
    ridge's height above the bed, L the hillslope's length) with r such that the crest's curvature is the cone's,
    ``s / r0``: the ridge and the valley floor's edge where they were, the crest round (brute force on one ridge point
    and one river point; a short hillslope becomes the parabola from crest to river)."""
    from orokit.raster.interpolate import apex_distance, sample_elevation

    ridge_xy, ridge_z = np.array([[0.0, 0.0]]), np.array([1000.0])
    river_xy, river_z, river_w = np.array([[2000.0, 0.0]]), np.array([0.0]), np.array([100.0])
    x = np.linspace(0.0, 2000.0, 41)
    pts = np.column_stack([x, np.zeros_like(x)])
    kw = dict(ridge_slope=np.array([0.6]), k_neighbours=1, floor_slope=0.0)
    line, _, _ = sample_elevation(pts, ridge_xy, ridge_z, river_xy, river_z, river_w, **kw)
    same, _, _ = sample_elevation(pts, ridge_xy, ridge_z, river_xy, river_z, river_w, apex_m=np.array([0.0]),
                                  crest_round=True, **kw)
    np.testing.assert_allclose(same, line)
    L, R = 1900.0, 1000.0
    for r0 in (300.0, 5000.0):
        got, _, _ = sample_elevation(pts, ridge_xy, ridge_z, river_xy, river_z, river_w, apex_m=np.array([r0]),
                                     crest_round=True, **kw)
        r = min(L - np.sqrt(max(L * L - 2.0 * R * r0 / 0.6, 0.0)), L)
        want = np.where(x >= L, 0.0, R - R * apex_distance(x, r) / apex_distance(np.array(L), r))
        env = R - 0.6 * apex_distance(x, r0)  # the cone caps with its own radius
        np.testing.assert_allclose(got, np.minimum(want, np.maximum(env, 0.0)), atol=1e-9)
        assert got[0] == R and got[-1] == 0.0
        assert (got[1:8] > line[1:8] + 5.0).all()
        if r < L:  # the crest's curvature is the cone's: 50 m out it lies s / r0 x 50^2 / 2 below the ridge
            assert abs((R - got[1]) - 0.6 / r0 * 50.0 ** 2 / 2.0) < 1e-6
        else:  # too short a hillslope for that curvature: the parabola
            np.testing.assert_allclose(got[x < L], R * (1.0 - (x[x < L] / L) ** 2))


def test_crest_relief_rounds_the_low_crests_keeps_the_steep_ones_and_the_orometry():
    """``crest_relief_m``: each ridge point's apex radius is ``crest_relief_m x s / G`` (G the tree's local relief
    gradient there): on a low-relief copy of the small tree (elevations / 5) the ground 100 m beside the crests
    lies much nearer the crest than without the option, on the tree itself (5x the gradient) the radius is 5x
    smaller; peaks and prominences stay the tree's. The lone pieces' gentle crest tails (default) are off: their 0.1
    cones would set the ground beside most of the small tree's crests in both copies."""
    from orokit.raster.render import render_elevation
    from orokit.raster.skeleton import crest_apex
    from orokit.validate.crest import crest_sections
    from orokit.topology.divide_tree import DivideTree

    r = crest_apex(np.zeros((2, 2)) + [[0.0, 0.0]], np.array([500.0, 500.0]), np.array([0.6, 0.3]),
                   np.array([0.2, 0.05]), length_m=80.0, saddle_xyz=np.zeros((0, 3)), clearance_m=400.0)
    np.testing.assert_allclose(r, [240.0, 480.0])
    base = small_tree()
    low = DivideTree.from_arrays(base.peaks[["x", "y", "elevation"]].to_numpy() / [1, 1, 5],
                                 base.saddles[["x", "y", "elevation"]].to_numpy() / [1, 1, 5],
                                 base.edges[["peak_a", "peak_b", "saddle"]].to_numpy(), attrs=base.attrs)
    drops = {}
    for label, tree in (("low", low), ("tree", base)):
        for relief in (None, 80.0):
            z = render_elevation(tree, cell_size_m=50.0, erosion=False, rng=7,
                                 params=RenderParams(crest_relief_m=relief, ridge_tail_flank_slope=None))
            p, s = tree.peaks[["x", "y"]].to_numpy(), tree.saddles[["x", "y"]].to_numpy()
            e = tree.edges[["peak_a", "peak_b", "saddle"]].to_numpy()
            cs = crest_sections(z.values, (0.0, 8000.0, 50.0), np.concatenate([p[e[:, 0]], p[e[:, 1]]]),
                                np.concatenate([s[e[:, 2]], s[e[:, 2]]]), offsets_m=(100.0,), skip_peak_m=300.0,
                                skip_saddle_m=500.0, border_m=300.0, search_m=100.0)
            assert cs.drop.shape[0] >= 10
            drops[label, relief] = float(cs.median()[0])
            assert_keeps_tree(tree, z, distance_tol_m=100.0, atol=6.0)
    # seed 7: low 18.6 -> 7.4 m, the tree 25.6 -> 12.1 m
    assert drops["low", 80.0] < 0.5 * drops["low", None]
    assert drops["tree", 80.0] > drops["low", 80.0]
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(InputError, match="crest_relief_m"):
            RenderParams(crest_relief_m=bad)
