"""``orokit validate --model``: per-disk classification and vote of a rendered terrain."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import rioxarray  # noqa: F401
import xarray as xr
from affine import Affine

import orokit
from orokit.cli.main import cli

# the small rendered raster leaves some disks with too few peaks: the CLI warns (an expected warning)
SKIPPED_DISKS = pytest.mark.filterwarnings(r"ignore:\d+ of \d+ disks .*were skipped:orokit.errors.OrokitWarning")


@pytest.fixture(scope="module")
def rendered_folder(tmp_path_factory):
    """A 30 x 30 km tree (analysis of a random multi-fractal DEM) rendered at 100 m."""
    from orokit.io.divide_tree_io import write_divide_tree_gpkg
    from orokit.raster.noise import fractal_noise
    from orokit.io.raster_io import write_cog
    from orokit.raster.params import RenderParams
    from orokit.raster.render import render_elevation

    z = 1500.0 + fractal_noise((300, 300), 100.0, amplitude=600.0, largest_m=8000.0, rng=4)
    x0, y0 = 500000.0, 4000000.0
    src = xr.DataArray(z.astype(np.float32), dims=("y", "x"), attrs={"units": "m"},
                       coords={"y": y0 - 50.0 - 100.0 * np.arange(300), "x": x0 + 50.0 + 100.0 * np.arange(300)})
    src = src.rio.write_crs("EPSG:32633").rio.write_transform(Affine(100.0, 0.0, x0, 0.0, -100.0, y0))
    tree = orokit.analyze(src, min_prominence_m=30.0, isolation=False).tree
    out = tmp_path_factory.mktemp("twin")
    write_divide_tree_gpkg(tree, out / "dividetree.gpkg")
    ext = (x0, y0 - 30000.0, x0 + 30000.0, y0)
    dem = render_elevation(tree, cell_size_m=100.0, extent=ext, erosion=False,
                           params=RenderParams(erosion_steps=1), rng=0)
    write_cog(dem, out / "dem.tif")
    return out, tree


@SKIPPED_DISKS
def test_validate_classifies_disks_with_a_trained_model(rendered_folder, region_model, tmp_path):
    from orokit.classify.model import load_model

    folder, tree = rendered_folder
    classes = load_model(region_model).classes
    label = classes[0]
    log = tmp_path / "roundtrip.csv"
    r = CliRunner().invoke(cli, ["validate", str(folder), "--model", str(region_model), "--label", label,
                                 "--append-to", str(log), "--overwrite"])
    assert r.exit_code == 0, r.output
    assert "classified as" in r.output
    v = json.loads((folder / "validation.json").read_text())
    s, c = v["summary"], v["classification"]
    assert s["n_disks"] == c["n_disks"] >= 1
    assert s["predicted"] == c["label"] and c["label"] in classes
    assert sum(c["votes"].values()) == s["n_disks"]
    # the overall label is the class of highest mean probability, and probabilities sum to 1
    probs = c["probabilities"]
    assert max(probs, key=probs.get) == c["label"]
    assert sum(probs.values()) == pytest.approx(1.0, abs=1e-6)
    # disk accuracy is the share of disks voting for the expected label
    assert s["expected"] == label
    assert s["disk_accuracy"] == pytest.approx(c["votes"][label] / s["n_disks"])
    assert s["vote_correct"] == (c["label"] == label)
    row = pd.read_csv(log).iloc[0]
    assert row["predicted"] == c["label"] and row["n_disks"] == s["n_disks"]
    # the tree's own terrain keeps its peaks
    assert s["recovered_share"] >= 0.95


@SKIPPED_DISKS
def test_validate_without_label_writes_only_the_folder(rendered_folder, region_model, tmp_path, monkeypatch):
    folder, _ = rendered_folder
    (folder / "validation.json").unlink(missing_ok=True)
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(cli, ["validate", str(folder), "--model", str(region_model)])
    assert r.exit_code == 0, r.output
    assert (folder / "validation.json").is_file() and list(tmp_path.iterdir()) == []
    # without --label and without a type there is no expected region, only the vote
    s = json.loads((folder / "validation.json").read_text())["summary"]
    assert "expected" not in s and s["predicted"]


@SKIPPED_DISKS
def test_roundtrip_report_table(rendered_folder, tmp_path):
    """roundtrip-report: one row per folder with the real-disk accuracy next to it."""
    import shutil

    folder, _ = rendered_folder
    if not (folder / "validation.json").exists():
        r = CliRunner().invoke(cli, ["validate", str(folder)])
        assert r.exit_code == 0, r.output
    twin = tmp_path / "twins" / "alaska"
    shutil.copytree(folder, twin)
    per_class = tmp_path / "per_class.csv"
    pd.DataFrame({"region": ["alaska"], "random_accuracy_%": [96.0], "spatial_accuracy_%": [38.0]}).to_csv(per_class)
    out = tmp_path / "twins" / "README.md"
    args = ["roundtrip-report", str(twin), "--classification", str(per_class), "-o", str(out), "--no-progress"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    text = out.read_text()
    assert "| alaska |" in text and "96" in text and "alaska/twin.png" in text
    assert (twin / "twin.png").stat().st_size > 0
    table = pd.read_csv(out.parent / "README.csv")
    assert table.loc[0, "real_disk_acc_%"] == 96.0
    assert table.loc[0, "recovered_%"] >= 95.0
    r = CliRunner().invoke(cli, args)
    assert r.exit_code != 0 and "--overwrite" in r.output


def test_synthesize_like_takes_the_size_and_cell_size_of_a_dem(rendered_folder, tmp_path):
    """`orokit synthesize --like DEM`: a twin with the DEM's extent size and cell size."""
    import rasterio

    from orokit.io.dem import read_dem
    from orokit.synthesis.terrain_type import TerrainType

    folder, _ = rendered_folder
    like = read_dem(str(folder / "dem.tif"), z_units="m")
    ttype = TerrainType.from_analysis(orokit.analyze(like, min_prominence_m=30.0), name="noise")
    type_file = ttype.save(tmp_path / "noise.json")
    out = tmp_path / "twin"
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(type_file), "--like", str(folder / "dem.tif"),
                                 "--no-erosion", "--seed", "1", "-o", str(out), "--no-progress"])
    assert r.exit_code == 0, r.output
    with rasterio.open(out / "dem.tif") as src:
        assert src.res == (100.0, 100.0) and (src.width, src.height) == (300, 300)
    meta = json.loads((out / "synthesis.json").read_text())
    assert meta["like"] == str(folder / "dem.tif") and meta["cell_size_m"] == 100.0
    r = CliRunner().invoke(cli, ["synthesize", "--type", str(type_file), "--like", "no-such-dataset", "-o",
                                 str(tmp_path / "x"), "--no-progress"])
    assert r.exit_code != 0 and "--like" in r.output


@SKIPPED_DISKS
def test_classify_reads_rendered_rasters_without_flags(rendered_folder, region_model, tmp_path):
    """`orokit classify` on a rendered raster, with its CRS and on a local grid, needs no --z-units."""
    from orokit.io.dem import read_dem
    from orokit.io.raster_io import write_cog

    folder, _ = rendered_folder
    dem = read_dem(str(folder / "dem.tif"))
    local = xr.DataArray(dem.values, dims=("y", "x"), coords={"y": dem.y.values, "x": dem.x.values},
                         attrs={"units": "m"}).rio.write_transform(dem.rio.transform())
    write_cog(local, tmp_path / "local.tif")
    for path in (folder / "dem.tif", tmp_path / "local.tif"):
        r = CliRunner().invoke(cli, ["classify", str(region_model), str(path), "--json"])
        assert r.exit_code == 0, r.output
        doc, _ = json.JSONDecoder().raw_decode(r.output[r.output.index("{"):])  # warnings may follow on stderr
        assert doc["n_disks"] >= 1


def test_roundtrip_report_landform_tables_and_figures(rendered_folder, tmp_path):
    """Per region: real vs render of the real tree vs twin, distances beside the halves' yardstick,
    and a 150 dpi landform figure. A 'render' identical to the real DEM is at distance 0."""
    import shutil

    import rasterio

    from orokit.io.raster_io import write_cog
    from orokit.raster.params import RenderParams
    from orokit.raster.render import render_elevation

    folder, tree = rendered_folder
    if not (folder / "validation.json").exists():
        r = CliRunner().invoke(cli, ["validate", str(folder)])
        assert r.exit_code == 0, r.output
    twin = tmp_path / "twins" / "somewhere"
    shutil.copytree(folder, twin)
    with rasterio.open(folder / "dem.tif") as ds:
        b = ds.bounds
    real = render_elevation(tree, cell_size_m=100.0, extent=(b.left, b.bottom, b.right, b.top), erosion=False,
                            params=RenderParams(erosion_steps=1), rng=9)
    write_cog(real, tmp_path / "real.tif")
    meta = json.loads((twin / "synthesis.json").read_text()) if (twin / "synthesis.json").is_file() else {}
    (twin / "synthesis.json").write_text(json.dumps({**meta, "like": str(tmp_path / "real.tif")}))
    renders = tmp_path / "renders"
    renders.mkdir()
    shutil.copy(tmp_path / "real.tif", renders / "somewhere.tif")
    out = tmp_path / "twins" / "README.md"
    r = CliRunner().invoke(cli, ["roundtrip-report", str(twin), "--renders", str(renders), "-o", str(out),
                                 "--no-progress"])
    assert r.exit_code == 0, r.output
    text = out.read_text()
    assert "## Landforms" in text and "### somewhere" in text and "somewhere/landforms.png" in text
    row = next(line for line in text.splitlines() if line.startswith("| slope distribution"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3] == "0.000"  # the render column: the real DEM itself
    assert "render of its real tree: 6 of 6" in text
    png = twin / "landforms.png"
    from PIL import Image

    with Image.open(png) as im:
        assert im.info.get("dpi", (0, 0))[0] >= 149 and im.size[0] > 1000
