"""``orokit type`` and ``orokit synthesize-tree`` on files in tmp_path."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from orokit.analysis import write_analysis
from orokit.cli.main import cli
from orokit.cli.synthesize_tree import parse_size
from orokit.synthesis.terrain_type import load_terrain_type


@pytest.fixture()
def type_file(tmp_path, small_type):
    return small_type.save(tmp_path / "t.json")


def test_parse_size():
    assert parse_size("90km") == (90_000.0, 90_000.0)
    assert parse_size("90x60km") == (90_000.0, 60_000.0)
    assert parse_size("2500") == (2500.0, 2500.0)
    with pytest.raises(Exception, match="not a size"):
        parse_size("ninety")


def test_synthesize_tree_writes_outputs_and_refuses_overwrite(tmp_path, type_file):
    out = tmp_path / "out"
    args = ["synthesize-tree", "--type", str(type_file), "--size", "20km", "--seed", "3", "--crs", "EPSG:32633",
            "--center", "15,45", "--no-progress", "-o", str(out)]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 0, res.output
    for f in ("dividetree.gpkg", "dividetree.txt", "peaks.csv", "synthesis.json"):
        assert (out / f).is_file()
    peaks = pd.read_csv(out / "peaks.csv", index_col="peak_id")
    meta = json.loads((out / "synthesis.json").read_text())
    assert len(peaks) == meta["n_peaks"]
    assert peaks["lon"].between(14.8, 15.2).all()
    assert {f["feature"] for f in meta["fidelity"]} >= {"prominence", "saddle_distance"}
    from orokit.io.divide_tree_io import read_divide_tree_gpkg, read_divide_tree_txt

    g = read_divide_tree_gpkg(out / "dividetree.gpkg")
    assert g.n_peaks == len(peaks) and g.crs.to_epsg() == 32633
    t = read_divide_tree_txt(out / "dividetree.txt", cell_size_m=30.0)
    assert t.n_peaks == len(peaks)
    # prominences survive the TXT round trip (feet, 1 ft rounding)
    assert np.allclose(np.sort(t.prominence()), np.sort(peaks["prominence"]), atol=1.0)
    again = CliRunner().invoke(cli, args)
    assert again.exit_code != 0 and "--overwrite" in again.output
    assert CliRunner().invoke(cli, args + ["--overwrite"]).exit_code == 0


def test_synthesize_tree_same_seed_same_peaks(tmp_path, type_file):
    outs = []
    for k in range(2):
        out = tmp_path / f"o{k}"
        res = CliRunner().invoke(cli, ["synthesize-tree", "--type", str(type_file), "--size", "15km", "--seed", "11",
                                       "--no-progress", "-o", str(out)])
        assert res.exit_code == 0, res.output
        outs.append((out / "peaks.csv").read_text())
    assert outs[0] == outs[1]


def test_synthesize_tree_bad_type_file(tmp_path, small_type):
    data = small_type.to_dict()
    data["version"] = 99
    p = tmp_path / "old.json"
    p.write_text(json.dumps(data))
    res = CliRunner().invoke(cli, ["synthesize-tree", "--type", str(p), "-o", str(tmp_path / "o"), "--no-progress"])
    assert res.exit_code == 1 and "version 99" in res.output


def test_synthesize_tree_with_fixed_peaks_file(tmp_path, type_file):
    fixed = tmp_path / "fixed.csv"
    pd.DataFrame({"x": [3000.0], "y": [4000.0], "elevation": [2700.0]}).to_csv(fixed, index=False)
    out = tmp_path / "o"
    res = CliRunner().invoke(cli, ["synthesize-tree", "--type", str(type_file), "--size", "15km", "--peaks", str(fixed),
                                   "--seed", "1", "--no-progress", "-o", str(out)])
    assert res.exit_code == 0, res.output
    peaks = pd.read_csv(out / "peaks.csv")
    top = peaks.loc[peaks["elevation"].idxmax()]
    assert (top["x"], top["y"], top["elevation"]) == (3000.0, 4000.0, 2700.0)


def test_type_from_analysis_folder_with_edit(tmp_path, make_dem):
    from orokit.analysis import analyze

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:96, 0:96]
    z = np.zeros((96, 96))
    for _ in range(60):
        cy, cx, h, w = rng.uniform(0, 96), rng.uniform(0, 96), rng.uniform(50, 400), rng.uniform(2, 6)
        z += h * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * w**2))
    write_analysis(analyze(make_dem(z + 100.0, res=50.0), min_prominence_m=30.0), tmp_path / "ana")
    out = tmp_path / "t.json"
    res = CliRunner().invoke(cli, ["type", str(tmp_path / "ana"), "-o", str(out), "--scale-prominence", "2"])
    assert res.exit_code == 0, res.output
    t = load_terrain_type(out)
    assert t.histograms["prominence"].edges[0] == pytest.approx(60.0)
    assert t.provenance["area_km2"] == pytest.approx(96 * 96 * 0.05**2, rel=1e-6)
    assert any("scale prominence" in e for e in t.provenance["edits"])


@pytest.mark.realdata
def test_type_from_reference_tree_and_fidelity(tmp_path, real_data):
    """A real region's type, synthesized back: orometry within the paper's error bounds."""
    from orokit.synthesis.fidelity import compare_to_type
    from orokit.synthesis.tree import synthesize_divide_tree

    from orokit.data import load_manifest

    txt = real_data("dems/appalachians.txt")
    cell = load_manifest()["appalachians"].cell_size_m  # the manifest knows the cell size
    out = tmp_path / "app.json"
    res = CliRunner().invoke(cli, ["type", str(txt), "-o", str(out), "--cell-size", str(cell)])
    assert res.exit_code == 0, res.output
    t = load_terrain_type(out)
    assert t.provenance["area_km2"] == pytest.approx((648 * cell) ** 2 / 1e6, rel=0.02)
    tree = synthesize_divide_tree(t, size_m=50_000, rng=0)
    tree.validate()
    err = compare_to_type(tree, t)["max_bin_error"]
    assert err["prominence"] < 0.03 and err["dominance"] < 0.03
    assert err["isolation_distance"] < 0.08
    assert err["saddle_distance"] < 0.04 and err["saddle_direction"] < 0.04


def test_synthesis_report_table(tmp_path, type_file):
    dirs = []
    for name, seed in (("a", "1"), ("b", "2")):
        out = tmp_path / name
        res = CliRunner().invoke(cli, ["synthesize-tree", "--type", str(type_file), "--size", "12km", "--seed", seed,
                                       "--no-progress", "-o", str(out)])
        assert res.exit_code == 0, res.output
        dirs.append(str(out))
    md = tmp_path / "R.md"
    res = CliRunner().invoke(cli, ["synthesis-report", *dirs, "-o", str(md)])
    assert res.exit_code == 0, res.output
    text = md.read_text()
    meta = json.loads((tmp_path / "a" / "synthesis.json").read_text())
    assert f"| a | {meta['n_peaks']} |" in text
    prom = next(f for f in meta["fidelity"] if f["feature"] == "prominence")["max_bin_error"]
    assert f"{prom:.4f}" in text
    assert "(s)" not in text  # timings change with the load: not in the committed page
    timings = pd.read_csv(tmp_path / "timings.csv")
    assert list(timings["type"]) == ["a", "b"] and (timings["seconds"] > 0).all()
    assert CliRunner().invoke(cli, ["synthesis-report", *dirs, "-o", str(md)]).exit_code != 0


def test_type_from_dem_file(tmp_path, make_dem):
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[0:80, 0:80]
    z = np.full((80, 80), 200.0)
    for _ in range(50):
        cy, cx, h, w = rng.uniform(0, 80), rng.uniform(0, 80), rng.uniform(50, 300), rng.uniform(2, 5)
        z += h * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * w**2))
    tif = tmp_path / "dem.tif"
    make_dem(z.astype("float32"), res=60.0).rio.to_raster(tif)
    out = tmp_path / "t.json"
    res = CliRunner().invoke(cli, ["type", str(tif), "-o", str(out), "--shift-elevation", "1000"])
    assert res.exit_code == 0, res.output
    t = load_terrain_type(out)
    assert t.name == "dem"
    assert t.histograms["elevation"].edges[0] >= 1000.0
    assert t.provenance["area_km2"] == pytest.approx(80 * 80 * 0.06**2, rel=1e-6)


def _bumps(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:n, 0:n]
    z = np.full((n, n), 200.0)
    for _ in range(50):
        cy, cx, h, w = rng.uniform(0, n), rng.uniform(0, n), rng.uniform(50, 300), rng.uniform(2, 5)
        z += h * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * w**2))
    return z.astype("float32")


def test_type_min_prominence_zero_is_kept(tmp_path, make_dem):
    """--min-prominence 0 is a threshold, not "use the default" (review B3)."""
    tif = tmp_path / "dem.tif"
    make_dem(_bumps(60, 2), res=60.0).rio.to_raster(tif)
    out = tmp_path / "t.json"
    res = CliRunner().invoke(cli, ["type", str(tif), "-o", str(out), "--min-prominence", "0", "--z-units", "m"])
    assert res.exit_code == 0, res.output
    t = load_terrain_type(out)
    assert t.min_prominence_m == 0.0
    assert json.loads(out.read_text())["min_prominence_m"] == 0.0
    # peaks below 30 m of prominence are counted: the prominence histogram starts at 0
    assert t.histograms["prominence"].edges[0] == 0.0


def test_type_min_prominence_zero_from_tree_file(tmp_path, small_type):
    from orokit.io.divide_tree_io import write_divide_tree_gpkg
    from orokit.synthesis.tree import synthesize_divide_tree

    tree = synthesize_divide_tree(small_type, size_m=12_000.0, rng=4)
    gpkg = tmp_path / "tree.gpkg"
    write_divide_tree_gpkg(tree, gpkg)
    out = tmp_path / "t.json"
    res = CliRunner().invoke(cli, ["type", str(gpkg), "-o", str(out), "--min-prominence", "0"])
    assert res.exit_code == 0, res.output
    assert load_terrain_type(out).min_prominence_m == 0.0


@pytest.mark.parametrize("size", ["1.2.3km", ".", "-5km", "0km", "90 miles", "x60km", "nan"])
def test_synthesize_tree_malformed_size_is_a_usage_error(tmp_path, type_file, size):
    out = tmp_path / "o"
    res = CliRunner().invoke(cli, ["synthesize-tree", "--type", str(type_file), "--size", size, "--no-progress",
                                   "-o", str(out)])
    assert res.exit_code == 2, res.output
    assert "--size" in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)
    assert "Traceback" not in res.output and not out.exists()


def test_length_parser_grammar():
    from click import BadParameter

    from orokit.cli.options import parse_length

    assert parse_length("30 m") == 30.0
    assert parse_length(".5km") == 500.0
    assert parse_length("2e3m") == 2000.0
    assert parse_length("9000 x 6000 m", pair=True) == (9000.0, 6000.0)
    assert parse_length("90x60KM", pair=True) == (90_000.0, 60_000.0)
    with pytest.raises(BadParameter, match="no unit"):
        parse_length("2500", allow_bare=False)
    with pytest.raises(BadParameter, match="did you mean"):
        parse_length("10", bare_min_m=100.0)
    for bad in ("1.2.3km", ".", "-5km", "0m", "1e999m", "5 k m", "90x60", "inf"):
        with pytest.raises(BadParameter):
            parse_length(bad, allow_bare=False, pair="x" in bad)
