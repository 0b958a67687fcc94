"""Round-trip comparison and the render / synthesize / validate commands."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import orokit
from orokit.cli.main import cli
from orokit.errors import InputError
from orokit.topology.divide_tree import DivideTree
from orokit.validate.roundtrip import compare_peaks, roundtrip


def two_peak_tree() -> DivideTree:
    return DivideTree.from_arrays([[1000.0, 1000.0, 600.0], [3000.0, 1000.0, 550.0]], [[2000.0, 1000.0, 450.0]],
                                  [[0, 1, 0]], attrs={"extent": [0.0, 0.0, 4000.0, 2000.0]})


def test_compare_peaks_counts_recovered_and_extra():
    tree = two_peak_tree()  # prominences 600 (root) and 100
    raster = pd.DataFrame({"x": [1010.0, 3000.0, 2000.0, 100.0], "y": [1000.0, 1500.0, 300.0, 100.0],
                           "prominence": [600.0, 100.0, 45.0, 10.0]})
    comp = compare_peaks(tree, raster, min_prominence_m=30.0, distance_tol_m=100.0)
    # peak 1's nearest raster peak is 500 m away: not recovered, and that raster peak is extra
    # like the 45 m one; the 10 m one is below eps
    assert comp.peaks["recovered"].tolist() == [True, False]
    assert sorted(comp.extra["prominence"]) == [45.0, 100.0]
    assert comp.extra_share == 1.0
    raster.loc[1, "y"] = 1000.0
    raster.loc[1, "prominence"] = 130.0  # 30 m off: beyond max(15, 10 %)
    assert compare_peaks(tree, raster, distance_tol_m=100.0).peaks["recovered"].tolist() == [True, False]
    raster.loc[1, "prominence"] = 108.0
    assert compare_peaks(tree, raster, distance_tol_m=100.0).recovered_share == 1.0
    with pytest.raises(InputError):
        compare_peaks(tree, raster, distance_tol_m=0.0)


def test_roundtrip_of_rendered_tree():
    from orokit.raster.params import RenderParams
    from orokit.raster.render import render_elevation

    tree = two_peak_tree()
    dem = render_elevation(tree, cell_size_m=50.0, erosion=False, params=RenderParams(erosion_steps=1), rng=1)
    rt = roundtrip(dem, tree, min_prominence_m=30.0)
    s = rt.summary()
    assert s["recovered_share"] == 1.0 and s["extra_peaks"] == 0
    assert s["tree_peaks"] == 2


def test_cli_render_then_validate(tmp_path):
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    tree = two_peak_tree()
    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(tree, gpkg)
    out = tmp_path / "dem.tif"
    args = ["render", str(gpkg), "-o", str(out), "--resolution", "50m", "--no-erosion", "--seed", "2",
            "--extent", "0", "0", "4000", "2000", "--preview", str(tmp_path / "hs.png"), "--tin", str(tmp_path / "t.ply")]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    import rasterio

    with rasterio.open(out) as src:
        assert src.res == (50.0, 50.0) and src.width == 80 and src.height == 40
        tags = src.tags()
        assert tags["units"] == "m" and tags["seed"] == "2" and "orokit_version" in tags
        assert np.isnan(src.nodata)
    assert (tmp_path / "hs.png").stat().st_size > 0 and (tmp_path / "t.ply").read_text().startswith("ply")
    r = CliRunner().invoke(cli, args)
    assert r.exit_code != 0 and "--overwrite" in r.output
    log = tmp_path / "reports" / "roundtrip.csv"
    r = CliRunner().invoke(cli, ["validate", str(out), "--tree", str(gpkg), "--append-to", str(log)])
    assert r.exit_code == 0, r.output
    table = pd.read_csv(log)
    assert len(table) == 1 and table["recovered_share"].iloc[0] == 1.0
    CliRunner().invoke(cli, ["validate", str(out), "--tree", str(gpkg), "--append-to", str(log)])
    assert len(pd.read_csv(log)) == 2  # appended


@pytest.mark.parametrize("res", ["0m", "-5", "abc"])
def test_cli_render_bad_resolution(tmp_path, res):
    from orokit.io.divide_tree_io import write_divide_tree_gpkg

    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(two_peak_tree(), gpkg)
    r = CliRunner().invoke(cli, ["render", str(gpkg), "-o", str(tmp_path / "x.tif"), "--resolution", res])
    assert r.exit_code != 0 and "resolution" in r.output.lower()
    assert not (tmp_path / "x.tif").exists()


@pytest.mark.realdata
@pytest.mark.slow
def test_real_tree_round_trip(real_data):
    """The Divide Tree of a real DEM, rendered on the DEM's grid, keeps >= 95 % of its peaks."""
    from orokit.io.manifest import load_manifest
    from orokit.io.dem import read_dem
    from orokit.raster.render import render_elevation

    ds = load_manifest()["alaska"]
    cell = ds.cell_size_m  # 92.61 m, as the manifest says
    dem = read_dem(real_data("alaska"), z_units=ds.z_units, cell_size_m=cell)
    res = orokit.analyze(dem, min_prominence_m=30.0, isolation=False)
    ny, nx = dem.shape
    out = render_elevation(res.tree, cell_size_m=cell, extent=(0.0, -ny * cell, nx * cell, 0.0),
                           erosion=True, rng=0)
    s = roundtrip(out, res.tree, min_prominence_m=30.0).summary()
    assert s["recovered_share"] >= 0.95
    assert s["extra_share"] <= 0.05
