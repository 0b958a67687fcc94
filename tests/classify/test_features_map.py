"""Feature invariances, the --map output, small regions through the CLI (issue 12)."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from orokit.classify.features import feature_table
from orokit.classify.peaklist import peak_geometry
from orokit.cli.main import cli
from orokit.sampling.feature_sets import FeatureSet

N, RES, RADIUS = 161, 100.0, 6000.0


def _terrain(seed: int = 3) -> np.ndarray:
    """Sum of Gaussian hills with a tiny continuous noise (no ties, so rotation keeps every peak)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:N, 0:N].astype(float)
    z = np.zeros((N, N))
    for _ in range(220):
        cy, cx = rng.uniform(0, N, 2)
        z += rng.uniform(40, 600) * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * rng.uniform(2, 9) ** 2))
    return z + 300.0 + rng.uniform(0, 1e-3, z.shape)


def write_tif(path, z: np.ndarray, *, res: float):
    """A float32 GeoTIFF in metres (EPSG:32633), as a user would have."""
    import rioxarray  # noqa: F401
    import xarray as xr
    from rasterio.transform import Affine

    ny, nx = z.shape
    da = xr.DataArray(z.astype(np.float32), dims=("y", "x"),
                      coords={"y": 4_000_000 - (np.arange(ny) + 0.5) * res, "x": 500_000 + (np.arange(nx) + 0.5) * res})
    da = da.rio.write_crs("EPSG:32633").rio.write_transform(Affine(res, 0, 500_000, 0, -res, 4_000_000))
    da.attrs["units"] = "m"
    da.rio.to_raster(path)
    return path


def _centre_features(make_dem, z: np.ndarray, fs: FeatureSet) -> pd.Series:
    import orokit

    dem = make_dem(z.astype(np.float64), res=RES)
    res = orokit.analyze(dem, min_prominence_m=0.0)
    peaks = peak_geometry(res.peaks, crs=dem.rio.crs)
    t = dem.rio.transform()
    cx, cy = t * (N // 2 + 0.5, N // 2 + 0.5)  # centre of the middle cell, the fixed point of rot90 / flips
    disks = pd.DataFrame({"disk_id": [0], "x": [cx], "y": [cy], "radius_m": [RADIUS]})
    f = feature_table(peaks, disks, feature_set=fs, min_prominence_m=30.0, min_peaks=5, crs=dem.rio.crs,
                      dem=dem if fs.terrain else None)
    assert len(f) == 1
    return f[fs.columns].iloc[0]


@pytest.mark.parametrize("name", ["paper", "orometry", "pattern", "terrain"])
def test_features_invariant_to_rotation_and_flips_except_directions(make_dem, name):
    import dataclasses

    fs = (dataclasses.replace(FeatureSet.orometry(), name="p", pattern=True) if name == "pattern"
          else FeatureSet.named(name))
    z = _terrain()
    base = _centre_features(make_dem, z, fs)
    direction = [c for c in fs.columns if "direction" in c]
    other = [c for c in fs.columns if c not in direction]
    dom = base[[f"dominance_{i}" for i in range(20)]].to_numpy()
    assert (dom[-1] if fs.cumulative else dom.sum()) == pytest.approx(1.0)  # normalized (cumulative: ends at 1)
    for k, zz in enumerate([np.rot90(z), np.fliplr(z), np.flipud(z), z.T]):
        f = _centre_features(make_dem, zz, fs)
        np.testing.assert_allclose(f[other].to_numpy(), base[other].to_numpy(), atol=1e-9,
                                   err_msg=f"transform {k}")
    if not direction:  # the default set leaves the direction histograms out
        return
    # a 90 degree counter-clockwise rotation turns every direction by +90 degrees: 3 bins of 30 degrees
    rot = _centre_features(make_dem, np.rot90(z), fs)
    for feat in ("isolation_direction", "saddle_direction"):
        cols = [f"{feat}_{i}" for i in range(12)]
        moved = np.roll(base[cols].to_numpy(), 3)
        # directions on a bin edge (multiples of 90 degrees on a grid) may land on either side of it
        assert np.abs(rot[cols].to_numpy() - moved).sum() < 0.1
        assert not np.allclose(rot[cols].to_numpy(), base[cols].to_numpy())  # they did rotate


@pytest.fixture(scope="module")
def dems_and_model(tmp_path_factory):
    """Two synthetic 'regions' as GeoTIFFs and a model trained on them through the CLI."""
    tmp = tmp_path_factory.mktemp("map")
    paths = []
    for name, seed, amp in (("hilly", 1, 1.0), ("steep", 2, 3.5)):
        z = 300 + amp * (_terrain(seed) - 300)
        z = np.tile(z, (2, 2))[: 2 * N - 1, : 2 * N - 1]
        paths.append(write_tif(tmp / f"{name}.tif", z, res=RES))
    r = CliRunner()
    feats = tmp / "f.parquet"
    res = r.invoke(cli, ["features", *map(str, paths), "-o", str(feats), "--radius", "5km", "--min-peaks", "5",
                         "--no-progress"])
    assert res.exit_code == 0, res.output
    model = tmp / "m.skops"
    res = r.invoke(cli, ["train", str(feats), "-o", str(model), "--runs", "2", "--feature-runs", "0", "--split",
                         "random", "--trees", "20", "--no-progress"])
    assert res.exit_code == 0, res.output
    return tmp, paths, model


def test_classify_map_gpkg(dems_and_model):
    import geopandas as gpd

    tmp, paths, model = dems_and_model
    out = tmp / "map.gpkg"
    res = CliRunner().invoke(cli, ["classify", str(model), str(paths[1]), "--map", str(out), "--json"])
    assert res.exit_code == 0, res.output
    js = json.loads(res.output[res.output.index("{"):])
    g = gpd.read_file(out, layer="disks")
    assert len(g) == js["n_disks"] > 3  # one polygon per disk
    assert g.crs.equals("EPSG:32633")  # the DEM's CRS
    p = g[[c for c in g.columns if c.startswith("proba_")]].to_numpy(float)
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-9)
    assert set(g.geom_type) == {"Polygon"}
    # each polygon is the disk: centred on its centre, radius R
    np.testing.assert_allclose(g.geometry.centroid.x, g["x"], atol=1.0)
    np.testing.assert_allclose(np.sqrt(g.geometry.area / np.pi), 5000.0, rtol=0.01)
    assert (tmp / "map.png").stat().st_size > 10_000
    assert js["label"] == "steep"
    # an existing map is kept without --overwrite; a non-GeoPackage name is refused
    assert CliRunner().invoke(cli, ["classify", str(model), str(paths[1]), "--map", str(out)]).exit_code != 0
    bad = CliRunner().invoke(cli, ["classify", str(model), str(paths[1]), "--map", str(tmp / "m.shp")])
    assert bad.exit_code != 0 and ".gpkg" in bad.output


def test_unknown_input_name_is_refused(dems_and_model):
    _, _, model = dems_and_model
    res = CliRunner().invoke(cli, ["classify", str(model), "no-such-dataset"])
    # a usage error (exit 2) like every bad argument, listing the manifest DEMs
    assert res.exit_code == 2 and "nor a DEM of the datasets manifest" in res.output and "gobi" in res.output


def test_region_with_one_disk_is_named_and_dropped(dems_and_model):
    import pandas as pd

    from orokit.io.model_io import read_feature_table, write_feature_table

    tmp, _, _ = dems_and_model
    f = read_feature_table(tmp / "f.parquet")
    one = f[f["label"] == "hilly"].iloc[:1].copy()
    one["label"] = "lonely"
    g = pd.concat([f, one], ignore_index=True)
    g.attrs = f.attrs
    path = write_feature_table(g, tmp / "g.parquet")
    r = CliRunner()
    res = r.invoke(cli, ["train", str(path), "-o", str(tmp / "g.skops"), "--runs", "1", "--no-progress"])
    assert res.exit_code == 1 and "lonely: 1" in res.output and "--drop-small-classes" in res.output
    from orokit.errors import OrokitWarning

    with pytest.warns(OrokitWarning) as rec:  # the evaluation and the final fit both drop the region
        res = r.invoke(cli, ["train", str(path), "-o", str(tmp / "g.skops"), "--runs", "1", "--feature-runs", "0",
                             "--drop-small-classes", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert any("dropping regions with fewer than 2" in str(w.message) and "lonely: 1" in str(w.message) for w in rec)


def test_terrain_label_sums_floored_log_probabilities():
    from orokit.classify.calibration import log_proba

    proba = np.array([[0.9, 0.1], [0.9, 0.1], [0.0, 1.0]])
    # the mean probability prefers class 0 (0.6), the summed log-probability class 1: one disk that rules
    # class 0 out (floored at 1e-3) outweighs two disks that merely lean to it
    logp = log_proba(proba).sum(axis=0)
    np.testing.assert_allclose(logp, [2 * np.log(0.9) + np.log(1e-3 / 1.001), 2 * np.log(0.1) + np.log(1 / 1.001)])
    assert np.argmax(proba.mean(0)) == 0 and np.argmax(logp) == 1


def test_disk_map_polygons_are_geodesic_circles_on_lonlat():
    from pyproj import Geod

    from orokit.classify.predict import Prediction, disk_map

    disks = pd.DataFrame({"disk_id": [0, 1], "x": [10.0, -70.0], "y": [46.0, -33.0], "radius_m": [10_000.0] * 2,
                          "n_peaks": [30, 40], "predicted": ["a", "b"], "proba_a": [0.7, 0.2],
                          "proba_b": [0.3, 0.8]})
    g = disk_map(Prediction(disks, "a", {"a": 0.5, "b": 0.5}, {"a": 1, "b": 1}), crs="EPSG:4326")
    assert g.crs.equals("EPSG:4326") and list(g["confidence"]) == [0.7, 0.8]
    geod = Geod(ellps="WGS84")
    for (_, row), poly in zip(disks.iterrows(), g.geometry):
        lon, lat = np.asarray(poly.exterior.xy)
        _, _, d = geod.inv(np.full(len(lon), row["x"]), np.full(len(lat), row["y"]), lon, lat)
        np.testing.assert_allclose(d, 10_000.0, rtol=1e-6)


def test_auto_features_are_terrain_for_dems_and_a_terrain_model_refuses_a_peak_list(dems_and_model):
    """`orokit features` on DEMs defaults to the terrain set; its model names the fix for a peak list."""
    import orokit
    from orokit.classify.inputs import auto_feature_set, has_dem
    from orokit.io.dem import read_dem
    from orokit.io.model_io import read_feature_table

    tmp, paths, model = dems_and_model
    assert read_feature_table(tmp / "f.parquet").attrs["feature_set"]["name"] == "terrain"
    peaks_csv = tmp / "peaks.csv"
    orokit.analyze(read_dem(str(paths[1])), min_prominence_m=30.0).peaks.to_csv(peaks_csv, index=False)
    assert has_dem(paths[0]) and not has_dem(peaks_csv)
    assert auto_feature_set([paths[0], peaks_csv]).name == "orometry"
    from orokit.errors import OrokitWarning

    with pytest.warns(OrokitWarning, match="convex hull"):  # a bare peak list: disks in the hull of its peaks
        res = CliRunner().invoke(cli, ["classify", str(model), str(peaks_csv)])
    assert res.exit_code == 1 and "needs the DEM" in res.output and "--features orometry" in res.output
    assert "Traceback" not in res.output


def test_features_in_worker_processes_equal_one_process(dems_and_model):
    """`--n-jobs 2` (the default: one process per input at a time) writes the same bytes as `--n-jobs 1`."""
    tmp, paths, _ = dems_and_model
    one = tmp / "f1.parquet"
    res = CliRunner().invoke(cli, ["features", *map(str, paths), "-o", str(one), "--radius", "5km", "--min-peaks", "5",
                                   "--no-progress", "--n-jobs", "1"])
    assert res.exit_code == 0, res.output
    assert one.read_bytes() == (tmp / "f.parquet").read_bytes()
