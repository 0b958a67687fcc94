"""The ranking table: one run per process, failures recorded, ranks, report files."""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from orokit.cli.main import cli
from orokit.reports.generators import METRICS, ranking_markdown, ranking_tables

from helpers.trees import small_tree


def _run(gen, seed, region="alpha", failed=False, **values):
    r = {"generator": gen, "region": region, "seed": seed, "failed": failed}
    if failed:
        r["error"] = "boom"
        return r
    base = {k: 0.5 for k in METRICS if not k.startswith("landform.")}
    base["landform"] = {k.split(".", 1)[1]: 1.0 for k in METRICS if k.startswith("landform.")}
    base.update(values)
    r.update(base)
    return r


def test_ranks_follow_the_direction_of_each_metric_and_failures_rank_last():
    runs = [_run("a", s, recovered_share=0.9, extra_share=0.1) for s in (0, 1)]
    runs += [_run("b", s, recovered_share=0.2, extra_share=0.3) for s in (0, 1)]
    runs += [_run("c", 0, failed=True), _run("c", 1, failed=True)]
    per_run, agg, mean_rank = ranking_tables(runs)
    assert len(per_run) == 6 and per_run["failed"].sum() == 2
    assert agg.loc[("alpha", "a"), ("recovered_share", "mean")] == pytest.approx(0.9)
    assert list(mean_rank.index) == ["a", "b", "c"]
    # c failed everywhere: last on every metric (rank 3)
    assert mean_rank["c"] == pytest.approx(3.0)
    md = ranking_markdown(runs)
    assert "| c | alpha" not in md and "| alpha | c | 0 | boom |" in md


def test_mean_and_range_over_seeds():
    runs = [_run("a", s, wall_s=float(s + 1)) for s in range(3)]
    _, agg, _ = ranking_tables(runs)
    row = agg.loc[("alpha", "a")]
    assert (row[("wall_s", "mean")], row[("wall_s", "min")], row[("wall_s", "max")]) == (2.0, 1.0, 3.0)
    assert "2 [1–3]" in ranking_markdown(runs)
    assert "Seeds 1 and 2 missing." in ranking_markdown(runs, note="Seeds 1 and 2 missing.")


def test_landform_targets_met_are_counted_per_generator_and_statistic():
    def run(gen, seed, slope, flat):
        r = _run(gen, seed)
        r["landform"] = {"slope_deg": slope, "flat_share": flat}
        r["landform_target"] = {"slope_deg": 4.0, "flat_share": 0.06}
        return r

    runs = [run("a", 0, 3.0, 0.1), run("a", 1, 4.0, 0.01), run("a", 2, 5.0, 0.2), run("b", 0, 9.0, 0.0),
            _run("b", 1, failed=True)]
    from orokit.reports.generators import landform_target_counts

    met = landform_target_counts(runs)
    assert met.loc["a", "slope_deg"] == "2/3" and met.loc["a", "flat_share"] == "1/3"
    assert met.loc["b", "slope_deg"] == "0/1" and met.loc["b", "flat_share"] == "1/1"
    assert "| a | 2/3 | 1/3 |" in ranking_markdown(runs)


def test_landform_targets_met_are_counted_per_region():
    def run(gen, region, seed, slope):
        r = _run(gen, seed, region=region)
        r["landform"] = {"slope_deg": slope}
        r["landform_target"] = {"slope_deg": 4.0}
        return r

    runs = [run("a", "norway", 0, 3.0), run("a", "norway", 1, 5.0), run("a", "nepal", 0, 1.0),
            run("a", "sahara", 0, 9.0), run("b", "sahara", 0, 2.0)]
    from orokit.reports.generators import landform_target_counts_by_region

    table, tags = landform_target_counts_by_region(runs)
    assert tags == {"nepal": "Ne", "norway": "No", "sahara": "S"}
    assert table.loc["a", "slope_deg"] == "Ne1 No1 S0" and table.loc["b", "slope_deg"] == "S1"
    md = ranking_markdown(runs)
    assert "Ne = nepal (1 seeds), No = norway (2 seeds), S = sahara (1 seeds)" in md
    assert "| a | Ne1 No1 S0 |" in md


def test_landform_status_tells_met_fixable_and_method_bound(monkeypatch):
    def run(seed, region, slope, flat):
        r = _run("michel", seed, region=region)
        r["backend"] = "michel"
        r["landform"] = {"slope_deg": slope, "flat_share": flat}
        r["landform_target"] = {"slope_deg": 4.0, "flat_share": 0.06}
        return r

    from orokit.reports import generators as rep

    monkeypatch.setattr(rep, "METHOD_BOUND", {"michel": {"flat_share@sahara": "the plain is flat by design"},
                                              "*": {"slope_deg@norway": "target: too tight"}})
    runs = [run(0, "norway", 3.0, 0.01), run(1, "norway", 5.0, 0.02), run(0, "sahara", 1.0, 0.2),
            run(1, "sahara", 2.0, 0.3)]
    table = rep.landform_status(runs, "michel")
    assert table.loc["slope_deg", "sahara"] == "met 2/2"
    assert table.loc["slope_deg", "norway"] == "target 1/2 (4 vs 4)"  # mean distance 4.0, one run over
    assert table.loc["flat_share", "norway"] == "met 2/2"
    assert table.loc["flat_share", "sahara"] == "method 0/2 (0.25 vs 0.06)"
    md = rep.ranking_markdown(runs)
    assert "### michel" in md and "- `flat_share`: the plain is flat by design" in md and "- `slope_deg`: too tight" in md
    runs[2]["landform"]["flat_share"] = 0.01  # the other region: not listed, so fixable
    runs[0]["landform"]["flat_share"] = 0.5
    table = rep.landform_status(runs, "michel")
    assert table.loc["flat_share", "norway"] == "fixable 1/2 (0.26 vs 0.06)"


def test_landform_status_reads_the_label_before_the_backend(monkeypatch):
    from orokit.reports import generators as rep

    def run(label, seed):
        r = _run(label, seed, region="norway")
        r["backend"] = "guerin"
        r["landform"] = {"curvature_per_km": 2.0}
        r["landform_target"] = {"curvature_per_km": 1.0}
        return r

    monkeypatch.setattr(rep, "METHOD_BOUND", {"guerin-cross": {"curvature_per_km@norway": "another region's texture"}})
    runs = [run("guerin", 0), run("guerin-cross", 0)]
    assert rep.landform_status(runs, "guerin-cross").loc["curvature_per_km", "norway"] == "method 0/1 (2 vs 1)"
    assert rep.landform_status(runs, "guerin").loc["curvature_per_km", "norway"] == "fixable 0/1 (2 vs 1)"
    md = rep.ranking_markdown(runs)
    assert md.count("another region's texture") == 1


@pytest.fixture()
def setup(tmp_path):
    """A tree file and a 'real' DEM of its domain (a smooth bump) at 100 m."""
    from affine import Affine

    from orokit.generators.base import as_dataarray
    from orokit.io.divide_tree_io import write_divide_tree_gpkg
    from orokit.io.raster_io import write_cog
    from orokit.raster.rasterize import make_grid
    from orokit.synthesis.terrain_type import TerrainType

    tree = small_tree(crs="EPSG:32633")
    write_divide_tree_gpkg(tree, tmp_path / "tree.gpkg")
    grid = make_grid((0.0, 0.0, 8000.0, 8000.0), 100.0)
    x, y = grid.centres()
    z = 900 + 500 * np.exp(-((x[None, :] - 3000) ** 2 + (y[:, None] - 4000) ** 2) / 2e6)
    real = as_dataarray(z, grid, "EPSG:32633")
    assert real.rio.transform() == Affine(100.0, 0, 0, 0, -100.0, 8000.0)
    write_cog(real, tmp_path / "real.tif")
    TerrainType.from_divide_tree(tree, area_km2=64.0, min_prominence_m=30.0, name="real").save(tmp_path / "type.json")
    return tmp_path


@pytest.mark.slow
def test_generators_run_records_a_run_and_a_failure_then_reports(setup, tmp_path):
    tmp = setup
    common = ["generators-run", "--tree", str(tmp / "tree.gpkg"), "--type", str(tmp / "type.json"),
              "--like", str(tmp / "real.tif"), "--seed", "1"]
    r = CliRunner().invoke(cli, common + ["--generator", "belhadj", "-o", str(tmp / "b" / "result.json")])
    assert r.exit_code == 0, r.output
    res = json.loads((tmp / "b" / "result.json").read_text())
    assert not res["failed"], res
    assert res["tree_peaks"] >= 1 and 0 <= res["recovered_share"] <= 1
    assert res["shape"] == res["real_shape"] == "80x80"
    assert res["peak_rss_gb"] > 0.05 and res["wall_s"] > 0
    assert set(res["landform"]) >= {"slope_deg", "hypsometry", "spectral_slope"}
    assert (tmp / "b" / "dem.tif").exists() and (tmp / "b" / "hillshade.png").exists()
    # an out-of-range parameter fails in the child process: recorded, not raised
    r = CliRunner().invoke(cli, common + ["--generator", "belhadj", "--param", "hurst=7",
                                          "-o", str(tmp / "f" / "result.json")])
    assert r.exit_code == 0, r.output
    bad = json.loads((tmp / "f" / "result.json").read_text())
    assert bad["failed"] and bad["stage"] == "render" and "hurst" in bad["error"]
    out = tmp / "rep" / "README.md"
    r = CliRunner().invoke(cli, ["generators-report", str(tmp / "b" / "result.json"), str(tmp / "f" / "result.json"),
                                 "-o", str(out)])
    assert r.exit_code == 0, r.output
    text = out.read_text()
    assert "Mean rank" in text and "hurst" in text
    assert (out.parent / "README.csv").exists()
