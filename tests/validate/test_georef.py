"""Georeferenced twins: `synthesize --like DEM` lands on the DEM's grid; `--center LON,LAT`."""
from __future__ import annotations

import numpy as np
import rasterio
from click.testing import CliRunner
from pyproj import CRS, Geod, Transformer
from rasterio.transform import from_origin

from orokit.cli.main import cli


def _utm_dem(path):
    """20 x 15 km at 100 m in UTM 33N, north-west corner at (612 300, 5 123 400)."""
    z = (np.add.outer(np.linspace(0, 400, 150), np.linspace(0, 300, 200)) + 800).astype("float32")
    with rasterio.open(path, "w", driver="GTiff", width=200, height=150, count=1, dtype="float32", crs="EPSG:32633",
                       transform=from_origin(612_300, 5_123_400, 100, 100)) as ds:
        ds.write(z, 1)
        ds.update_tags(1, units="m")
    return path


def test_twin_of_a_georeferenced_dem_carries_its_crs_and_transform(small_type_file, tmp_path):
    dem = _utm_dem(tmp_path / "real.tif")
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(small_type_file), "--like", str(dem), "--seed", "2",
                                 "--no-erosion", "--no-progress", "-o", str(tmp_path / "twin")])
    assert r.exit_code == 0, r.output
    with rasterio.open(dem) as a, rasterio.open(tmp_path / "twin" / "dem.tif") as b:
        assert b.crs == a.crs
        assert (b.width, b.height) == (a.width, a.height)
        assert tuple(b.transform)[:6] == tuple(a.transform)[:6]
    import geopandas as gpd

    peaks = gpd.read_file(tmp_path / "twin" / "dividetree.gpkg", layer="peaks")
    assert CRS.from_user_input(peaks.crs) == CRS.from_epsg(32633)
    assert peaks.geometry.x.between(612_300, 632_300).all() and peaks.geometry.y.between(5_108_400, 5_123_400).all()
    # a local frame only when asked for
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(small_type_file), "--like", str(dem), "--seed", "2",
                                 "--crs", "local", "--no-erosion", "--no-progress", "-o", str(tmp_path / "local")])
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "local" / "dem.tif") as b:
        assert b.crs is None and b.transform.c == 0.0


def test_center_places_the_domain_centre_within_one_cell(small_type_file, tmp_path):
    lon, lat = 86.925, 27.988
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(small_type_file), "--size", "20km", "--resolution", "100m",
                                 "--center", f"{lon},{lat}", "--seed", "1", "--no-erosion", "--no-progress",
                                 "-o", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "c" / "dem.tif") as b:
        assert b.crs is not None and "Azimuthal" in CRS.from_user_input(b.crs).to_wkt().replace("_", " ").title()
        cx, cy = b.transform * (b.width / 2, b.height / 2)
        clon, clat = Transformer.from_crs(b.crs, "EPSG:4326", always_xy=True).transform(cx, cy)
        res = b.transform.a
    assert Geod(ellps="WGS84").inv(lon, lat, clon, clat)[2] <= res
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(small_type_file), "--size", "20km", "--center", "86.9",
                                 "--no-progress", "-o", str(tmp_path / "bad")])
    assert r.exit_code != 0 and "--center" in r.output
