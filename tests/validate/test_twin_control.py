"""`orokit synthesize --like DEM --control-elevation like`: a twin keeps the real large-scale relief."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import rasterio
from click.testing import CliRunner
from rasterio.transform import from_origin

from orokit.cli.main import cli


def _tilted_dem(path):
    """20 x 20 km at 100 m: high in the west (1800 m), low in the east (300 m)."""
    x = np.linspace(1800.0, 300.0, 200)
    z = np.tile(x, (200, 1)).astype("float32")
    with rasterio.open(path, "w", driver="GTiff", width=200, height=200, count=1, dtype="float32", crs="EPSG:32633",
                       transform=from_origin(500000, 4000000, 100, 100)) as ds:
        ds.write(z, 1)
        ds.update_tags(1, units="m")
    return path


def test_control_elevation_like_follows_the_real_relief(small_type_file, tmp_path):
    dem = _tilted_dem(tmp_path / "real.tif")
    runner = CliRunner()
    out = {}
    for name, extra in (("free", []), ("twin", ["--control-elevation", "like"])):
        r = runner.invoke(cli, ["synthesize", "--type", str(small_type_file), "--like", str(dem), "--seed", "3",
                                "--no-erosion", "--no-progress", "-o", str(tmp_path / name), *extra])
        assert r.exit_code == 0, r.output
        out[name] = pd.read_csv(tmp_path / name / "peaks.csv")
    meta = json.loads((tmp_path / "twin" / "synthesis.json").read_text())
    assert meta["control_elevation"] == "like"

    def west_minus_east(p):
        xm = p["x"].median()
        return p.loc[p["x"] < xm, "elevation"].mean() - p.loc[p["x"] >= xm, "elevation"].mean()

    # with C_H from the tilted DEM, western peaks are much higher than eastern ones; without it, not
    assert west_minus_east(out["twin"]) > 300.0
    assert west_minus_east(out["twin"]) > west_minus_east(out["free"]) + 200.0


def test_control_elevation_like_needs_like(small_type_file, tmp_path):
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(small_type_file), "--size", "20km", "--no-progress",
                                 "--control-elevation", "like", "-o", str(tmp_path / "x")])
    assert r.exit_code != 0 and "--like" in r.output
