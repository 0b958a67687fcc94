"""Terrain (raster) features of disks against analytic surfaces; a terrain set without a DEM is refused."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from orokit.classify.terrain import disk_terrain_vector, terrain_fields, terrain_matrix
from orokit.errors import InputError
from orokit.sampling.feature_sets import TERRAIN_COLUMNS, FeatureSet

RES, N = 100.0, 121


def _dem(z: np.ndarray):
    import rioxarray  # noqa: F401
    import xarray as xr
    from rasterio.transform import Affine

    ny, nx = z.shape
    da = xr.DataArray(z.astype(np.float64), dims=("y", "x"),
                      coords={"y": 4e6 - (np.arange(ny) + 0.5) * RES, "x": 5e5 + (np.arange(nx) + 0.5) * RES})
    return da.rio.write_crs("EPSG:32633").rio.write_transform(Affine(RES, 0, 5e5, 0, -RES, 4e6))


def _centre(z: np.ndarray, radius_m: float = 2500.0) -> dict[str, float]:
    v = disk_terrain_vector(terrain_fields(_dem(z)), N // 2, N // 2, radius_m)
    assert v.shape == (len(TERRAIN_COLUMNS),) and np.isfinite(v).all()
    return dict(zip(TERRAIN_COLUMNS, v))


def test_inclined_plane():
    a = 0.2  # 20 % grade towards the east
    z = 1000.0 + a * RES * np.arange(N)[None, :] * np.ones((N, 1))
    f = _centre(z)
    for q in (10, 25, 50, 75, 90):
        assert f[f"q{q}_slope_deg"] == pytest.approx(np.degrees(np.arctan(a)))
    assert f["flat_share"] == 0.0
    # 1 km windows are 11 cells: relief a x 10 cells x 100 m; disk cells are > 5 windows from the edge
    assert f["q50_relief_1km_km"] == pytest.approx(a * 10 * RES / 1000.0)
    assert f["q25_relief_1km_km"] == pytest.approx(f["q90_relief_1km_km"])
    assert f["iqr_curvature_per_km"] == pytest.approx(0.0, abs=1e-9)
    assert f["hypsometric_integral"] == pytest.approx(0.5, abs=1e-9)  # a disk is symmetric about its centre
    assert f["q50_hypsometry"] == pytest.approx(0.5, abs=1e-9)


def test_bowl_curvature_and_drainage():
    c = 1e-4  # z = c r^2: Laplacian 4c per metre, exact for the 5-point stencil on a quadratic
    yy, xx = (np.mgrid[0:N, 0:N] - N // 2) * RES
    bowl = _centre(500.0 + c * (xx**2 + yy**2))
    assert bowl["q10_curvature_per_km"] == pytest.approx(4 * c * 1000.0)
    assert bowl["q90_curvature_per_km"] == pytest.approx(4 * c * 1000.0)
    dome = _centre(2000.0 - c * (xx**2 + yy**2))
    assert dome["q10_curvature_per_km"] == pytest.approx(-4 * c * 1000.0)
    # a dome sheds water outwards in thin lines: few cells drain > 1 km2 near its top; a bowl routed to the
    # border through its flooded centre collects everything in its middle
    assert dome["drainage_share"] < bowl["drainage_share"]
    assert dome["hypsometric_integral"] > 0.5 > bowl["hypsometric_integral"]


def test_rougher_terrain_has_more_relief_and_a_flatter_spectrum():
    rng = np.random.default_rng(0)
    smooth = np.cumsum(np.cumsum(rng.normal(size=(N, N)), 0), 1)  # red noise: steep spectrum
    rough = smooth + 40.0 * rng.normal(size=(N, N))  # white noise on top: flatter spectrum, more local relief
    a, b = _centre(smooth, 5000.0), _centre(rough, 5000.0)
    assert b["spectral_slope"] < a["spectral_slope"]
    assert b["q50_relief_1km_km"] > a["q50_relief_1km_km"]


def test_terrain_matrix_places_disks_by_coordinates():
    yy, xx = np.mgrid[0:N, 0:N] * RES
    z = 100.0 + 0.05 * xx + 1e-5 * yy**2  # slope grows towards the south
    dem = _dem(z)
    t = dem.rio.transform()
    xs, ys = zip(*(t * (N // 2 + 0.5, r + 0.5) for r in (30, 90)))
    m = terrain_matrix(dem, pd.DataFrame({"x": xs, "y": ys, "radius_m": [2500.0, 2500.0]}))
    k = TERRAIN_COLUMNS.index("q50_slope_deg")
    assert m.shape == (2, len(TERRAIN_COLUMNS)) and m[1, k] > m[0, k]
    fields = terrain_fields(dem)
    np.testing.assert_allclose(m[0], disk_terrain_vector(fields, 30, N // 2, 2500.0))


def test_terrain_feature_set_needs_a_dem():
    from orokit.classify.features import feature_table

    fs = FeatureSet.named("terrain")
    assert fs.terrain and fs.columns[-len(TERRAIN_COLUMNS):] == TERRAIN_COLUMNS
    assert FeatureSet.from_dict(fs.to_dict()) == fs and fs.to_dict()["terrain_cell_size_m"] == 90.0
    assert "terrain" not in FeatureSet.orometry().to_dict()  # files written before stay equal
    peaks = pd.DataFrame({"x": [0.0, 10.0], "y": [0.0, 5.0], "elevation": [900.0, 500.0],
                          "prominence": [900.0, 100.0]})
    disks = pd.DataFrame({"disk_id": [0], "x": [0.0], "y": [0.0], "radius_m": [1000.0]})
    with pytest.raises(InputError, match="needs the DEM.*--features orometry"):
        feature_table(peaks, disks, feature_set=fs, min_peaks=1)


def test_a_30m_dem_is_averaged_to_90m_before_the_terrain_features():
    """The same ground at 30 m and as its 3 x 3 block means at 90 m gives the same disk features."""
    import rioxarray  # noqa: F401
    import xarray as xr
    from rasterio.transform import Affine

    from orokit.classify.terrain import coarsen_dem

    def dem(z, res):
        ny, nx = z.shape
        da = xr.DataArray(z, dims=("y", "x"), coords={"y": 4e6 - (np.arange(ny) + 0.5) * res,
                                                     "x": 5e5 + (np.arange(nx) + 0.5) * res})
        return da.rio.write_crs("EPSG:32633").rio.write_transform(Affine(res, 0, 5e5, 0, -res, 4e6))

    rng = np.random.default_rng(1)
    z30 = np.cumsum(np.cumsum(rng.normal(size=(363, 363)), 0), 1) + 3.0 * rng.normal(size=(363, 363))
    z90 = z30.reshape(121, 3, 121, 3).mean(axis=(1, 3))
    assert coarsen_dem(dem(z90, 90.0), 90.0) is not None
    fine30 = dem(z30, 30.0)
    fine30.attrs["cell_size_m"] = (30.0, 30.0)  # as read_dem sets it
    coarse = coarsen_dem(fine30, 90.0)
    np.testing.assert_allclose(coarse.values, z90)
    assert coarse.attrs["cell_size_m"] == (90.0, 90.0)  # the coarse cells' (was the input's 30 m)
    disks = pd.DataFrame({"x": [5e5 + 5400.0, 5e5 + 4000.0], "y": [4e6 - 5400.0, 4e6 - 6000.0],
                          "radius_m": [3000.0, 2500.0]})
    fine = terrain_matrix(dem(z30, 30.0), disks, cell_size_m=90.0)
    np.testing.assert_allclose(fine, terrain_matrix(dem(z90, 90.0), disks, cell_size_m=90.0), atol=1e-9)
    raw = terrain_matrix(dem(z30, 30.0), disks, cell_size_m=None)  # at 30 m the white noise makes it steeper
    k = TERRAIN_COLUMNS.index("q50_slope_deg")
    assert (raw[:, k] > fine[:, k] + 1.0).all()
