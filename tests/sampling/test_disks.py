from __future__ import annotations

import numpy as np
import pytest
import shapely
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Geod
from scipy.spatial.distance import pdist

from orokit.errors import InputError
from orokit.sampling.disks import sample_disks_in_mask, sample_disks_in_polygon


@settings(max_examples=12, deadline=None)
@given(w=st.floats(5_000, 80_000), h=st.floats(5_000, 80_000), r=st.floats(2_000, 20_000),
       seed=st.integers(0, 2**16), max_disks=st.integers(1, 100))
def test_polygon_invariants(w, h, r, seed, max_disks):
    poly = shapely.Polygon([(0, 0), (w, 0), (w, h), (0.3 * w, 0.6 * h), (0, h)])  # non-convex
    d = sample_disks_in_polygon(poly, radius_m=r, max_disks=max_disks, rng=seed)
    xy = d[["x", "y"]].to_numpy()
    assert len(d) <= max_disks
    if len(d) > 1:
        assert pdist(xy).min() >= 0.5 * r * (1 - 1e-9)
    for x, y in xy:  # whole disk inside the polygon
        assert poly.buffer(1e-6 * r).contains(shapely.Point(x, y).buffer(r * 0.999, 32))
    d2 = sample_disks_in_polygon(poly, radius_m=r, max_disks=max_disks, rng=seed)
    assert np.array_equal(xy, d2[["x", "y"]].to_numpy())


def test_region_smaller_than_disk_gives_no_disk():
    d = sample_disks_in_polygon(shapely.box(0, 0, 5000, 5000), radius_m=3000, rng=1)
    assert len(d) == 0 and list(d.columns[:4]) == ["disk_id", "x", "y", "radius_m"]


def test_max_100_and_coverage():
    d = sample_disks_in_polygon(shapely.box(0, 0, 400_000, 400_000), radius_m=10_000, rng=3)
    assert len(d) == 100
    # a random subset of a space-filling sample: spread over the region, not clumped
    assert d["x"].std() > 80_000 and d["y"].std() > 80_000


def test_geographic_polygon_geodesic():
    poly = shapely.box(10.0, 45.0, 12.0, 46.5)  # lon/lat
    d = sample_disks_in_polygon(poly, radius_m=20_000, crs="EPSG:4326", rng=5)
    assert len(d) > 3
    g = Geod(ellps="WGS84")
    lon, lat = d["x"].to_numpy(), d["y"].to_numpy()
    for i in range(len(d)):
        _, _, dist = g.inv(np.full(len(d) - 1, lon[i]), np.full(len(d) - 1, lat[i]),
                           np.delete(lon, i), np.delete(lat, i))
        assert dist.min() >= 0.5 * 20_000 * 0.995
        ex, ey, _ = g.fwd(np.full(36, lon[i]), np.full(36, lat[i]), np.arange(0, 360, 10), np.full(36, 19_900.0))
        assert shapely.contains_xy(poly, ex, ey).all()


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**16), r_cells=st.floats(4.0, 12.0), hole=st.booleans())
def test_mask_disks_inside_valid(seed, r_cells, hole):
    cell = 30.0
    valid = np.ones((60, 80), dtype=bool)
    if hole:
        valid[20:35, 30:50] = False
    tr = Affine(cell, 0, 1000.0, 0, -cell, 5000.0)
    r = r_cells * cell
    d = sample_disks_in_mask(valid, transform=tr, radius_m=r, rng=seed)
    rows, cols = np.mgrid[0:60, 0:80]
    cx, cy = tr.c + tr.a * (cols + 0.5), tr.f + tr.e * (rows + 0.5)
    x0, y1 = tr.c, tr.f
    x1, y0 = tr.c + 80 * tr.a, tr.f + 60 * tr.e
    for x, y in d[["x", "y"]].to_numpy():
        near = np.hypot(cx - x, cy - y) <= r + 0.5 * cell * np.sqrt(2)
        assert valid[near].all()
        assert x - r >= x0 and x + r <= x1 and y - r >= y0 and y + r <= y1
    if len(d) > 1:
        assert pdist(d[["x", "y"]].to_numpy()).min() >= 0.5 * r - 1e-9


def test_mask_too_small_and_bad_args():
    assert len(sample_disks_in_mask(np.ones((10, 10), bool), transform=Affine(30, 0, 0, 0, -30, 0),
                                    radius_m=1000, rng=0)) == 0
    with pytest.raises(InputError):
        sample_disks_in_mask(np.ones((10, 10), bool), transform=Affine(30, 0, 0, 0, -30, 0), radius_m=-1)
    with pytest.raises(InputError):
        sample_disks_in_polygon(shapely.box(0, 0, 1, 1), radius_m=10, separation=0)
