"""The tree's own floor under river beds and samples (``RenderParams.saddle_floor_ratio``)."""
from __future__ import annotations

import numpy as np
import pytest

import orokit
from orokit.errors import InputError
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation
from orokit.raster.rivers import ridge_segments, river_network, saddle_floor
from orokit.validate.roundtrip import compare_peaks

from helpers.trees import small_tree


def _random_nodes(seed: int, n_peaks: int = 40, n_saddles: int = 30):
    rng = np.random.default_rng(seed)
    peaks = np.column_stack([rng.uniform(0, 10_000, (n_peaks, 2)), rng.uniform(500, 900, n_peaks)])
    saddles = np.column_stack([rng.uniform(0, 10_000, (n_saddles, 2)), rng.uniform(300, 500, n_saddles)])
    return peaks, saddles, rng.uniform(0, 10_000, (200, 2))


@pytest.mark.parametrize("k", [1, 5, 16])
def test_saddle_floor_against_brute_force(k):
    """The k nearest saddles and peaks by a full distance matrix give the same floor."""
    peaks, saddles, q = _random_nodes(1)
    ds = np.hypot(*(q[:, None, :] - saddles[None, :, :2]).transpose(2, 0, 1))
    dp = np.hypot(*(q[:, None, :] - peaks[None, :, :2]).transpose(2, 0, 1))
    s = np.take_along_axis(np.broadcast_to(saddles[:, 2], ds.shape), np.argsort(ds, axis=1)[:, :k], 1).min(1)
    p = np.take_along_axis(np.broadcast_to(peaks[:, 2], dp.shape), np.argsort(dp, axis=1)[:, :k], 1).max(1)
    for ratio in (0.0, 0.3, 1.0):
        np.testing.assert_allclose(saddle_floor(q, peaks, saddles, ratio=ratio, k=k), s - ratio * (p - s))


def test_saddle_floor_lies_below_the_nearby_saddles_and_falls_with_the_ratio():
    peaks, saddles, q = _random_nodes(2)
    f0 = saddle_floor(q, peaks, saddles, ratio=0.0, k=8)
    f1 = saddle_floor(q, peaks, saddles, ratio=0.5, k=8)
    assert (f1 < f0).all()  # every peak is above every saddle here
    near = np.argmin(np.hypot(*(q[:, None, :] - saddles[None, :, :2]).transpose(2, 0, 1)), axis=1)
    assert (f0 <= saddles[near, 2]).all()
    # k covering every node: one floor everywhere
    every = saddle_floor(q, peaks, saddles, ratio=0.5, k=1000)
    np.testing.assert_allclose(every, saddles[:, 2].min() - 0.5 * (peaks[:, 2].max() - saddles[:, 2].min()))
    # a tree without saddles sets no floor
    assert np.isneginf(saddle_floor(q, peaks, saddles[:0], ratio=0.5)).all()


def _chain(saddle_z: float = 700.0):
    rng = np.random.default_rng(3)
    peaks = np.column_stack([rng.uniform(1000, 19000, (12, 2)), rng.uniform(800, 1200, 12)])
    saddles = np.column_stack([(peaks[:-1, :2] + peaks[1:, :2]) / 2, np.full(11, saddle_z)])
    edges = np.column_stack([np.arange(11), np.arange(1, 12), np.arange(11)])
    return ridge_segments(peaks, saddles, edges), np.concatenate([peaks[:, :2], saddles[:, :2]])


def test_river_floor_raises_beds_to_it_and_nothing_else():
    """A floor under the saddles: every bed (outlets too) lies on or above it, above the cap if need be,
    never lower than without it, on the same network; no floor gives the same beds as before."""
    ridges, nodes = _chain()
    ext = (0, 0, 20000, 20000)
    kw = dict(base_elevation=0.0, margin_m=5.0, slope=0.05, cap=lambda xy: np.full(xy.shape[0], 650.0))
    free = river_network(ridges, nodes, ext, **kw)
    none = river_network(ridges, nodes, ext, floor=None, **kw)
    held = river_network(ridges, nodes, ext, floor=lambda xy: np.full(xy.shape[0], 660.0), **kw)
    assert np.array_equal(free.elevation, none.elevation)
    assert np.array_equal(free.receiver, held.receiver)
    assert (free.elevation < 600.0).any()  # the sweep pinned beds far below the saddles
    assert (held.elevation >= free.elevation - 1e-9).all()
    assert (held.elevation >= 660.0 - 1e-9).all()  # above the cap (650): a floor below the saddles
    # a floor above the saddles: beds facing a ridge stay margin_m below where they cross it (>= 700 m)
    high = river_network(ridges, nodes, ext, floor=lambda xy: np.full(xy.shape[0], 2000.0), **kw)
    assert (high.elevation < 1200.0).any() and (high.elevation >= held.elevation - 1e-9).all()


def test_render_with_the_floor_keeps_the_orometry_and_lifts_the_valleys():
    """The small tree rendered with a tight floor: every peak recovered, none extra, peaks and saddles
    exact; the skeleton's beds sit on or above the floor (the default ratio is 1)."""
    assert RenderParams().saddle_floor_ratio == 1.0
    tree = small_tree()
    params = RenderParams(lam=200.0, saddle_floor_ratio=0.0)
    dem, skel = render_elevation(tree, cell_size_m=50.0, erosion=False, params=params, return_skeleton=True, rng=7)
    plain = render_elevation(tree, cell_size_m=50.0, erosion=False, params=RenderParams(lam=200.0,
                             saddle_floor_ratio=None), rng=7)
    peaks = tree.peaks[["x", "y", "elevation"]].to_numpy(float)
    saddles = tree.saddles[["x", "y", "elevation"]].to_numpy(float)
    rv = skel.river_network
    f = saddle_floor(rv.xy, peaks, saddles, ratio=0.0)  # 900 m: the lowest saddle
    assert (rv.elevation >= np.minimum(f, 900.0 - 5.0) - 1e-6).all()  # crossings bound beds at >= 900 - margin
    # the plain render's beds sink to the outlets' 870 m; floored, the lowest ground is near 900 m
    assert np.quantile(dem.values, 0.05) > np.quantile(plain.values, 0.05) + 10.0
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0
    z = dem.values
    for frame in (tree.peaks, tree.saddles):
        col = np.floor(frame["x"].to_numpy() / 50.0).astype(int)
        row = np.floor((8000.0 - frame["y"].to_numpy()) / 50.0).astype(int)
        np.testing.assert_allclose(z[row, col], frame["elevation"].to_numpy(), atol=0.01)


def test_saddle_floor_ratio_follows_the_local_relief():
    """With ``relief_m`` the ratio is ``max(min_ratio, ratio x min(1, R / relief_m))`` of the brute-force
    relief ``R = p - s``: the full ratio where R reaches relief_m, min_ratio where R is small, between
    the two never above the constant-ratio floor's depth nor below min_ratio's."""
    peaks, saddles, q = _random_nodes(4)
    k = 8
    s0 = saddle_floor(q, peaks, saddles, ratio=0.0, k=k)
    r = saddle_floor(q, peaks, saddles, ratio=-1.0, k=k) - s0  # p - s
    assert (r > 0).all()
    for relief_m, lo in ((float(np.median(r)), 0.5), (1e9, 0.25), (1.0, 0.0)):
        got = saddle_floor(q, peaks, saddles, ratio=1.0, k=k, relief_m=relief_m, min_ratio=lo)
        np.testing.assert_allclose(got, s0 - np.maximum(lo, np.minimum(r / relief_m, 1.0)) * r)
        assert (got >= saddle_floor(q, peaks, saddles, ratio=1.0, k=k) - 1e-9).all()
        assert (got <= saddle_floor(q, peaks, saddles, ratio=lo, k=k) + 1e-9).all()
    # relief_m small: every point reaches the full ratio; a min_ratio above the ratio is capped at it
    np.testing.assert_allclose(saddle_floor(q, peaks, saddles, ratio=0.3, k=k, relief_m=1.0, min_ratio=0.9),
                               saddle_floor(q, peaks, saddles, ratio=0.3, k=k))
    with pytest.raises(ValueError, match="relief_m"):
        saddle_floor(q, peaks, saddles, ratio=1.0, relief_m=0.0)
    with pytest.raises(InputError, match="saddle_floor_relief_m"):
        RenderParams(saddle_floor_relief_m=-5.0)


def test_render_with_a_relief_following_floor_keeps_the_orometry():
    """The small tree (relief ~300 m) with the floor's ratio scaled by its relief: its beds lie on or
    above the constant-ratio floor and on or above the relief-scaled floor (ridge crossings aside); every
    peak recovered, none extra."""
    tree = small_tree()
    kw = dict(lam=200.0, saddle_floor_ratio=1.0)
    params = RenderParams(**kw, saddle_floor_relief_m=2000.0, saddle_floor_min_ratio=0.1)
    dem, skel = render_elevation(tree, cell_size_m=50.0, erosion=False, params=params, return_skeleton=True, rng=7)
    peaks = tree.peaks[["x", "y", "elevation"]].to_numpy(float)
    saddles = tree.saddles[["x", "y", "elevation"]].to_numpy(float)
    rv = skel.river_network
    f = saddle_floor(rv.xy, peaks, saddles, ratio=1.0, relief_m=2000.0, min_ratio=0.1)
    assert (f > saddle_floor(rv.xy, peaks, saddles, ratio=1.0) + 1.0).all()  # a shallower floor everywhere
    assert (rv.elevation >= np.minimum(f, 900.0 - 5.0) - 1e-6).all()
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0


@pytest.mark.parametrize("k", [1, 5, 16])
def test_saddle_floor_spread_against_brute_force(k):
    """With ``spread_ratio`` the floor's depth below the lowest of the k nearest saddles is at most
    ``spread_ratio`` x (their median - their lowest), by a full distance matrix; 0 puts the floor at that
    lowest saddle, a large ratio leaves the floor as it was."""
    peaks, saddles, q = _random_nodes(5)
    ds = np.hypot(*(q[:, None, :] - saddles[None, :, :2]).transpose(2, 0, 1))
    near = np.take_along_axis(np.broadcast_to(saddles[:, 2], ds.shape), np.argsort(ds, axis=1)[:, :k], 1)
    s, spread = near.min(1), np.median(near, 1) - near.min(1)
    for ratio, relief_m, lo in ((1.0, None, 0.0), (1.0, 300.0, 0.5), (0.3, None, 0.0)):
        plain = saddle_floor(q, peaks, saddles, ratio=ratio, k=k, relief_m=relief_m, min_ratio=lo)
        for c in (0.0, 1.0, 3.0):
            got = saddle_floor(q, peaks, saddles, ratio=ratio, k=k, relief_m=relief_m, min_ratio=lo, spread_ratio=c)
            np.testing.assert_allclose(got, s - np.minimum(s - plain, c * spread))
            assert (got >= plain - 1e-9).all() and (got <= s + 1e-9).all()
        if k > 1:  # one saddle has no spread: the floor sits at it
            np.testing.assert_allclose(saddle_floor(q, peaks, saddles, ratio=ratio, k=k, relief_m=relief_m,
                                                    min_ratio=lo, spread_ratio=1e9), plain)
    if k > 2:
        assert (spread > 0).any()  # the test can fail: the bound binds somewhere
        assert (saddle_floor(q, peaks, saddles, ratio=1.0, k=k, spread_ratio=1.0)
                > saddle_floor(q, peaks, saddles, ratio=1.0, k=k) + 1.0).any()
    with pytest.raises(ValueError, match="spread_ratio"):
        saddle_floor(q, peaks, saddles, ratio=1.0, spread_ratio=-1.0)
    with pytest.raises(InputError, match="saddle_floor_spread"):
        RenderParams(saddle_floor_spread=-1.0)


def test_render_with_a_spread_bounded_floor_keeps_the_orometry():
    """The small tree with the floor bounded by its saddles' spread: the beds lie on or above that floor
    (ridge crossings aside), which is never below the plain floor; every peak recovered, none extra."""
    assert RenderParams().saddle_floor_spread is None
    tree = small_tree()
    params = RenderParams(lam=200.0, saddle_floor_ratio=1.0, saddle_floor_spread=0.5)
    dem, skel = render_elevation(tree, cell_size_m=50.0, erosion=False, params=params, return_skeleton=True, rng=7)
    peaks = tree.peaks[["x", "y", "elevation"]].to_numpy(float)
    saddles = tree.saddles[["x", "y", "elevation"]].to_numpy(float)
    rv = skel.river_network
    f = saddle_floor(rv.xy, peaks, saddles, ratio=1.0, spread_ratio=0.5)
    assert (f >= saddle_floor(rv.xy, peaks, saddles, ratio=1.0) - 1e-9).all()
    assert (rv.elevation >= np.minimum(f, 900.0 - 5.0) - 1e-6).all()
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0


@pytest.mark.parametrize("k", [5, 16])
def test_saddle_floor_level_against_brute_force(k):
    """With ``level_ratio`` L0 the floor's depth below the lowest of the k nearest saddles is the plain depth times
    ``min(1, (L / L0)^2)``, ``L`` = (their median - their lowest) / (highest of the k nearest peaks - that lowest),
    by a full distance matrix: shallower where the saddles lie at one level, unchanged where L >= L0."""
    peaks, saddles, q = _random_nodes(9)
    ds = np.hypot(*(q[:, None, :] - saddles[None, :, :2]).transpose(2, 0, 1))
    dp = np.hypot(*(q[:, None, :] - peaks[None, :, :2]).transpose(2, 0, 1))
    near = np.take_along_axis(np.broadcast_to(saddles[:, 2], ds.shape), np.argsort(ds, axis=1)[:, :k], 1)
    p = np.take_along_axis(np.broadcast_to(peaks[:, 2], dp.shape), np.argsort(dp, axis=1)[:, :k], 1).max(1)
    s = near.min(1)
    level = (np.median(near, 1) - s) / (p - s)
    for ratio, relief_m, lo in ((1.0, None, 0.0), (1.0, 800.0, 0.5)):
        plain = saddle_floor(q, peaks, saddles, ratio=ratio, k=k, relief_m=relief_m, min_ratio=lo)
        for l0 in (0.05, 0.2, 1.0):
            got = saddle_floor(q, peaks, saddles, ratio=ratio, k=k, relief_m=relief_m, min_ratio=lo, level_ratio=l0)
            np.testing.assert_allclose(got, s - (s - plain) * np.minimum(level / l0, 1.0) ** 2)
            assert (got >= plain - 1e-9).all() and (got <= s + 1e-9).all()
        # the test can fail: at L0 = the median L the factor binds at some points and not at others
        l0 = float(np.median(level))
        assert ((level < l0) & (level > 0)).any() and (level >= l0).any()
        got = saddle_floor(q, peaks, saddles, ratio=ratio, k=k, relief_m=relief_m, min_ratio=lo, level_ratio=l0)
        assert (got > plain + 1.0).any() and np.allclose(got[level >= l0], plain[level >= l0])
    with pytest.raises(ValueError, match="level_ratio"):
        saddle_floor(q, peaks, saddles, ratio=1.0, level_ratio=0.0)
    with pytest.raises(InputError, match="saddle_floor_level"):
        RenderParams(saddle_floor_level=-0.1)


def test_render_with_a_level_bounded_floor_keeps_the_orometry():
    """The small tree with the floor shrunk by the saddles' levelness: the beds lie on or above that floor
    (ridge crossings aside), which is never below the plain floor; every peak recovered, none extra."""
    assert RenderParams().saddle_floor_level == 0.3
    tree = small_tree()
    params = RenderParams(lam=200.0, saddle_floor_ratio=1.0, saddle_floor_level=0.5)
    dem, skel = render_elevation(tree, cell_size_m=50.0, erosion=False, params=params, return_skeleton=True, rng=7)
    peaks = tree.peaks[["x", "y", "elevation"]].to_numpy(float)
    saddles = tree.saddles[["x", "y", "elevation"]].to_numpy(float)
    rv = skel.river_network
    f = saddle_floor(rv.xy, peaks, saddles, ratio=1.0, level_ratio=0.5)
    assert (f >= saddle_floor(rv.xy, peaks, saddles, ratio=1.0) - 1e-9).all()
    assert (rv.elevation >= np.minimum(f, 900.0 - 5.0) - 1e-6).all()
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    comp = compare_peaks(tree, res.peaks, min_prominence_m=30.0, distance_tol_m=100.0)
    assert comp.recovered_share == 1.0 and len(comp.extra) == 0
