"""Georeferenced twins: `synthesize --like DEM` lands on the DEM's grid; `--center LON,LAT`."""
from __future__ import annotations

import numpy as np
import pytest
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


def _located_type_file(small_type_file, tmp_path, center=(86.925, 27.988)):
    """The small type with a recorded source (UTM 45N) and centre."""
    from orokit.synthesis.terrain_type import TerrainType, load_terrain_type

    tt = load_terrain_type(small_type_file)
    tt = TerrainType.from_dict({**tt.to_dict(), "source_crs": CRS.from_epsg(32645).to_wkt(),
                                "source_center": list(center)})
    return tt.save(tmp_path / "located.json")


def test_type_of_a_georeferenced_dem_remembers_crs_centre_and_texture(tmp_path):
    from orokit.synthesis.terrain_type import load_terrain_type

    dem = tmp_path / "real.tif"
    rng = np.random.default_rng(4)
    z = (np.add.outer(np.linspace(0, 400, 150), np.linspace(0, 300, 200)) + 800 + rng.normal(0, 20, (150, 200)))
    hills = 300 * np.sin(np.linspace(0, 9, 150))[:, None] * np.cos(np.linspace(0, 11, 200))[None, :]
    with rasterio.open(dem, "w", driver="GTiff", width=200, height=150, count=1, dtype="float32", crs="EPSG:32633",
                       transform=from_origin(612_300, 5_123_400, 100, 100)) as ds:
        ds.write((z + hills).astype("float32"), 1)
        ds.update_tags(1, units="m")
    r = CliRunner().invoke(cli, ["type", str(dem), "-o", str(tmp_path / "t.json"), "--no-progress"])
    assert r.exit_code == 0, r.output
    tt = load_terrain_type(tmp_path / "t.json")
    assert CRS.from_user_input(tt.source_crs) == CRS.from_epsg(32633)
    # the grid's centre, (622 300, 5 115 900) in UTM 33N, as lon/lat
    lon, lat = Transformer.from_crs("EPSG:32633", "EPSG:4326", always_xy=True).transform(622_300, 5_115_900)
    assert Geod(ellps="WGS84").inv(lon, lat, *tt.source_center)[2] < 1.0
    assert tt.texture is not None and tt.texture["rms_m"] > 5.0 and np.isfinite(tt.texture["beta"])


def test_synthesize_places_the_terrain_where_its_type_was_measured(small_type_file, tmp_path):
    lon, lat = 86.925, 27.988
    typ = _located_type_file(small_type_file, tmp_path, (lon, lat))
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(typ), "--size", "20km", "--resolution", "100m",
                                 "--seed", "1", "--no-erosion", "--no-progress", "-o", str(tmp_path / "here")])
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "here" / "dem.tif") as b:
        assert b.crs is not None and "Azimuthal" in CRS.from_user_input(b.crs).to_wkt().replace("_", " ").title()
        cx, cy = b.transform * (b.width / 2, b.height / 2)
        clon, clat = Transformer.from_crs(b.crs, "EPSG:4326", always_xy=True).transform(cx, cy)
        assert Geod(ellps="WGS84").inv(lon, lat, clon, clat)[2] <= b.transform.a
    # a projected CRS alone: centred there too, not at the CRS's false origin
    r = CliRunner().invoke(cli, ["synthesize-tree", "--type", str(typ), "--size", "20km", "--crs", "EPSG:32645",
                                 "--seed", "1", "--no-progress", "-o", str(tmp_path / "utm")])
    assert r.exit_code == 0, r.output
    import pandas as pd

    peaks = pd.read_csv(tmp_path / "utm" / "peaks.csv")
    assert peaks["lon"].between(lon - 0.2, lon + 0.2).all() and peaks["lat"].between(lat - 0.2, lat + 0.2).all()
    # a local frame only when asked for
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(typ), "--size", "20km", "--resolution", "100m",
                                 "--crs", "local", "--seed", "1", "--no-erosion", "--no-progress",
                                 "-o", str(tmp_path / "local")])
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "local" / "dem.tif") as b:
        assert b.crs is None and b.transform.c == 0.0


def test_a_crs_without_centre_is_centred_on_its_area_of_use():
    from orokit.synthesis.controls import make_domain

    d = make_domain(20_000.0, crs="EPSG:32645")
    lon, lat = Transformer.from_crs(d.crs, "EPSG:4326", always_xy=True).transform(d.x0 + 10_000, d.y0 + 10_000)
    assert 84.0 <= lon <= 90.0 and 0.0 < lat < 84.0  # in UTM 45N's zone, not at its false origin (about 82.5 E, 0 N)


def test_render_like_a_manifest_dataset_takes_its_grid(real_data, tmp_path):
    """`render TREE --like NAME` with a manifest dataset name (as `synthesize --like` takes it):
    the render lands on that DEM's own extent and cells (issue 11)."""
    from orokit.io.divide_tree_io import write_divide_tree_gpkg
    from orokit.io.dem import read_dem
    from orokit.topology.divide_tree import DivideTree

    real_data("gobi")  # CI: fail, not skip, when the data is missing
    from orokit.cli.render import like_dem

    like = like_dem("gobi")
    t = like.rio.transform()
    x0, y0 = t.c + 20_000.0, t.f - 30_000.0  # inside the DEM, whose row 0 is north
    tree = DivideTree.from_arrays([[x0, y0, 1600.0], [x0 + 2000.0, y0, 1550.0]], [[x0 + 1000.0, y0, 1450.0]],
                                  [[0, 1, 0]], crs=None)
    write_divide_tree_gpkg(tree, tmp_path / "tree.gpkg")
    out = tmp_path / "r.tif"
    r = CliRunner().invoke(cli, ["render", str(tmp_path / "tree.gpkg"), "-o", str(out), "--like", "gobi",
                                 "--no-erosion", "--seed", "1"])
    assert r.exit_code == 0, r.output
    back = read_dem(str(out))
    assert back.shape == like.shape
    assert tuple(back.rio.transform())[:6] == tuple(pytest.approx(v) for v in tuple(t)[:6])


def test_center_is_one_word_lon_lat_on_both_commands(small_type_file, tmp_path):
    """`--center LON,LAT` on `synthesize` and `synthesize-tree`; the old two-word form of synthesize-tree,
    a point off Earth and `--crs local` with a centre are refused naming --center and the fix."""
    lon, lat = 15.0, 45.0
    base = ["--type", str(small_type_file), "--size", "10km", "--seed", "1", "--no-progress"]
    r = CliRunner().invoke(cli, ["synthesize-tree", *base, "--center", f"{lon},{lat}", "-o", str(tmp_path / "t")])
    assert r.exit_code == 0, r.output
    import pandas as pd

    peaks = pd.read_csv(tmp_path / "t" / "peaks.csv")
    assert peaks["lon"].between(lon - 0.2, lon + 0.2).all() and peaks["lat"].between(lat - 0.2, lat + 0.2).all()
    # a centre in a given CRS: the same on both commands (synthesize refused the pair before)
    for cmd, extra in (("synthesize-tree", []), ("synthesize", ["--resolution", "200m", "--no-erosion"])):
        out = tmp_path / f"utm-{cmd}"
        r = CliRunner().invoke(cli, [cmd, *base, *extra, "--crs", "EPSG:32633", "--center", f"{lon},{lat}",
                                     "-o", str(out)])
        assert r.exit_code == 0, (cmd, r.output)
        p = pd.read_csv(out / "peaks.csv")
        assert p["lon"].between(lon - 0.2, lon + 0.2).all(), cmd
    for cmd in ("synthesize-tree", "synthesize"):
        for bad, says in ((["--center", "15", "45"], "one word"), (["--center", "200,45"], "LON in [-180, 180]"),
                          (["--center", "15;45"], "not LON,LAT"),
                          (["--crs", "local", "--center", "15,45"], "not both")):
            r = CliRunner().invoke(cli, [cmd, *base, *bad, "-o", str(tmp_path / "bad")])
            assert r.exit_code == 2 and says in r.output and "--center" in r.output, (cmd, bad, r.output)
            assert "Traceback" not in r.output
