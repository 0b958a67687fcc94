"""Outputs of synthesize / validate / roundtrip-report: seeds, no clobbering, safe overwrite, zero defaults."""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
import rasterio
from click.testing import CliRunner

import orokit.io.raster_io as raster_io
from orokit.cli.main import cli
from orokit.io.dem import read_dem
from orokit.topology.divide_tree import DivideTree
from orokit.validate.roundtrip import model_feature_options, roundtrip


def synthesize(out, type_file, *extra: str):
    """`orokit synthesize` of a 6 x 6 km domain at 100 m without erosion (about 7 peaks)."""
    args = ["synthesize", "--type", str(type_file), "--size", "6km", "--resolution", "100m", "--no-erosion",
            "-o", str(out), "--no-progress", *extra]
    return CliRunner().invoke(cli, args)


@pytest.fixture(scope="module")
def twin(tmp_path_factory, small_type_file):
    """A synthesize folder made without --seed."""
    out = tmp_path_factory.mktemp("twin") / "twin"
    r = synthesize(out, small_type_file)
    assert r.exit_code == 0, r.output
    return out


def test_synthesize_records_the_seed_it_ran_with(twin, small_type_file, tmp_path):
    seed = json.loads((twin / "synthesis.json").read_text())["seed"]
    assert isinstance(seed, int) and seed >= 0
    with rasterio.open(twin / "dem.tif") as src:
        assert int(src.tags()["seed"]) == seed
        z = src.read(1)
    # the recorded seed replays the run: same tree, same raster
    again = tmp_path / "again"
    r = synthesize(again, small_type_file, "--seed", str(seed))
    assert r.exit_code == 0, r.output
    with rasterio.open(again / "dem.tif") as src:
        np.testing.assert_array_equal(src.read(1), z)
    pd.testing.assert_frame_equal(pd.read_csv(again / "peaks.csv"), pd.read_csv(twin / "peaks.csv"))


def test_synthesized_dem_reads_back_without_flags(twin, small_type_file, tmp_path):
    dem = read_dem(str(twin / "dem.tif"))
    assert dem.attrs["local_grid"] and not dem.attrs["z_units_assumed"]
    out = tmp_path / "utm"
    r = synthesize(out, small_type_file, "--seed", "3", "--crs", "EPSG:32633")
    assert r.exit_code == 0, r.output
    assert read_dem(str(out / "dem.tif")).rio.crs.to_epsg() == 32633


def test_failed_overwrite_keeps_the_previous_terrain_byte_identical(small_type_file, tmp_path, monkeypatch):
    out = tmp_path / "twin"
    assert synthesize(out, small_type_file, "--seed", "1").exit_code == 0
    (out / "validation.json").write_text("{}")  # a validation of the old terrain
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(raster_io, "write_cog", disk_full)
    r = synthesize(out, small_type_file, "--seed", "2", "--overwrite")
    assert r.exit_code == 1
    assert f"no space left on {out.resolve()}" in r.output and "Traceback" not in r.output
    # the new tree was written (staged) but nothing of the old terrain changed, no temp file left
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    monkeypatch.undo()
    r = synthesize(out, small_type_file, "--seed", "2", "--overwrite")
    assert r.exit_code == 0, r.output
    assert json.loads((out / "synthesis.json").read_text())["seed"] == 2
    assert not (out / "validation.json").exists()  # it described the old terrain
    mtimes = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    assert max(mtimes, key=mtimes.get) == "hillshade.png"  # the marker is written last


def test_validate_writes_only_into_out_and_keeps_existing_json(twin, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = {p.name for p in twin.iterdir()}
    r = CliRunner().invoke(cli, ["validate", str(twin)])
    assert r.exit_code == 0, r.output
    assert not (tmp_path / "reports").exists() and list(tmp_path.iterdir()) == []
    assert {p.name for p in twin.iterdir()} - before == {"validation.json"}
    first = (twin / "validation.json").read_text()
    r = CliRunner().invoke(cli, ["validate", str(twin), "--min-prominence", "50"])
    assert r.exit_code == 2 and "--overwrite" in r.output
    assert (twin / "validation.json").read_text() == first
    log = tmp_path / "logs" / "roundtrip.csv"
    for _ in range(2):
        r = CliRunner().invoke(cli, ["validate", str(twin), "--min-prominence", "50", "--overwrite",
                                     "--append-to", str(log)])
        assert r.exit_code == 0, r.output
    table = pd.read_csv(log)
    assert len(table) == 2 and (table["min_prominence_m"] == 50.0).all()
    assert json.loads((twin / "validation.json").read_text())["summary"]["min_prominence_m"] == 50.0
    # a raster (not a folder) with -o JSON; an existing -o is kept without --overwrite
    res = tmp_path / "v.json"
    args = ["validate", str(twin / "dem.tif"), "--tree", str(twin / "dividetree.gpkg"), "-o", str(res)]
    assert CliRunner().invoke(cli, args).exit_code == 0 and res.is_file()
    assert CliRunner().invoke(cli, args).exit_code == 2


def test_roundtrip_report_does_not_clobber_the_validate_log(twin, tmp_path):
    import shutil

    region = tmp_path / "rep" / "alaska"
    shutil.copytree(twin, region)
    if not (region / "validation.json").exists():
        assert CliRunner().invoke(cli, ["validate", str(region)]).exit_code == 0
    log = tmp_path / "rep" / "roundtrip.csv"
    log.write_text("time,raster\nearlier,run\n")
    out = tmp_path / "rep" / "README.md"
    args = ["roundtrip-report", str(region), "-o", str(out), "--no-progress"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 0, r.output
    assert log.read_text() == "time,raster\nearlier,run\n"
    assert pd.read_csv(tmp_path / "rep" / "README.csv")["region"].tolist() == ["alaska"]
    # every output is checked before any work: a left-over twin.png alone stops a rerun
    out.unlink()
    (tmp_path / "rep" / "README.csv").unlink()
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 2 and "twin.png" in r.output and not out.exists()
    assert CliRunner().invoke(cli, args + ["--overwrite"]).exit_code == 0 and out.is_file()
    r = CliRunner().invoke(cli, args + ["--overwrite", "--table", str(out)])
    assert r.exit_code == 2 and "--table" in r.output


def test_model_zero_options_are_kept(monkeypatch):
    """A model trained at eps = 0 with min_peaks = 0 is applied with 0 and 0, not 30 m and 20."""
    import orokit.classify.features as features
    import orokit.classify.predict as predict
    from orokit.raster.render import render_elevation

    seen = {}

    def fake_features(dem, **kw):
        seen.update(kw)
        return pd.DataFrame()

    monkeypatch.setattr(features, "features_from_dem", fake_features)
    monkeypatch.setattr(predict, "predict_regions",
                        lambda model, feats, **kw: SimpleNamespace(label="x", disks=pd.DataFrame({"predicted": ["x"]})))
    tree = DivideTree.from_arrays([[1000.0, 1000.0, 600.0], [3000.0, 1000.0, 550.0]], [[2000.0, 1000.0, 450.0]],
                                  [[0, 1, 0]], attrs={"extent": [0.0, 0.0, 4000.0, 2000.0]})
    dem = render_elevation(tree, cell_size_m=100.0, erosion=False, rng=0)
    model = SimpleNamespace(radius_m=1000.0, feature_set=None,
                            metadata={"min_prominence_m": 0.0, "min_peaks": 0, "relative_elevation": None})
    roundtrip(dem, tree, min_prominence_m=30.0, model=model)
    assert seen["min_prominence_m"] == 0.0 and seen["min_peaks"] == 0
    assert seen["relative_elevation"] == "minmax"
    assert model_feature_options({}, min_prominence_m=12.0) == {
        "min_prominence_m": 12.0, "min_peaks": 20, "relative_elevation": "minmax"}


def test_validate_says_when_no_disk_fits(twin, region_model, tmp_path):
    """A 6 km twin holds no 10 km disk: the message says so instead of 'classified as None'."""
    from orokit.errors import OrokitWarning

    with pytest.warns(OrokitWarning, match="no disk"):
        r = CliRunner().invoke(cli, ["validate", str(twin), "--model", str(region_model), "-o",
                                     str(tmp_path / "v.json")])
    assert r.exit_code == 0, r.output
    assert "not classified: no disk of radius 10 km fits" in r.output and "None" not in r.output
    assert json.loads((tmp_path / "v.json").read_text())["summary"]["n_disks"] == 0


def test_validate_on_an_analysis_folder_says_what_to_validate(tmp_path):
    """An `orokit analyze` folder has a Divide Tree but no raster: the hint is to render it, not to synthesize
    into the analysis folder."""
    folder = tmp_path / "analysis"
    folder.mkdir()
    (folder / "analysis.json").write_text("{}")
    (folder / "dividetree.gpkg").write_bytes(b"")
    r = CliRunner().invoke(cli, ["validate", str(folder)])
    assert r.exit_code == 2
    assert "orokit analyze" in r.output and "orokit render" in r.output
    assert "synthesize -o" not in r.output
    assert not (folder / "validation.json").exists()
