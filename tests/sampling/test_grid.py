"""Grid of an analysis and its area on the ground (orokit.sampling.grid)."""
from __future__ import annotations

import numpy as np
import pytest
from affine import Affine
from pyproj import Geod

from orokit.errors import InputError
from orokit.sampling.grid import analysis_grid, grid_area_km2, row_cell_area_m2


@pytest.mark.parametrize("lat", [0.0, 46.0, -70.0, 89.5])
def test_lonlat_cell_area_matches_geodesic_polygon(lat):
    t = Affine(0.01, 0.0, 10.0, 0.0, -0.01, lat + 0.01)
    ours = row_cell_area_m2(t, 1)[0]
    ref, _ = Geod(ellps="WGS84").polygon_area_perimeter([10, 10.01, 10.01, 10], [lat + 0.01, lat + 0.01, lat, lat])
    assert ours == pytest.approx(abs(ref), rel=1e-6)


def test_grid_area_in_every_kind_of_crs():
    assert grid_area_km2(Affine(30, 0, 0, 0, -30, 0), None, (100, 200)) == pytest.approx(18.0)
    assert grid_area_km2(Affine(30, 0, 5e5, 0, -30, 4e6), "EPSG:32633", (100, 200)) == pytest.approx(18.0)
    # US survey feet: 100 ft cells
    ft = grid_area_km2(Affine(100, 0, 0, 0, -100, 0), "EPSG:2249", (10, 10))
    assert ft == pytest.approx(100 * (100 * 1200 / 3937) ** 2 / 1e6, rel=1e-6)
    # lon/lat: the whole sphere band, and a valid mask counts only its cells
    whole = grid_area_km2(Affine(1, 0, -180, 0, -1, 90), "EPSG:4326", (180, 360))
    assert whole == pytest.approx(510_065_622, rel=1e-6)  # WGS84 ellipsoid surface, km2
    valid = np.zeros((180, 360), bool)
    valid[:90] = True
    assert grid_area_km2(Affine(1, 0, -180, 0, -1, 90), "EPSG:4326", (180, 360), valid) == pytest.approx(whole / 2)


def test_analysis_grid_reads_the_recorded_transform_and_old_folders():
    t, crs, shape = analysis_grid({"shape": [4, 5], "transform": [0.001, 0, 10, 0, -0.001, 46], "crs": "EPSG:4326"})
    assert tuple(t)[:6] == (0.001, 0, 10, 0, -0.001, 46) and crs.is_geographic and shape == (4, 5)
    # folders written before the transform was recorded: a local grid from its cell size
    t, crs, _ = analysis_grid({"shape": [4, 5], "local_grid": True, "cell_size_m": [92.61, 92.61]})
    assert tuple(t)[:6] == (92.61, 0, 0, 0, -92.61, 0) and crs is None
    # ... and before the key was named with its unit (``cell_size``)
    t, crs, _ = analysis_grid({"shape": [4, 5], "local_grid": True, "cell_size": [92.61, 78.0]})
    assert tuple(t)[:6] == (92.61, 0, 0, 0, -78.0, 0) and crs is None
    with pytest.raises(InputError, match="shape"):
        analysis_grid({"transform": [1, 0, 0, 0, -1, 0]})
    with pytest.raises(InputError, match="re-run"):
        analysis_grid({"shape": [4, 5], "crs": "EPSG:32633"})
