"""Concave trunk profiles (issue 11, session 20: ``river_concavity``, off by default): the rendered trunks fell at
``river_slope`` (0.01) from far away, so every tributary cut a deep gorge to reach them; with the option the beds
follow Flint's law ``S = k_s min(1, A_c / A)^theta`` from each outlet to its basin's heads."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from orokit.errors import InputError
from orokit.raster.params import RenderParams
from orokit.raster.render import render_elevation
from orokit.raster.rivers import concave_lift
from orokit.raster.skeleton import build_skeleton
from orokit.topology.divide_tree import DivideTree

from helpers.trees import assert_keeps_small_tree, small_tree


@pytest.mark.parametrize("seed", range(4))
def test_concave_lift_follows_flints_law(seed):
    """Random forests (receivers numbered before their donors): every edge of the profile rises by ``k_s
    min(1, A_c / A)^theta x length`` with one ``k_s`` per outlet's tree, the median of its heads' ``(top - outlet
    bed) / chi`` (chi summed edge by edge here, independently of the kernel)."""
    rng = np.random.default_rng(seed)
    n, theta, ac = 400, 0.45, 1.0e6
    receiver = np.array([-1 if v == 0 or rng.random() < 0.03 else int(rng.integers(0, v)) for v in range(n)])
    length = np.where(receiver >= 0, rng.uniform(50.0, 300.0, n), 0.0)
    area = rng.uniform(1.0e4, 4.0e6, n)
    for v in range(n - 1, 0, -1):  # donors before receivers: an area that grows downstream
        if receiver[v] >= 0:
            area[receiver[v]] += area[v]
    top = rng.uniform(500.0, 3000.0, n)
    bed = rng.uniform(0.0, 200.0, n)
    got = concave_lift(receiver, length, area, top, bed, concavity=theta, area_m2=ac)
    outlet = np.arange(n)
    chi = np.zeros(n)
    for v in range(n):
        if receiver[v] >= 0:
            outlet[v] = outlet[receiver[v]]
            chi[v] = chi[receiver[v]] + length[v] * min(1.0, ac / area[v]) ** theta
    head = np.ones(n, bool)
    head[receiver[receiver >= 0]] = False
    for o in np.flatnonzero(receiver < 0):
        members = outlet == o
        heads = members & head & (chi > 0)
        if not heads.any():
            assert np.isneginf(got[members]).all()
            continue
        ks = max(float(np.median((top[heads] - bed[o]) / chi[heads])), 0.0)
        np.testing.assert_allclose(got[members], bed[o] + ks * chi[members], rtol=1e-12, atol=1e-9)
    with pytest.raises(ValueError, match="concavity"):
        concave_lift(receiver, length, area, top, bed, concavity=float("nan"))


def _valley_tree() -> DivideTree:
    """Two parallel ridges 3 km apart (10 peaks each, rising 220 m per peak upstream, east), joined at the head of
    the valley between them by a saddle east of their last peaks: one trunk drains the valley to the west."""
    xs = np.arange(1000.0, 20000.0, 2000.0)
    z = 2000.0 + 220.0 * np.arange(xs.size)
    bump = 60.0 * (np.arange(xs.size) % 2)
    peaks = np.concatenate([np.column_stack([xs, np.full(xs.size, 6500.0), z + bump]),
                            np.column_stack([xs, np.full(xs.size, 3500.0), z + 60.0 - bump])])
    n = xs.size
    saddles, edges = [], []
    for side in (0, n):
        for i in range(n - 1):
            a, b = side + i, side + i + 1
            saddles.append([0.5 * (peaks[a, 0] + peaks[b, 0]), peaks[a, 1], min(peaks[a, 2], peaks[b, 2]) - 200.0])
            edges.append([a, b, len(saddles) - 1])
    saddles.append([20500.0, 5000.0, z[-1] - 300.0])
    edges.append([n - 1, 2 * n - 1, len(saddles) - 1])
    return DivideTree.from_arrays(peaks, np.array(saddles), np.array(edges),
                                  attrs={"extent": [0.0, 0.0, 22000.0, 10000.0]})


def _slope_by_area(**kw) -> tuple[dict[tuple[float, float], float], object]:
    """Median edge slope (m/m) of the valley tree's river network per band of drainage area (km^2; each node
    drains its share of a 50 m grid), and the network."""
    extent = (0.0, 0.0, 22000.0, 10000.0)
    net = build_skeleton(_valley_tree(), extent=extent, params=RenderParams(lam=200.0, **kw), rng=3).river_network
    has = net.receiver >= 0
    slope = (net.elevation[has] - net.elevation[net.receiver[has]]) / net.length[has]
    grid = np.mgrid[25.0:22000.0:50.0, 25.0:10000.0:50.0].reshape(2, -1).T
    _, near = cKDTree(net.xy).query(grid)
    area = net.drainage_area(np.bincount(near, minlength=net.n_nodes) * 2500.0)[has] / 1.0e6
    bands = ((0.3, 1.0), (1.0, 3.0), (3.0, 10.0))
    return {b: float(np.median(slope[(area >= b[0]) & (area < b[1])])) for b in bands}, net


def test_trunk_slopes_fall_with_drainage_area():
    """The valley's network: plain, the trunk (3-10 km2) falls at ``river_slope`` (0.01) and the reaches above it
    barely more; with ``river_concavity`` 0.45 the median slope falls band by band with the drainage area and the
    trunk falls at several times ``river_slope``; the same receivers, beds that still fall downstream."""
    assert RenderParams().river_concavity is None
    plain, pnet = _slope_by_area()
    assert plain[(3.0, 10.0)] == pytest.approx(0.01, abs=1e-6)
    got, net = _slope_by_area(river_concavity=0.45)
    np.testing.assert_array_equal(net.receiver, pnet.receiver)
    has = net.receiver >= 0
    assert (net.elevation[has] >= net.elevation[net.receiver[has]] - 1e-9).all()
    assert got[(0.3, 1.0)] > got[(1.0, 3.0)] > got[(3.0, 10.0)] >= 4.0 * 0.01
    assert got[(1.0, 3.0)] > 3.0 * plain[(1.0, 3.0)]


def test_render_with_concave_trunks_keeps_the_orometry():
    """The small tree rendered with ``river_concavity`` 0.45 and the ratio 1: every peak recovered within 100 m,
    none extra, the hand-written prominences kept."""
    dem = render_elevation(small_tree(), cell_size_m=50.0, erosion=False,
                           params=RenderParams(lam=200.0, river_concavity=0.45, river_bed_slope_ratio=1.0), rng=7)
    assert_keeps_small_tree(dem)


@pytest.mark.parametrize("field, bad", [("river_concavity", -0.1), ("river_concavity", float("nan")),
                                        ("river_concave_area_m2", 0.0), ("river_concave_wall_slope", 0.0)])
def test_concave_parameters_refuse_bad_values(field, bad):
    with pytest.raises(InputError, match=field):
        RenderParams(**{field: bad})
