"""Crests that fall from their peak at a bounded slope (``RenderParams.ridge_max_slope``; by default 1.0 on the
pieces ``ridge_plateau_spread`` selects)."""
from __future__ import annotations

import numpy as np
import pytest

import orokit
from orokit.errors import InputError
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation
from orokit.raster.skeleton import RIDGE_TAIL_SLOPE, build_skeleton, steep_ridge_profile
from orokit.validate.roundtrip import compare_peaks

from helpers.trees import assert_keeps_small_tree, assert_keeps_tree, small_tree


def test_steep_ridge_profile_falls_at_the_slope_then_runs_low_never_above_the_line():
    rng = np.random.default_rng(0)
    m = 200
    peak = np.column_stack([np.zeros(m), np.zeros(m), rng.uniform(500.0, 3000.0, m)])
    length = rng.uniform(200.0, 20000.0, m)
    saddle = np.column_stack([length, np.zeros(m), peak[:, 2] - rng.uniform(0.0, 2500.0, m)])
    saddle[:, 2] = np.minimum(saddle[:, 2], peak[:, 2])
    f = steep_ridge_profile(peak, saddle, 0.8)
    t = np.linspace(0.0, 1.0, 101)
    for i in range(m):
        w = f(t, np.full(t.size, i))
        h = peak[i, 2] - saddle[i, 2]
        assert w[0] == 0.0 and w[-1] == pytest.approx(1.0)
        assert (np.diff(w) >= -1e-12).all()  # the crest never climbs toward the saddle
        assert (w >= t - 1e-12).all()  # never above the straight line
        z = peak[i, 2] - w * h
        d = t * length[i]
        if h / length[i] >= 0.8:  # a short or steep piece keeps its line
            np.testing.assert_allclose(w, t, atol=1e-12)
        else:  # above its tail the crest falls at 0.8 from the peak; below it, at the tail's slope to the saddle
            tail = min(RIDGE_TAIL_SLOPE, h / length[i]) * (length[i] - d)
            np.testing.assert_allclose(z - saddle[i, 2], np.maximum(peak[i, 2] - 0.8 * d - saddle[i, 2], tail),
                                       atol=1e-6)
    with pytest.raises(ValueError, match="max_slope"):
        steep_ridge_profile(peak, saddle, 0.0)
    with pytest.raises(InputError, match="ridge_max_slope"):
        RenderParams(ridge_max_slope=-1.0)


def test_steep_ridges_lie_at_or_below_the_straight_crests_and_keep_the_tree_orometry():
    """The same jitter draws: every refined ridge point lies where the straight crest put it in the plane and no
    higher, lower on the small tree's long gentle pieces; a render keeps the tree's peaks and prominences."""
    kw = {"extent": (0.0, 0.0, 8000.0, 8000.0), "rng": 3}
    plain = build_skeleton(small_tree(), params=RenderParams(lam=200.0, ridge_max_slope=None), **kw)
    steep = build_skeleton(small_tree(), params=RenderParams(lam=200.0, ridge_max_slope=0.8), **kw)
    np.testing.assert_array_equal(plain.ridges.xy, steep.ridges.xy)
    assert (steep.ridges.z <= plain.ridges.z + 1e-9).all()
    assert (steep.ridges.z < plain.ridges.z - 100.0).any()
    z = render_elevation(small_tree(), cell_size_m=50.0, erosion=False, params=RenderParams(ridge_max_slope=0.8),
                         rng=7)
    assert_keeps_small_tree(z)


def test_plateau_pieces_tell_a_level_base_from_a_falling_one():
    """Saddles all at one level under high peaks (volcanoes on a plain): every piece is a plateau's; the same
    field tilted so the base level falls 1 km over the domain (a range draining to its main valleys): none."""
    from orokit.raster.skeleton import plateau_pieces

    rng = np.random.default_rng(1)
    sxy = rng.uniform(0.0, 50000.0, (300, 2))
    pxy = rng.uniform(0.0, 50000.0, (300, 2))
    peaks = np.column_stack([pxy, 4000.0 + rng.uniform(200.0, 1500.0, 300)])
    level = np.column_stack([sxy, 4000.0 + rng.uniform(0.0, 20.0, 300)])
    assert plateau_pieces(level, peaks, level, 0.05).all()
    tilt = level.copy()
    tilt[:, 2] -= 2.0 * sxy[:, 0] / 50.0  # 2 km over 50 km, saddles and peaks alike
    peaks_t = peaks.copy()
    peaks_t[:, 2] -= 2.0 * pxy[:, 0] / 50.0
    assert plateau_pieces(tilt, peaks_t, tilt, 0.05).mean() < 0.2


def test_ridge_plateau_drop_is_checked():
    """A negative or NaN drop selected no piece, and a drop without ridge_max_slope did nothing (both silently):
    refused, naming the fix."""
    for bad in (-0.1, 0.0, float("nan")):
        with pytest.raises(InputError, match="ridge_plateau_drop must be > 0"):
            RenderParams(ridge_max_slope=0.8, ridge_plateau_drop=bad)
    with pytest.raises(InputError, match="set ridge_max_slope too"):
        RenderParams(ridge_max_slope=None, ridge_plateau_drop=0.05)
    assert RenderParams(ridge_max_slope=0.8, ridge_plateau_drop=0.05).ridge_plateau_drop == 0.05


def _field(rng, n, saddle_span, peak_lo, peak_hi, size=50000.0):
    sxy = rng.uniform(0.0, size, (n, 2))
    pxy = rng.uniform(0.0, size, (n, 2))
    saddles = np.column_stack([sxy, 4000.0 + rng.uniform(0.0, saddle_span, n)])
    peaks = np.column_stack([pxy, 4000.0 + rng.uniform(peak_lo, peak_hi, n)])
    return peaks, saddles


def test_spread_pieces_select_volcanoes_on_a_plain_not_dunes_nor_ranges():
    """Level saddles under peaks 0.2-1.5 km higher (volcanoes on a plateau): every piece; the same field 20-150 m
    high (a dune field, relief under the bound): none; saddles spread over the whole relief (a range): few."""
    from orokit.raster.skeleton import spread_pieces

    rng = np.random.default_rng(2)
    peaks, saddles = _field(rng, 300, 20.0, 200.0, 1500.0)
    assert spread_pieces(saddles, peaks, saddles, 0.25, min_relief_m=300.0).all()
    dunes_p, dunes_s = _field(rng, 300, 5.0, 20.0, 150.0)
    assert spread_pieces(dunes_s, dunes_p, dunes_s, 0.25).all()  # level saddles ...
    assert not spread_pieces(dunes_s, dunes_p, dunes_s, 0.25, min_relief_m=300.0).any()  # ... under low domes
    range_p, range_s = _field(rng, 300, 2000.0, 1500.0, 2500.0)
    assert spread_pieces(range_s, range_p, range_s, 0.25, min_relief_m=300.0).mean() < 0.05


def test_spread_pieces_follow_the_tree_piece_by_piece():
    """Volcanoes on a plain in the west half and a range in the east half of one tree: the cut selects the west's
    pieces, not the east's (a per-piece quantity, not one value per tree); brute force over all pairs."""
    from orokit.raster.skeleton import spread_pieces

    rng = np.random.default_rng(3)
    vp, vs = _field(rng, 400, 20.0, 200.0, 1500.0)
    rp, rs = _field(rng, 400, 2000.0, 1500.0, 2500.0)
    vp[:, 0] *= 0.5
    vs[:, 0] *= 0.5
    rp[:, 0] = 50000.0 + 0.5 * rp[:, 0]
    rs[:, 0] = 50000.0 + 0.5 * rs[:, 0]
    peaks, saddles = np.concatenate([vp, rp]), np.concatenate([vs, rs])
    sel = spread_pieces(saddles, peaks, saddles, 0.25, min_relief_m=300.0)
    # brute force: nearest 16 by full distance matrices
    ds = np.hypot(*(saddles[:, None, :2] - saddles[None, :, :2]).transpose(2, 0, 1))
    dp = np.hypot(*(saddles[:, None, :2] - peaks[None, :, :2]).transpose(2, 0, 1))
    ns = np.argsort(ds, axis=1)[:, :16]
    low = saddles[ns, 2].min(axis=1)
    relief = peaks[np.argsort(dp, axis=1)[:, :16], 2].max(axis=1) - low
    spread = (np.median(saddles[ns, 2], axis=1) - low) / np.maximum(relief, 1.0)
    expect = (np.median(spread[ns], axis=1) <= 0.25) & (relief >= 300.0)
    np.testing.assert_array_equal(sel, expect)
    west = saddles[:, 0] < 20000.0
    east = saddles[:, 0] > 60000.0
    assert sel[west].mean() > 0.95 and sel[east].mean() < 0.1


def test_ridge_plateau_spread_bounds_only_the_selected_pieces():
    """The small tree's saddles lie within 0.21 of its 600-m relief: with the cut at 0.25 every piece is
    selected (the crests of ``ridge_max_slope`` alone); with a relief bound above 600 m none is (straight crests)."""
    kw = {"extent": (0.0, 0.0, 8000.0, 8000.0), "rng": 3}
    plain = build_skeleton(small_tree(), params=RenderParams(lam=200.0, ridge_max_slope=None), **kw)
    steep = build_skeleton(small_tree(), params=RenderParams(lam=200.0, ridge_max_slope=0.8,
                                                             ridge_plateau_spread=None), **kw)
    both = build_skeleton(small_tree(), params=RenderParams(lam=200.0, ridge_max_slope=0.8, ridge_plateau_spread=0.25,
                                                            ridge_plateau_relief_m=300.0), **kw)
    none = build_skeleton(small_tree(), params=RenderParams(lam=200.0, ridge_max_slope=0.8, ridge_plateau_spread=0.25,
                                                            ridge_plateau_relief_m=700.0), **kw)
    np.testing.assert_array_equal(both.ridges.z, steep.ridges.z)
    np.testing.assert_array_equal(none.ridges.z, plain.ridges.z)
    assert (steep.ridges.z < plain.ridges.z - 100.0).any()
    for bad in ({"ridge_plateau_spread": -0.1}, {"ridge_plateau_spread": float("nan")},
                {"ridge_plateau_relief_m": -1.0}):
        with pytest.raises(InputError, match=next(iter(bad))):
            RenderParams(ridge_max_slope=0.8, **bad)
    # the defaults: 1.0 on the pieces the cut at 0.25 / 300 m selects; None turns the bound off whatever the cut
    assert (RenderParams().ridge_max_slope, RenderParams().ridge_plateau_spread,
            RenderParams().ridge_plateau_relief_m) == (1.0, 0.25, 300.0)
    off = build_skeleton(small_tree(), params=RenderParams(lam=200.0, ridge_max_slope=None, ridge_plateau_spread=0.25),
                         **kw)
    np.testing.assert_array_equal(off.ridges.z, plain.ridges.z)


def test_river_blend_k_removes_the_step_where_the_nearest_river_changes():
    """Two straight rivers 1 km apart in elevation, a ridge far off: with the nearest bed the hillslope points
    step by ~alpha x 1 km where the nearer river changes; the blend of the 64 nearest steps by < 10 % of that, equal
    to the nearest bed's where one river is far, and ``river_blend_k`` None keeps the old elevations exactly."""
    from orokit.raster.interpolate import sample_elevation

    t = np.arange(0.0, 10000.0, 50.0)
    low = np.column_stack([t, np.zeros_like(t)])           # trunk along y = 0 at 1000 m
    high = np.column_stack([t, np.full_like(t, 2000.0)])   # tributary along y = 2000 at 2000 m
    rxy = np.concatenate([low, high])
    rz = np.concatenate([np.full(t.size, 1000.0), np.full(t.size, 2000.0)])
    rw = np.full(rxy.shape[0], 10.0)
    ridge = np.array([[5000.0, 20000.0]])
    ridge_z = np.array([4000.0])
    y = np.arange(800.0, 1200.0, 5.0)
    pts = np.column_stack([np.full_like(y, 5000.0), y])
    near, _, _ = sample_elevation(pts, ridge, ridge_z, rxy, rz, rw)
    blend, _, _ = sample_elevation(pts, ridge, ridge_z, rxy, rz, rw, river_blend_k=64)
    step_near, step_blend = np.abs(np.diff(near)).max(), np.abs(np.diff(blend)).max()
    assert step_near > 100.0  # the step at y = 1000
    assert step_blend < 0.1 * step_near  # what is left: points entering the 64 nearest
    again, _, _ = sample_elevation(pts, ridge, ridge_z, rxy, rz, rw, river_blend_k=None)
    np.testing.assert_array_equal(again, near)
    far = np.array([[5000.0, 30.0]])  # beside the trunk, the tributary 2 km off: weights ~ 1/d^2
    a, _, _ = sample_elevation(far, ridge, ridge_z, rxy, rz, rw)
    b, _, _ = sample_elevation(far, ridge, ridge_z, rxy, rz, rw, river_blend_k=64)
    assert abs(a[0] - b[0]) < 5.0
    with pytest.raises(InputError, match="river_blend_k"):
        RenderParams(river_blend_k=1)


@pytest.mark.parametrize("name", ["river_blend_k", "saddle_floor_k", "flank_neighbours", "erosion_steps",
                                  "river_base_saddle_k", "erosion_max_nodes", "river_foot_k"])
def test_counts_are_whole_numbers(name):
    """A count given as 2.5 was cut to 2 by ``int()`` (``river_blend_k=2.5`` blended 2 rivers), silently: refused
    naming the parameter; a whole float (JSON's 3.0) is its int, a bool or a string is refused."""
    for bad in (2.5, True, "3", float("nan")):
        with pytest.raises(InputError, match=f"{name} must be a whole number"):
            RenderParams(**{name: bad})
    assert getattr(RenderParams(**{name: 3.0}), name) == 3 and isinstance(getattr(RenderParams(**{name: 3.0}), name), int)
    assert RenderParams(erosion_steps=(4.0, 2)).erosion_steps == (4, 2)
    with pytest.raises(InputError, match="erosion_steps"):
        RenderParams(erosion_steps=(4, 2.5))


def test_river_foot_band_blends_the_foot_only_across_the_jump():
    """Two straight rivers 2 km apart, the trunk at 1000 m and a tributary at 2000 m: with the nearest bed the
    hillslope steps by ~1 km x (1 - profile) on the line where both are equally far (a cliff band in the TIN);
    ``river_foot_band`` moves the foot from one bed to the other over a band as wide as ``band`` x the jump's excess
    over ``slope`` x the rivers' distance, so no 5-m step climbs more than 1 m per m. Along one steep bed (slope
    0.2 < ``river_foot_slope``) and beside one river the foot stays the nearest bed exactly, where
    ``river_blend_k`` moves it; None keeps the old elevations exactly."""
    from orokit.raster.interpolate import sample_elevation

    t = np.arange(0.0, 10000.0, 50.0)
    rxy = np.concatenate([np.column_stack([t, np.zeros_like(t)]), np.column_stack([t, np.full_like(t, 2000.0)])])
    rz = np.concatenate([np.full(t.size, 1000.0), np.full(t.size, 2000.0)])
    rw = np.full(rxy.shape[0], 10.0)
    ridge, ridge_z = np.array([[5000.0, 20000.0]]), np.array([4000.0])
    y = np.arange(300.0, 1700.0, 5.0)
    pts = np.column_stack([np.full_like(y, 5000.0), y])
    near, _, _ = sample_elevation(pts, ridge, ridge_z, rxy, rz, rw)
    foot, _, _ = sample_elevation(pts, ridge, ridge_z, rxy, rz, rw, river_foot_band=2.0)
    assert np.abs(np.diff(near)).max() > 100.0  # the step at y = 1000
    assert np.abs(np.diff(foot)).max() < 10.0  # < 2 m per m over 5-m steps (the hillslope itself included)
    assert np.abs(np.diff(foot)).max() < 0.01 * np.abs(np.diff(near)).max()
    np.testing.assert_array_equal(foot[[0, -1]], near[[0, -1]])  # 700 m from the line: the nearest bed
    again, _, _ = sample_elevation(pts, ridge, ridge_z, rxy, rz, rw, river_foot_band=None)
    np.testing.assert_array_equal(again, near)
    # one river whose bed climbs 0.2 m/m: the foot is its nearest point's bed, as without the option
    steep_z = 1000.0 + 0.2 * t
    side = np.column_stack([np.arange(500.0, 9500.0, 37.0), np.full(244, 600.0)])
    a, _, _ = sample_elevation(side, ridge, ridge_z, rxy[: t.size], steep_z, rw[: t.size])
    b, _, _ = sample_elevation(side, ridge, ridge_z, rxy[: t.size], steep_z, rw[: t.size], river_foot_band=2.0)
    c, _, _ = sample_elevation(side, ridge, ridge_z, rxy[: t.size], steep_z, rw[: t.size], river_blend_k=64)
    np.testing.assert_array_equal(b, a)
    assert np.abs(c - a).max() > 1.0  # the k-nearest mean moves it
    # at the valley floor's edge (d0 = w0) the foot is the nearest bed whatever the other river: no step where the
    # hillslope starts; halfway to the line where both are equally far it is between the beds
    from orokit.raster.interpolate import foot_across_jumps

    d0 = np.array([300.0, 650.0, 1000.0])
    xy0 = np.array([[5000.0, 0.0]] * 3)
    other = np.array([[[5000.0, 2000.0]]] * 3)
    got = foot_across_jumps(d0, xy0, np.full(3, 1000.0), 2000.0 - d0[:, None], other, np.full((3, 1), 2000.0),
                            band=2.0, slope=0.25, w0=300.0)
    assert got[0] == 1000.0 and 1000.0 < got[1] < 1500.0 and got[2] == 1500.0
    for bad in ({"river_foot_band": 0.0}, {"river_foot_slope": -0.1}, {"river_foot_k": 1}):
        with pytest.raises(InputError, match=next(iter(bad))):
            RenderParams(**bad)


def test_cut_bowls_never_take_a_crest_below_its_saddle():
    """Strong detail on crests that fall gently to their saddles (``ridge_max_slope`` 1.0 on every piece of the
    small tree) makes hills on the crest near the saddle; with ``cut_slope`` > 0 their cut bowls went below the
    crest's own saddle and opened passes 4-19 m under the tree's saddles (prominences off by that much): the
    ridge cells now stop at their floor, and the prominences are the tree's."""
    p = RenderParams(detail_gain=30.0, detail_flat_deg=2.0, keep_hill_ratio=0.5, cut_slope=0.05,
                     ridge_max_slope=1.0, ridge_plateau_spread=None)
    z = render_elevation(small_tree(), cell_size_m=50.0, erosion=False, params=p, rng=11)
    assert_keeps_small_tree(z, atol=1.0)


def _volcano_tree():
    """A 5000-m volcano amid six 4300-4400-m hills 11 km out on a plateau, each joined to it through a saddle at
    4000-4010 m 9 km out: six 9-km pieces falling 1 km, whose crests ``ridge_max_slope`` 1.0 cuts to a 1-km steep
    part and an 8-km tail."""
    from orokit.topology.divide_tree import DivideTree

    ang = np.arange(6) * np.pi / 3.0 + 0.3
    c = 15000.0
    hills = np.column_stack([c + 11000.0 * np.cos(ang), c + 11000.0 * np.sin(ang), 4300.0 + 20.0 * np.arange(6)])
    saddles = np.column_stack([c + 9000.0 * np.cos(ang), c + 9000.0 * np.sin(ang), 4000.0 + 2.0 * np.arange(6)])
    peaks = np.concatenate([[[c, c, 5000.0]], hills])
    edges = np.column_stack([np.zeros(6, int), np.arange(1, 7), np.arange(6)])
    return DivideTree.from_arrays(peaks, saddles, edges, attrs={"extent": [0.0, 0.0, 30000.0, 30000.0]})


def test_ridge_tail_flank_slope_lays_the_spokes_into_the_plateau_and_keeps_the_orometry():
    """The six cut crests' tails run 0.02 m/m above their saddles; with cones at the flank slope (0.6 m/m here) the
    ground beside them falls 60+ m within 400 m (a spoke across the plateau, andes-chile's render); with
    ``ridge_tail_flank_slope`` 0.05 the tails' cones fall at 0.05 and the ground beside them stays near their
    level (the real plateau: 4 m at 400 m; here 64 -> 18 m). Peaks and prominences stay the tree's."""
    from orokit.validate.crest import crest_sections

    tree = _volcano_tree()
    kw = dict(lam=200.0, ridge_max_slope=1.0, ridge_plateau_spread=None, flank_slope_relief_m=None)
    drops = []
    for tail in (None, 0.05):
        z = render_elevation(tree, cell_size_m=100.0, erosion=False, rng=5,
                             params=RenderParams(**kw, ridge_tail_flank_slope=tail))
        p = tree.peaks[["x", "y"]].to_numpy()
        cs = crest_sections(z.values, (0.0, 30000.0, 100.0), np.repeat(p[:1], 6, axis=0),
                            tree.saddles[["x", "y"]].to_numpy(), offsets_m=(400.0,), skip_peak_m=2500.0,
                            skip_saddle_m=1000.0)
        assert cs.drop.shape[0] >= 6 * 25
        drops.append(float(cs.median()[0]))
        res = orokit.analyze(z, min_prominence_m=30.0, isolation=False)
        comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=200.0)
        assert comp.recovered_share == 1.0 and len(comp.extra) == 0
        np.testing.assert_allclose(np.sort(comp.peaks["raster_prominence"].to_numpy()),
                                   np.sort(comp.peaks["prominence"].to_numpy()), atol=1.0)
    # no option: the 0.6 cones; with it the ground beside falls no faster than the tails' own 0.05 cones
    assert drops[0] > 50.0 and drops[1] <= 0.05 * 400.0 + 1.0 and drops[1] < 0.3 * drops[0]
    with pytest.raises(InputError, match="ridge_tail_flank_slope"):
        RenderParams(ridge_tail_flank_slope=0.01)
    with pytest.raises(InputError, match="ridge_tail_flank_slope"):
        RenderParams(ridge_tail_flank_slope=float("nan"))


def test_ridge_tail_spacing_keeps_the_gentle_tails_to_peaks_that_stand_alone():
    """``ridge_tail_spacing_m``: ``ridge_tail_flank_slope``'s gentle cones apply only to the tails of pieces whose
    peak lies, on average, at least that far from its 4 nearest other peaks. The lone volcano (its hills 11 km out)
    keeps its gentle tails; a copy of the tree with a crowd of summits 1.2 km around the volcano (a range) keeps the
    cut but its tails keep the flank slope's cones: the ground beside them falls as without the option. Prominences
    stay the tree's."""
    from orokit.raster.skeleton import lone_pieces
    from orokit.topology.divide_tree import DivideTree
    from orokit.validate.crest import crest_sections

    lone = _volcano_tree()
    p = lone.peaks[["x", "y", "elevation"]].to_numpy()
    np.testing.assert_array_equal(lone_pieces(p[:1], p, 3000.0), [True])
    ang = np.arange(6) * np.pi / 3.0
    crowd = np.column_stack([15000.0 + 1200.0 * np.cos(ang), 15000.0 + 1200.0 * np.sin(ang), np.full(6, 4700.0)])
    cs_ = np.column_stack([15000.0 + 600.0 * np.cos(ang), 15000.0 + 600.0 * np.sin(ang), np.full(6, 4600.0)])
    s = lone.saddles[["x", "y", "elevation"]].to_numpy()
    e = lone.edges[["peak_a", "peak_b", "saddle"]].to_numpy()
    ranged = DivideTree.from_arrays(np.concatenate([p, crowd]), np.concatenate([s, cs_]),
                                    np.concatenate([e, np.column_stack([np.zeros(6, int), 7 + np.arange(6),
                                                                        6 + np.arange(6)])]), attrs=lone.attrs)
    pr = ranged.peaks[["x", "y", "elevation"]].to_numpy()
    assert not lone_pieces(pr[:1], pr, 3000.0)[0]
    kw = dict(lam=200.0, ridge_max_slope=1.0, ridge_plateau_spread=None, flank_slope_relief_m=None,
              ridge_tail_flank_slope=0.05)
    drops = {}
    for label, tree in (("lone", lone), ("ranged", ranged)):
        for spacing in (None, 3000.0):
            z = render_elevation(tree, cell_size_m=100.0, erosion=False, rng=5,
                                 params=RenderParams(**kw, ridge_tail_spacing_m=spacing))
            cs = crest_sections(z.values, (0.0, 30000.0, 100.0), np.repeat(p[:1, :2], 6, axis=0), s[:, :2],
                                offsets_m=(400.0,), skip_peak_m=2500.0, skip_saddle_m=1000.0)
            drops[label, spacing] = float(cs.median()[0])
            assert_keeps_tree(tree, z, distance_tol_m=200.0, atol=1.0)
    # lone 17.9 m either way; ranged 18.1 m with every tail gentle, 67.5 m with the spacing (its tails' 0.6 cones)
    assert drops["lone", 3000.0] == pytest.approx(drops["lone", None], abs=1e-6)  # the lone volcano: still cut
    assert drops["ranged", None] < 25.0 and drops["ranged", 3000.0] > 2.0 * drops["ranged", None]
    with pytest.raises(InputError, match="ridge_tail_spacing_m"):
        RenderParams(ridge_tail_spacing_m=float("nan"))


def test_ridge_tail_defaults_lay_the_lone_volcanos_tails_into_the_plateau():
    """The defaults (session 20): ``ridge_tail_flank_slope`` 0.1 on the tails of pieces whose peak stands alone
    (``ridge_tail_spacing_m`` 3000). The lone volcano's six crests pass the default spread cut; with the defaults the
    ground 400 m beside their tails falls no faster than the tails' 0.1 cones (34 m), with the option off at the
    flank slope (64 m). Peaks and prominences stay the tree's."""
    from orokit.validate.crest import crest_sections

    assert (RenderParams().ridge_tail_spacing_m, RenderParams().ridge_tail_flank_slope) == (3000.0, 0.1)
    tree = _volcano_tree()
    p = tree.peaks[["x", "y"]].to_numpy()
    drops = {}
    for label, kw in (("defaults", {}), ("off", {"ridge_tail_flank_slope": None})):
        z = render_elevation(tree, cell_size_m=100.0, erosion=False, rng=5, params=RenderParams(lam=200.0, **kw))
        cs = crest_sections(z.values, (0.0, 30000.0, 100.0), np.repeat(p[:1], 6, axis=0),
                            tree.saddles[["x", "y"]].to_numpy(), offsets_m=(400.0,), skip_peak_m=2500.0,
                            skip_saddle_m=1000.0)
        assert cs.drop.shape[0] >= 6 * 25
        drops[label] = float(cs.median()[0])
        assert_keeps_tree(tree, z, distance_tol_m=200.0, atol=1.0)
    assert drops["off"] > 50.0 and drops["defaults"] <= 0.1 * 400.0 + 1.0 and drops["defaults"] < 0.6 * drops["off"]
