"""Same inputs and seed, same bytes: what `make report` commits does not change on a rerun."""
from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from orokit.cli.main import cli



def _features(tmp_path: Path) -> Path:
    import geopandas as gpd
    import shapely
    from helpers.classify_synth import make_peaks

    region = tmp_path / "region.gpkg"
    gpd.GeoDataFrame(geometry=[shapely.box(0, -60_000, 60_000, 0)], crs="EPSG:32633").to_file(region)
    inputs = []
    for k, kw in enumerate(({"prom_scale": 80.0}, {"prom_scale": 300.0, "relief_m": 3000.0})):
        p = make_peaks(900, rng=40 + k, **kw)
        path = tmp_path / f"r{k}.parquet"
        gpd.GeoDataFrame(p, geometry=gpd.points_from_xy(p["x"], p["y"]), crs="EPSG:32633").to_parquet(path)
        inputs.append(str(path))
    out = tmp_path / "f.parquet"
    res = CliRunner().invoke(cli, ["features", *inputs, "-o", str(out), "--region", str(region), "--no-progress"])
    assert res.exit_code == 0, res.output
    return out


def test_train_twice_same_model_bytes(tmp_path):
    feats = _features(tmp_path)
    models = []
    for k in (1, 2):
        m = tmp_path / f"m{k}.skops"
        res = CliRunner().invoke(cli, ["train", str(feats), "-o", str(m), "--runs", "2", "--feature-runs", "0",
                                       "--trees", "20", "--seed", "5", "--no-progress"])
        assert res.exit_code == 0, res.output
        models.append(m)
    assert models[0].read_bytes() == models[1].read_bytes()
    side = [json.loads(Path(f"{m}.json").read_text()) for m in models]
    assert side[0] == side[1] and side[0]["sha256"]
    other = tmp_path / "m3.skops"
    res = CliRunner().invoke(cli, ["train", str(feats), "-o", str(other), "--runs", "2", "--feature-runs", "0",
                                   "--trees", "20", "--seed", "6", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert other.read_bytes() != models[0].read_bytes()  # the seed matters


def test_terrain_type_has_no_clock_and_no_absolute_path(tmp_path, make_dem, monkeypatch):
    import numpy as np

    rng = np.random.default_rng(3)
    z = rng.normal(size=(60, 60)).cumsum(0).cumsum(1) * 5 + 500
    dem = tmp_path / "dem.tif"
    make_dem(z.astype("float32"), res=50.0).rio.to_raster(dem)
    monkeypatch.chdir(tmp_path)  # the DEM is under the working directory: recorded relative to it
    outs = []
    for k in (1, 2):
        out = tmp_path / f"t{k}.json"
        res = CliRunner().invoke(cli, ["type", str(dem), "-o", str(out), "--min-prominence", "10m",
                                       "--no-progress"])
        assert res.exit_code == 0, res.output
        outs.append(out.read_text())
    assert outs[0] == outs[1]
    prov = json.loads(outs[0])["provenance"]
    assert "created" not in prov
    assert prov["source"] == "dem.tif"
