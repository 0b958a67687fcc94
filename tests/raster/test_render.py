"""Renderer: rivers, orometry of the raster, reproducibility, bad inputs."""
from __future__ import annotations

import json

import numpy as np
import pytest

import orokit
from orokit.errors import CRSError, DivideTreeError, InputError
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation
from orokit.raster.skeleton import build_skeleton
from orokit.topology.divide_tree import DivideTree
from orokit.validate.roundtrip import compare_peaks

from helpers.trees import assert_keeps_small_tree, small_tree

FAST = RenderParams(lam=200.0, erosion_steps=2)


@pytest.fixture(scope="module")
def rendered():
    tree = small_tree()
    dem, skel = render_elevation(tree, cell_size_m=50.0, erosion=False, params=FAST, return_skeleton=True, rng=7)
    return tree, dem, skel


def test_river_graph_is_forest_draining_to_outlets(rendered):
    _, _, skel = rendered
    rv = skel.river_network
    assert rv.n_nodes > 10
    # following receivers from every node ends at an outlet within n steps (no cycle)
    v = np.arange(rv.n_nodes)
    for _ in range(rv.n_nodes):
        nxt = rv.receiver[v]
        v = np.where(nxt >= 0, nxt, v)
    assert rv.outlet[v].all()
    assert (rv.receiver[rv.outlet] == -1).all()
    # beds never rise downstream
    has = rv.receiver >= 0
    assert (rv.elevation[rv.receiver[has]] <= rv.elevation[has] + 1e-9).all()


def test_no_river_crosses_a_ridge(rendered):
    import shapely

    _, _, skel = rendered
    rv = skel.river_network
    ed = rv.edges()
    assert len(ed) > 10
    rivers = shapely.linestrings(np.stack([rv.xy[ed[:, 0]], rv.xy[ed[:, 1]]], 1))
    # no river edge crosses a refined (jittered) ridge piece
    fine = skel.ridges
    fr = shapely.linestrings(np.stack([fine.xy[fine.segments[:, 0]], fine.xy[fine.segments[:, 1]]], 1))
    hits = shapely.STRtree(fr).query(rivers, predicate="crosses")
    assert hits.shape[1] == 0


def test_raster_honours_peaks_and_saddles(rendered):
    tree, dem, _ = rendered
    z = dem.values
    for frame in (tree.peaks, tree.saddles):
        col = np.floor(frame["x"].to_numpy() / 50.0).astype(int)
        row = np.floor((8000.0 - frame["y"].to_numpy()) / 50.0).astype(int)
        np.testing.assert_allclose(z[row, col], frame["elevation"].to_numpy(), atol=0.01)
    assert z.max() == pytest.approx(1500.0, abs=0.01)
    assert dem.attrs["units"] == "m" and dem.rio.transform().a == 50.0


def test_round_trip_recovers_every_peak(rendered):
    assert_keeps_small_tree(rendered[1])


def test_resolution_independence():
    tree = small_tree()
    proms = []
    for res in (100.0, 40.0):
        dem = render_elevation(tree, cell_size_m=res, erosion=False, params=FAST, rng=3)
        r = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
        comp = compare_peaks(tree, r.peaks, min_prominence_m=30.0, distance_tol_m=2 * res)
        assert comp.recovered_share == 1.0
        proms.append(comp.peaks["raster_prominence"].to_numpy())
    # consistent within eps / 3 (10 m): discretisation beside saddles grows with the cell
    np.testing.assert_allclose(proms[0], proms[1], atol=10.0)


def test_same_seed_same_raster_other_seed_differs():
    tree = small_tree()
    a = render_elevation(tree, cell_size_m=100.0, erosion=False, params=FAST, rng=11).values
    b = render_elevation(tree, cell_size_m=100.0, erosion=False, params=FAST, rng=11).values
    c = render_elevation(tree, cell_size_m=100.0, erosion=False, params=FAST, rng=12).values
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_erosion_keeps_peaks_and_saddles_and_lowers_valleys():
    tree = small_tree()
    plain = render_elevation(tree, cell_size_m=50.0, erosion=False, params=FAST, rng=5).values
    eroded = render_elevation(tree, cell_size_m=50.0, erosion=True, params=FAST, rng=5).values
    for frame in (tree.peaks, tree.saddles):
        col = np.floor(frame["x"].to_numpy() / 50.0).astype(int)
        row = np.floor((8000.0 - frame["y"].to_numpy()) / 50.0).astype(int)
        assert np.all(np.abs(eroded[row, col] - frame["elevation"].to_numpy()) <= 1.0)
    assert (eroded < plain - 1.0).sum() > 100  # erosion did something


def test_single_peak_and_collinear_trees_render():
    one = DivideTree.from_arrays([[1000.0, 1000.0, 500.0]], np.empty((0, 3)), np.empty((0, 3)),
                                 attrs={"extent": [0, 0, 2000, 2000]})
    dem = render_elevation(one, cell_size_m=50.0, erosion=False, params=FAST, rng=0)
    assert float(dem.max()) == pytest.approx(500.0, abs=0.01)
    line = DivideTree.from_arrays([[1000.0, 1000.0, 500.0], [2000.0, 1000.0, 450.0], [3000.0, 1000.0, 480.0]],
                                  [[1500.0, 1000.0, 400.0], [2500.0, 1000.0, 420.0]], [[0, 1, 0], [1, 2, 1]],
                                  attrs={"extent": [0, 0, 4000, 2000]})
    dem = render_elevation(line, cell_size_m=50.0, erosion=False, params=FAST, rng=0)
    r = orokit.analyze(dem, min_prominence_m=20.0, isolation=False)
    assert compare_peaks(line, r.peaks, min_prominence_m=20.0, distance_tol_m=100.0).recovered_share == 1.0


@pytest.mark.parametrize("res", [0.0, -30.0, float("nan"), float("inf")])
def test_bad_resolution(res):
    with pytest.raises(InputError, match="resolution"):
        render_elevation(small_tree(), cell_size_m=res, erosion=False)


def test_enormous_raster_refused_before_allocating():
    with pytest.raises(InputError, match="exceeds the limit"):
        render_elevation(small_tree(), cell_size_m=0.01, erosion=False)
    with pytest.raises(InputError, match="coarser than the extent"):
        render_elevation(small_tree(), cell_size_m=1e6, erosion=False)


def test_tree_outside_extent_and_bad_trees():
    with pytest.raises(InputError, match="no peak"):
        render_elevation(small_tree(), cell_size_m=100.0, extent=(1e6, 1e6, 1.01e6, 1.01e6), erosion=False)
    empty = DivideTree.from_arrays(np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)))
    with pytest.raises(DivideTreeError):
        render_elevation(empty, cell_size_m=100.0, extent=(0, 0, 1000, 1000), erosion=False)
    with pytest.raises(CRSError, match="geographic"):
        render_elevation(small_tree(crs="EPSG:4326"), cell_size_m=100.0, erosion=False)


def test_skeleton_tin_keeps_ridge_segments(rendered):
    tree, _, skel = rendered
    tin = skel.tin
    edges = {tuple(sorted(e)) for t in tin.triangles for e in ((t[0], t[1]), (t[1], t[2]), (t[0], t[2]))}
    from scipy.spatial import cKDTree

    # every refined ridge piece is an edge of the TIN (Triangle may split a piece, never drop it)
    kd = cKDTree(tin.xy)
    seg = skel.ridges.segments
    a = kd.query(skel.ridges.xy[seg[:, 0]])[1]
    b = kd.query(skel.ridges.xy[seg[:, 1]])[1]
    present = np.mean([tuple(sorted((i, j))) in edges for i, j in zip(a, b)])
    assert present > 0.95


def test_learned_profiles_shape_ridges_and_flanks():
    """With profiles="learned" a refined ridge follows the measured concave profile (not a
    straight line) and stays between its saddle and its peak; the linear default is the paper's."""
    import numpy as np

    from orokit.raster.profiles import hillslope_profile, ridge_profile
    from orokit.raster.refine import refine_segments

    xy = np.array([[0.0, 0.0], [1000.0, 0.0]])
    zz = np.array([800.0, 500.0])  # peak, saddle
    lin = refine_segments(xy, zz, np.array([[0, 1]]), lam=100.0, jitter=0.0, rng=0)
    con = refine_segments(xy, zz, np.array([[0, 1]]), lam=100.0, jitter=0.0, rng=0,
                          profile=lambda t: 1.0 - ridge_profile(t))
    t = lin.xy[2:, 0] / 1000.0
    assert np.allclose(lin.z[2:], 800.0 - 300.0 * t)
    assert np.allclose(con.z[2:], 500.0 + 300.0 * ridge_profile(t))
    mid = t >= 0.2  # rounded summit, then below the straight line: concave
    assert (con.z[2:][mid] < lin.z[2:][mid]).all() and (np.diff(con.z[2:]) <= 0).all()
    u = np.linspace(0, 1, 101)
    assert (np.diff(hillslope_profile(u)) >= 0).all() and hillslope_profile(u)[50] < 0.5
    assert RenderParams().profiles == "linear"
    with pytest.raises(Exception, match="profiles"):
        RenderParams(profiles="cubic")


def test_texture_adds_short_wavelength_relief_and_keeps_the_orometry():
    """A type's texture (RMS, spectral slope) is added back: the render gains short-wavelength
    relief measured by texture_spectrum (a measure the renderer does not steer), the peaks
    and prominences of the tree stay, and no extra peak >= eps appears."""
    from orokit.raster.noise import texture_spectrum

    tree = small_tree()
    plain = render_elevation(tree, cell_size_m=50.0, erosion=False, params=FAST, rng=3)
    rough = render_elevation(tree, cell_size_m=50.0, erosion=False, rng=3,
                             params=RenderParams(lam=200.0, erosion_steps=2, texture_rms_m=40.0, texture_beta=4.0,
                                                 texture_gain=1.0))
    r0, _ = texture_spectrum(plain.values, 50.0)
    r1, _ = texture_spectrum(rough.values, 50.0)
    assert r1 > r0 + 5.0
    assert json.loads(rough.attrs["parameters"])["texture_rms_m"] == 40.0
    assert_keeps_small_tree(rough)


def test_spectral_noise_follows_its_spectral_slope():
    from orokit.raster.noise import spectral_noise, texture_spectrum

    for beta in (3.0, 4.5):
        n = spectral_noise((512, 512), 30.0, rms=10.0, beta=beta, largest_m=4000.0, rng=5)
        rms, got = texture_spectrum(n, 30.0, largest_m=4000.0, fit_m=(150.0, 1000.0))
        assert got == pytest.approx(beta, abs=0.4)
        assert rms == pytest.approx(10.0, rel=0.25)


def test_texture_from_relief_and_kept_hills_keep_the_orometry():
    """texture_relief_ratio gives a tree-only render a texture scaled by its own relief
    (recorded), keep_hill_ratio / cut_slope / trench_slope leave low hills and graded cuts:
    the tree's peaks and prominences stay, no extra peak >= eps appears."""
    from orokit.raster.noise import texture_spectrum
    from orokit.raster.render import _median_relief

    tree = small_tree()
    # straight crests (the texture's weight follows the skeleton's slope; the bounded crests' gentle tails take
    # less of it, and this spectral check is calibrated on straight ones)
    plain = render_elevation(tree, cell_size_m=50.0, erosion=False,
                             params=RenderParams(lam=200.0, erosion_steps=2, ridge_max_slope=None), rng=3)
    params = RenderParams(lam=200.0, erosion_steps=2, texture_relief_ratio=0.2, texture_gain=1.0,
                          keep_hill_ratio=0.5, cut_slope=0.1, trench_slope=0.1, flank_max_slope=0.5,
                          ridge_max_slope=None)
    rough = render_elevation(tree, cell_size_m=50.0, erosion=False, params=params, rng=3)
    used = json.loads(rough.attrs["parameters"])["texture_rms_used_m"]
    assert json.loads(plain.attrs["parameters"])["texture_rms_used_m"] == 0.0
    assert used > 5.0
    assert texture_spectrum(rough.values, 50.0)[0] > texture_spectrum(plain.values, 50.0)[0] + 0.3 * used
    assert_keeps_small_tree(rough)
    z = np.arange(60.0).reshape(6, 10)  # 2 x 2-cell blocks at 1 m: ptp of each block is 11
    assert _median_relief(z, 1.0, 2.0) == 11.0


def test_flank_envelope_with_more_neighbours_approaches_the_full_envelope():
    """The cone envelope over k nearest ridge points is a lower bound of the envelope over all of
    them (brute force), and equals it when k covers every point (RenderParams.flank_neighbours)."""
    from orokit.raster.interpolate import flank_envelope

    rng = np.random.default_rng(0)
    q = rng.uniform(0, 10_000, (200, 2))
    z = rng.uniform(1000, 3000, 200)
    s = rng.uniform(0.1, 1.0, 200)
    p = rng.uniform(0, 10_000, (500, 2))
    full = np.max(z[None, :] - s[None, :] * np.hypot(*(p[:, None, :] - q[None, :, :]).transpose(2, 0, 1)), axis=1)
    e16 = flank_envelope(p, q, z, s, k_neighbours=16)
    e64 = flank_envelope(p, q, z, s, k_neighbours=64)
    assert (e16 <= e64 + 1e-9).all() and (e64 <= full + 1e-9).all() and (e16 < full - 1.0).any()
    np.testing.assert_allclose(flank_envelope(p, q, z, s, k_neighbours=200), full)


def _chain_of_ridges(peak_z: tuple[float, float], saddle_z: float):
    """12 random peaks on a 20 km square joined in a chain by 11 ridges of one saddle height:
    ``(ridges, nodes)`` for :func:`orokit.raster.rivers.river_network`."""
    from orokit.raster.rivers import ridge_segments

    rng = np.random.default_rng(3)
    peaks = np.column_stack([rng.uniform(1000, 19000, (12, 2)), rng.uniform(*peak_z, 12)])
    saddles = np.column_stack([(peaks[:-1, :2] + peaks[1:, :2]) / 2, np.full(11, saddle_z)])
    edges = np.column_stack([np.arange(11), np.arange(1, 12), np.arange(11)])
    return ridge_segments(peaks, saddles, edges), np.concatenate([peaks[:, :2], saddles[:, :2]])


def test_river_max_sink_keeps_beds_near_their_bound():
    """Without a limit the downstream sweep pulls beds far below the bound the cap sets; with
    ``max_sink_m`` every bed stays within it, never lower than without, on the same network."""
    from orokit.raster.rivers import river_network

    ridges, nodes = _chain_of_ridges((800, 1200), 700.0)

    def cap(xy):
        return np.full(xy.shape[0], 650.0)

    kw = dict(base_elevation=0.0, margin_m=5.0, slope=0.05, cap=cap)
    free = river_network(ridges, nodes, (0, 0, 20000, 20000), **kw)
    held = river_network(ridges, nodes, (0, 0, 20000, 20000), max_sink_m=20.0, **kw)
    assert np.array_equal(free.receiver, held.receiver)
    inner = ~held.outlet
    assert (held.elevation >= free.elevation - 1e-9).all()
    assert (held.elevation[inner] >= 645.0 - 20.0 - 1e-9).all()  # the bound is at most cap - margin
    assert (free.elevation[inner] < 600.0).any()  # the sweep pinned some beds far below it


def test_limit_slope_fills_cliff_feet_only():
    """A cliff becomes a talus of the critical slope; cells are only raised, a gentler plane is
    unchanged, and no new maximum appears (the tree's peaks stay the only ones)."""
    from scipy import ndimage

    from orokit.raster.hillslope import limit_slope

    res = 30.0
    yy, xx = np.mgrid[0:60, 0:80] * res
    plane = 0.2 * xx + 0.1 * yy  # ~12.6 deg
    assert np.array_equal(limit_slope(plane, res, 45.0), plane)
    z = np.where(xx > 1200.0, 500.0, 0.0) + plane
    z[30, 60] += 300.0  # a pinnacle: one maximum
    out = limit_slope(z, res, 45.0)
    assert (out >= z).all()
    t = np.tan(np.radians(45.0)) * res
    assert (np.abs(np.diff(out, axis=1)) <= t + 1e-9).all() and (np.abs(np.diff(out, axis=0)) <= t + 1e-9).all()
    assert (np.abs(out[1:, 1:] - out[:-1, :-1]) <= t * np.sqrt(2) + 1e-9).all()
    assert out[30, 60] == z[30, 60]  # the summit keeps its height
    # local maxima (>= all 8 neighbours): only the pinnacle and the cliff top's far corner
    fp = np.ones((3, 3), bool)
    fp[1, 1] = False
    neigh = ndimage.maximum_filter(out, footprint=fp, mode="constant", cval=-np.inf)
    assert np.argwhere(out > neigh).tolist() == np.argwhere(z > ndimage.maximum_filter(
        z, footprint=fp, mode="constant", cval=-np.inf)).tolist()
    with pytest.raises(InputError):
        RenderParams(max_slope_deg=95.0)


def test_river_relief_ratio_deepens_beds_below_steep_ridges_only():
    """``relief_ratio``: the minimum bed slope follows the gradient from the nearest ridge; beds
    are never higher than with the plain slope, 0 gives the same beds, beds still fall downstream,
    and under a flat-topped (gentle) ridge set nothing changes."""
    from orokit.raster.rivers import river_network

    ridges, nodes = _chain_of_ridges((1800, 2200), 1500.0)
    kw = dict(base_elevation=0.0, margin_m=5.0, slope=0.01)
    ext = (0, 0, 20000, 20000)
    plain = river_network(ridges, nodes, ext, **kw)
    same = river_network(ridges, nodes, ext, relief_ratio=0.0, **kw)
    steep = river_network(ridges, nodes, ext, relief_ratio=0.5, **kw)
    assert np.array_equal(plain.elevation, same.elevation)
    assert np.array_equal(plain.receiver, steep.receiver)
    assert (steep.elevation <= plain.elevation + 1e-9).all()
    assert (steep.elevation < plain.elevation - 50.0).any()
    has = steep.receiver >= 0
    assert (steep.elevation[steep.receiver[has]] <= steep.elevation[has] + 1e-9).all()
    # level ridges (no gradient down to any bed's bound): nothing changes
    low, _ = _chain_of_ridges((1500.0, 1500.0), 1500.0)  # the same positions, level
    a = river_network(low, nodes, ext, **kw)
    b = river_network(low, nodes, ext, relief_ratio=0.5, **kw)
    np.testing.assert_allclose(a.elevation, b.elevation)


def test_valley_width_narrows_on_steep_beds():
    """Floor width: A^0.4 on beds at the reference slope (default the minimum), S^-p narrower on steeper ones."""
    from orokit.raster.interpolate import valley_width

    area = np.full(5, 4e6)
    s = np.array([0.001, 0.01, 0.04, 0.16, 1.0])
    plain = valley_width(area, coef=0.15)
    w = valley_width(area, coef=0.15, bed_slope=s, min_bed_slope=0.01, slope_exponent=0.5)
    np.testing.assert_allclose(plain, 0.15 * 4e6 ** 0.4)
    np.testing.assert_allclose(w, plain * np.array([1.0, 1.0, 0.5, 0.25, 0.1]))
    np.testing.assert_array_equal(valley_width(area, bed_slope=s), valley_width(area))
    # a reference slope above the minimum: gentler beds get wider floors (S^-p both ways)
    wr = valley_width(area, coef=0.15, bed_slope=s, min_bed_slope=0.01, slope_exponent=0.5, ref_bed_slope=0.04)
    np.testing.assert_allclose(wr, plain * np.array([2.0, 2.0, 1.0, 0.5, 0.2]))


def test_floor_relief_ratio_keeps_valley_sides_steep():
    """Where the flank cone has fallen below it, the ground rises from the river at
    ``floor_relief_ratio`` x the ridge-to-river gradient (a hand-computed case), not at 0.05."""
    from orokit.raster.interpolate import sample_elevation

    ridge_xy = np.array([[0.0, 0.0]])
    river_xy = np.array([[1000.0, 0.0]])
    p = np.array([[500.0, 0.0], [800.0, 0.0]])
    kw = dict(ridge_slope=np.array([2.0]), floor_slope=0.05)  # a steep cone: 1000 - 2 d
    h0, _, _ = sample_elevation(p, ridge_xy, np.array([1000.0]), river_xy, np.array([0.0]), np.array([0.0]), **kw)
    # cone at 500 m: 0; at 800 m: -600 -> the floor 0.05 x (d to river) wins: 25 and 10
    np.testing.assert_allclose(h0, [25.0, 10.0])
    h1, _, _ = sample_elevation(p, ridge_xy, np.array([1000.0]), river_xy, np.array([0.0]), np.array([0.0]),
                                floor_relief_ratio=0.5, **kw)
    # gradient (1000 - 0) / 1000 = 1, half of it: 0.5 x 500 = 250 and 0.5 x 200 = 100
    np.testing.assert_allclose(h1, [250.0, 100.0])
    h2, _, _ = sample_elevation(p, ridge_xy, np.array([1000.0]), river_xy, np.array([0.0]), np.array([0.0]),
                                floor_relief_ratio=2.0, **kw)
    np.testing.assert_allclose(h2, [500.0, 200.0])  # never above the linear profile


def test_river_sink_relief_ratio_keeps_beds_near_low_ridges():
    """``sink_relief_ratio``: a bed sinks below its bound at most that many times the height of its
    nearest ridge point above the bound; beds are never lower than after the plain sweep, a huge
    ratio changes nothing, and where the ridges are no higher than the bound the beds stay on it."""
    from orokit.raster.rivers import river_network

    ridges, nodes = _chain_of_ridges((800, 1200), 700.0)

    def cap(xy):
        return np.full(xy.shape[0], 650.0)

    kw = dict(base_elevation=0.0, margin_m=5.0, slope=0.05, cap=cap)
    ext = (0, 0, 20000, 20000)
    plain = river_network(ridges, nodes, ext, **kw)
    held = river_network(ridges, nodes, ext, sink_relief_ratio=0.1, **kw)
    loose = river_network(ridges, nodes, ext, sink_relief_ratio=1e6, **kw)
    assert np.array_equal(plain.receiver, held.receiver)
    assert (held.elevation >= plain.elevation - 1e-9).all()
    assert (held.elevation > plain.elevation + 1.0).any()
    np.testing.assert_allclose(loose.elevation, plain.elevation)
    # ridges at the cap's height: no relief above any bound, so every inner bed stays at cap - margin
    level, _ = _chain_of_ridges((650.0, 650.0), 650.0)  # the same positions
    flat = river_network(level, nodes, ext, sink_relief_ratio=0.5, **kw)
    inner = ~flat.outlet
    np.testing.assert_allclose(flat.elevation[inner], 645.0)


def _limit_slope_brute(z, res, deg):
    """The talus fill by plain relaxation to the fixed point (the reference for the sweeps)."""
    out = z.copy()
    s = np.tan(np.radians(deg)) * res
    ny, nx = out.shape
    while True:
        changed = False
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                if dr or dc:
                    dst = (slice(max(dr, 0), ny + min(dr, 0)), slice(max(dc, 0), nx + min(dc, 0)))
                    src = (slice(max(-dr, 0), ny + min(-dr, 0)), slice(max(-dc, 0), nx + min(-dc, 0)))
                    low = out[src] - s * np.hypot(dr, dc)
                    m = low > out[dst]
                    if m.any():
                        out[dst][m] = low[m]
                        changed = True
        if not changed:
            return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_limit_slope_sweeps_equal_relaxation(seed):
    """The raster sweeps give the relaxation's fixed point (brute force) on rough random grids
    with spikes and pits, float64 to 1e-9 m and float32 to 1 cm (rounding along the paths)."""
    from orokit.raster.hillslope import limit_slope

    rng = np.random.default_rng(seed)
    z = rng.normal(0.0, 30.0, (37, 53)).cumsum(axis=1)
    z[rng.integers(0, 37, 20), rng.integers(0, 53, 20)] += rng.uniform(200, 2000, 20)
    for deg in (20.0, 45.0, 70.0):
        ref = _limit_slope_brute(z, 30.0, deg)
        np.testing.assert_allclose(limit_slope(z, 30.0, deg), ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(limit_slope(z.astype(np.float32), 30.0, deg), ref, rtol=0, atol=1e-2)


def test_threshold_profile_gradient_and_monotone():
    """``threshold_profile``: 0 at the river, 1 at the ridge, gradient 1 + c at the river and 1 - c
    at the crest (finite differences), monotone for c in [0, 1], linear for c = 0; c > 1 refused."""
    from orokit.raster.profiles import threshold_profile

    u = np.linspace(0.0, 1.0, 2001)
    for c in (0.0, 0.3, 1.0):
        f = threshold_profile(u, c)
        assert f[0] == 0.0 and abs(f[-1] - 1.0) < 1e-12
        assert (np.diff(f) >= -1e-15).all()
        g = np.gradient(f, u)
        assert abs(g[1] - (1 + c)) < 1e-3 and abs(g[-2] - (1 - c)) < 1e-3
    np.testing.assert_allclose(threshold_profile(u, 0.0), u)
    with pytest.raises(ValueError, match="convexity"):
        threshold_profile(u, 1.5)


def test_tree_gradient_matches_brute_force():
    """With k covering every node, the steepest drop to the tree's nodes equals the brute force;
    with fewer neighbours it is a lower bound."""
    from orokit.raster.skeleton import tree_gradient

    rng = np.random.default_rng(5)
    nodes = np.column_stack([rng.uniform(0, 10_000, (40, 2)), rng.uniform(0, 2000, 40)])
    p = rng.uniform(0, 10_000, (300, 2))
    z = rng.uniform(0, 2500, 300)
    d = np.hypot(*(p[:, None, :] - nodes[None, :, :2]).transpose(2, 0, 1))
    full = np.max(np.maximum(z[:, None] - nodes[None, :, 2], 0.0) / np.maximum(d, 200.0), axis=1)
    np.testing.assert_allclose(tree_gradient(p, z, nodes, k=40, min_distance_m=200.0), full)
    assert (tree_gradient(p, z, nodes, k=8, min_distance_m=200.0) <= full + 1e-12).all()
