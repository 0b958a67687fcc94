"""Isolation of ``orokit.analyze`` against an exhaustive nearest-higher-cell scan.

Isolation is the distance from the peak cell to the nearest strictly higher valid
cell (cell centres, Euclidean with the cell sizes for projected grids). It is exact
only when that cell is closer than the nearest cell outside the data (just beyond the
raster, or NaN); NaN (and not exact) when no higher cell exists.
"""
from __future__ import annotations

import numpy as np
import pytest
from helpers.orometry_oracles import brute_isolation, grids, make_dem
from hypothesis import given, settings
from hypothesis import strategies as st

import orokit


def check_isolation(z: np.ndarray, dx: float, dy: float) -> None:
    dem = make_dem(z, res=(dx, dy))
    peaks = orokit.analyze(dem, min_prominence_m=0.0, isolation=True).peaks
    zz = z.astype(np.float64)
    for _, p in peaks.iterrows():
        r, c = int(p["row"]), int(p["col"])
        iso, edge, exact = brute_isolation(zz, r, c, dx, dy)
        if np.isnan(iso):
            assert np.isnan(p["isolation"]), f"peak {r, c} has no higher cell in\n{z!r}"
            assert not p["isolation_exact"]
            assert int(p["isolation_row"]) == -1
            continue
        assert p["isolation"] == pytest.approx(iso, rel=1e-9), f"isolation of {r, c} in\n{z!r} (dx={dx}, dy={dy})"
        ir, ic = int(p["isolation_row"]), int(p["isolation_col"])
        assert zz[ir, ic] > zz[r, c], "isolation target is not strictly higher"
        assert np.hypot((ir - r) * dy, (ic - c) * dx) == pytest.approx(iso, rel=1e-9)
        assert p["isolation_x"] == pytest.approx(dem.x.values[ic])
        assert p["isolation_y"] == pytest.approx(dem.y.values[ir])
        if abs(iso - edge) > 1e-9 * max(iso, 1.0):  # a tie with the edge may go either way
            assert bool(p["isolation_exact"]) == exact, f"isolation_exact of {r, c} in\n{z!r} (dx={dx}, dy={dy})"


@settings(max_examples=150, deadline=None)
@given(z=grids(12), res=st.sampled_from([(10.0, 10.0), (10.0, 25.0), (30.0, 7.5), (92.61, 92.61)]))
def test_isolation_matches_scan(z, res):
    check_isolation(z, *res)


def test_isolation_simple_cases():
    z = np.zeros((7, 9), np.float32)
    z[3, 2], z[3, 7] = 5, 9     # 5 m peak, higher 9 m peak 5 columns east
    z[0, 2] = 4                  # lower, nearer: irrelevant
    peaks = orokit.analyze(make_dem(z, res=(20.0, 20.0)), min_prominence_m=0).peaks.set_index(["row", "col"])
    assert peaks.loc[(3, 2), "isolation"] == pytest.approx(100.0)
    assert not peaks.loc[(3, 2), "isolation_exact"]   # the west edge is 60 m away
    assert np.isnan(peaks.loc[(3, 7), "isolation"])
    z = np.zeros((21, 21), np.float32)
    z[10, 10], z[10, 12] = 5, 9
    peaks = orokit.analyze(make_dem(z, res=(20.0, 20.0)), min_prominence_m=0).peaks.set_index(["row", "col"])
    assert peaks.loc[(10, 10), "isolation"] == pytest.approx(40.0)
    assert peaks.loc[(10, 10), "isolation_exact"]


def _bumps(lon, lat, centres):
    """Sum of Gaussian bumps (metres) on lon/lat; width in metres via a local scale."""
    z = np.zeros_like(lon, dtype=np.float64)
    kx = 111320.0 * np.cos(np.radians(46.0))
    for clon, clat, h, s in centres:
        d2 = ((lon - clon) * kx) ** 2 + ((lat - clat) * 110950.0) ** 2
        z += h * np.exp(-d2 / (2 * s * s))
    return z


def test_isolation_geographic_vs_projected():
    """The same terrain on an EPSG:4326 grid and a UTM grid: isolations agree within cells."""
    from pyproj import Transformer

    centres = [(10.030, 46.030, 900.0, 900.0), (10.075, 46.040, 600.0, 700.0),
               (10.050, 46.075, 750.0, 800.0), (10.020, 46.090, 400.0, 500.0)]
    step = 3.0 / 3600.0  # 3 arc-seconds: ~64 m E-W by ~93 m N-S at 46 N
    n = 132
    lon0, lat_top = 10.0, 46.11
    glon = lon0 + step * (np.arange(n) + 0.5)
    glat = lat_top - step * (np.arange(n) + 0.5)
    LON, LAT = np.meshgrid(glon, glat)
    geo = make_dem(_bumps(LON, LAT, centres).astype(np.float32), res=(step, step), crs="EPSG:4326",
                   x0=lon0, y0=lat_top)
    to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True)
    to_geo = Transformer.from_crs("EPSG:32632", "EPSG:4326", always_xy=True)
    west, north = to_utm.transform(lon0, lat_top)
    cell = 60.0
    mx, my = int(8400 // cell), int(12100 // cell)  # inside the geographic extent (8.5 x 12.2 km)
    ux = west + cell * (np.arange(mx) + 0.5)
    uy = north - cell * (np.arange(my) + 0.5)
    UX, UY = np.meshgrid(ux, uy)
    ulon, ulat = to_geo.transform(UX, UY)
    utm = make_dem(_bumps(ulon, ulat, centres).astype(np.float32), res=(cell, cell), crs="EPSG:32632",
                   x0=west, y0=north)
    pg = orokit.analyze(geo, min_prominence_m=100.0).peaks
    pu = orokit.analyze(utm, min_prominence_m=100.0).peaks
    assert len(pg) == len(pu) == 4
    gx, gy = to_utm.transform(pg["x"].to_numpy(), pg["y"].to_numpy())
    tol = np.hypot(64.0, 93.0) + np.hypot(cell, cell)  # one cell diagonal of each grid
    for i in range(len(pg)):
        d = np.hypot(pu["x"].to_numpy() - gx[i], pu["y"].to_numpy() - gy[i])
        j = int(np.argmin(d))
        assert d[j] < tol, "the same summit should be found on both grids"
        a, b = pg["isolation"].iloc[i], pu["isolation"].iloc[j]
        if np.isnan(a) or np.isnan(b):
            assert np.isnan(a) and np.isnan(b)
            continue
        assert a == pytest.approx(b, abs=tol), f"isolation geographic {a:.1f} m vs projected {b:.1f} m"
        assert pg["lon"].iloc[i] == pytest.approx(pg["x"].iloc[i])


@pytest.mark.parametrize("chunks", [None, 8])
def test_isolation_in_metres_on_a_foot_based_crs(chunks):
    """EPSG:2227 counts in US survey feet: a grid of 30 ft cells there and one of the same
    cells in metres (EPSG:32633) give the same isolation in metres, in memory and by chunks."""
    rng = np.random.default_rng(3)
    z = rng.integers(0, 40, size=(19, 23)).astype(np.float32)
    ft = 1200.0 / 3937.0
    feet = orokit.analyze(make_dem(z, res=(30.0, 30.0), crs="EPSG:2227", x0=6_000_000.0, y0=2_000_000.0),
                          min_prominence_m=0, isolation=True, chunks=chunks).peaks
    metres = orokit.analyze(make_dem(z, res=(30.0 * ft, 30.0 * ft)), min_prominence_m=0, isolation=True,
                            chunks=chunks).peaks
    key = ["row", "col"]
    a, b = feet.set_index(key).sort_index(), metres.set_index(key).sort_index()
    assert a.index.equals(b.index) and len(a) > 5
    np.testing.assert_allclose(a["isolation"], b["isolation"], rtol=1e-9)
    finite = a["isolation"].dropna()
    assert finite.min() >= 30.0 * ft * (1 - 1e-9)  # metres, not feet: a neighbour is 9.14 m away
    np.testing.assert_array_equal(a["isolation_row"], b["isolation_row"])


def test_prebuilt_search_pyramid_gives_the_same_search():
    """``orokit analyze`` builds the pyramid beside the tree's finalize: the search is the same; a raster
    with NaN gets None (the search then builds its NaN-free copy itself)."""
    from affine import Affine

    from orokit.metrics.isolation import KernelMetric, nearest_higher, search_pyramid

    z = np.random.default_rng(5).random((40, 33)).astype(np.float32)
    rows, cols = np.array([0, 7, 39, 20], np.int64), np.array([0, 12, 32, 5], np.int64)
    metric = KernelMetric.from_grid(Affine(30.0, 0, 0, 0, -20.0, 0), None)
    pyramid = search_pyramid(z)
    assert pyramid is not None and pyramid[0] is z
    for a, b in zip(nearest_higher(z, rows, cols, metric, pyramid), nearest_higher(z, rows, cols, metric)):
        assert np.array_equal(a, b)
    z[3, 4] = np.nan
    assert search_pyramid(z) is None
