"""Distances (m) and directions (degrees CCW from east) between cells and points."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Geod, Transformer
from rasterio.transform import Affine

from orokit.geodesy import CellMetric, cell_distance, point_distance


def test_direction_conventions_projected():
    m = CellMetric(Affine(30, 0, 500000, 0, -30, 4000000), "EPSG:32633")
    r, c = 10, 10
    # east, north (row - 1), west, south (row + 1), north-east
    np.testing.assert_allclose(m.direction(r, c, [r, r - 1, r, r + 1, r - 1], [c + 1, c, c - 1, c, c + 1]),
                               [0, 90, 180, 270, 45])
    assert np.isnan(m.direction(r, c, r, c)) and m.distance(r, c, r, c) == 0
    np.testing.assert_allclose(m.distance(0, 0, [3, 0], [4, 2]), [150.0, 60.0])


def test_local_grid_and_feet_crs():
    local = CellMetric(Affine(92.61, 0, 0, 0, -92.61, 0), None)
    assert not local.is_geographic and local.distance(0, 0, 0, 10) == pytest.approx(926.1)
    # a state plane in US survey feet: CRS units are converted to metres
    ft = CellMetric(Affine(10, 0, 6000000, 0, -10, 2000000), "EPSG:2227")
    assert ft.unit_m == pytest.approx(1200 / 3937)
    assert ft.distance(0, 0, 0, 1) == pytest.approx(10 * 1200 / 3937)
    assert np.isnan(local.lonlat(1.0, 2.0)[0])


def test_geographic_matches_projected_after_reprojection():
    # two points ~14 km apart near the UTM 32N central meridian (9 E), 46 N
    lon0, lat0, lon1, lat1 = 9.01, 46.00, 9.11, 46.10
    to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True)
    (x0, x1), (y0, y1) = to_utm.transform([lon0, lon1], [lat0, lat1])
    d_geo, a_geo = point_distance(lon0, lat0, lon1, lat1, crs="EPSG:4326")
    d_utm, a_utm = point_distance(x0, y0, x1, y1, crs="EPSG:32632")
    # UTM scale factor near the central meridian is 0.9996: agree to 0.1 %
    assert d_geo == pytest.approx(d_utm, rel=1e-3)
    assert float(a_geo) == pytest.approx(float(a_utm), abs=0.2)  # grid convergence ~0.001 deg here
    _, _, d_ref = Geod(ellps="WGS84").inv(lon0, lat0, lon1, lat1)
    assert d_geo == pytest.approx(d_ref, rel=1e-12)


def test_geographic_cells_are_not_square():
    m = CellMetric(Affine(1 / 1200, 0, 10.0, 0, -1 / 1200, 60.0), "EPSG:4326")
    dx, dy = m.cell_size_m([0])
    assert dy[0] == pytest.approx(92.6, abs=0.3)
    assert dx[0] == pytest.approx(dy[0] * np.cos(np.radians(60.0)), rel=5e-3)
    # north/east directions on the ellipsoid
    assert m.direction(5, 5, 4, 5) == pytest.approx(90.0, abs=1e-9)
    assert m.direction(5, 5, 5, 6) == pytest.approx(0.0, abs=0.05)


def test_cell_distance_on_dem(make_dem):
    dem = make_dem(np.zeros((5, 5)), res=30.0)
    d, a = cell_distance(dem, 4, 0, 0, 4)
    assert d == pytest.approx(np.hypot(120, 120)) and a == pytest.approx(45.0)
    geo = make_dem(np.zeros((5, 5)), res=1 / 1200, crs="EPSG:4326")
    d2, _ = cell_distance(geo, 0, 0, 0, 4)
    assert d2 < 4 * 92.7 and d2 > 4 * 60  # ~64 m per cell east-west at 46 N


def test_lonlat_projected():
    m = CellMetric(Affine(30, 0, 500000, 0, -30, 0), "EPSG:32633")
    lon, lat = m.lonlat(*m.xy(0, 0))
    assert lon == pytest.approx(15.0, abs=1e-3) and lat == pytest.approx(0.0, abs=1e-3)


@settings(max_examples=50, deadline=None)
@given(st.integers(-50, 50), st.integers(-50, 50), st.integers(-50, 50), st.integers(-50, 50))
def test_property_symmetry_and_opposite_directions(r0, c0, r1, c1):
    m = CellMetric(Affine(25, 0, 0, 0, -25, 0), "EPSG:32633")
    d01, a01 = m.distance_direction(r0, c0, r1, c1)
    d10, a10 = m.distance_direction(r1, c1, r0, c0)
    assert d01 == pytest.approx(d10)
    if d01 > 0:
        assert 0 <= a01 < 360 and (a10 - a01) % 360 == pytest.approx(180.0)
