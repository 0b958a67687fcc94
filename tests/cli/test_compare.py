"""``orokit compare`` and the peak-list matcher (issue 16)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import orokit
from orokit.cli.main import cli
from orokit.io.analysis_io import write_analysis
from orokit.io.kirmse_io import kirmse_columns, write_kirmse_peaks
from orokit.io.peak_lists import read_peak_list
from orokit.metrics.peak_match import compare_peak_lists, match_peaks


def _table(rows, cols, z, q, lp=None, pp=None):
    n = len(z)
    return pd.DataFrame({"lat": np.nan, "lon": np.nan, "row": rows, "col": cols, "x": np.nan, "y": np.nan,
                         "elevation": z, "prominence": q,
                         "line_parent": lp if lp is not None else [-1] * n,
                         "prominence_parent": pp if pp is not None else [-1] * n})


def test_match_is_one_to_one_closest_first():
    ia, ib, d = match_peaks(np.array([[0, 0], [0, 1]], float), np.array([[0, 0.9]], float), 1.0)
    assert ia.tolist() == [1] and ib.tolist() == [0] and d[0] == pytest.approx(0.1)


def test_compare_small_tables_by_hand():
    a = _table([0, 10, 20, 30], [0, 10, 20, 30], [100, 90, 80, 70], [100, 30, 20, 10], lp=[-1, 0, 1, 0],
               pp=[-1, 0, 0, 0])
    b = _table([0, 11, 20, 50], [0, 10, 20, 50], [100, 90, 80.5, 60], [100, 30, 20, 5], lp=[-1, 0, 0, 0],
               pp=[-1, 0, 0, 0])
    s, pairs = compare_peak_lists(a, b, max_cells=1.5)
    assert s["matched"] == 3 and s["location_precision"] == 0.75 and s["location_recall"] == 0.75
    assert s["matched_values_agree"] == pytest.approx(2 / 3)
    assert s["value_precision"] == 0.5  # (100, 100) and (90, 30)
    assert s["line_parent_compared"] == 2 and s["line_parent_agree"] == 0.5  # peak 2: 1 vs 0
    assert s["prominence_parent_agree"] == 1.0
    assert sorted(pairs["status"]) == ["extra", "matched", "matched", "matched", "missing"]


def test_cli_compare_analysis_with_itself_and_kirmse_list(make_dem, tmp_path):
    rng = np.random.default_rng(8)
    z = rng.normal(size=(80, 70)).cumsum(0).cumsum(1)
    r = orokit.analyze(make_dem(z, res=0.0005, crs="EPSG:4326"), min_prominence_m=3, isolation=False)
    write_analysis(r, tmp_path / "a")
    write_kirmse_peaks(kirmse_columns(r.peaks), tmp_path / "results.txt")
    res = CliRunner().invoke(cli, ["compare", str(tmp_path / "a"), str(tmp_path / "a"), "--csv",
                                   str(tmp_path / "c.csv")])
    assert res.exit_code == 0, res.output
    assert "location precision / recall" in res.output and "100.0 % / 100.0 %" in res.output
    assert "line parent agrees" in res.output
    pairs = pd.read_csv(tmp_path / "c.csv")
    assert (pairs["status"] == "matched").all() and len(pairs) == len(r.peaks)
    res = CliRunner().invoke(cli, ["compare", str(tmp_path / "results.txt"), str(tmp_path / "a"),
                                   "--distance", "5m"])
    assert res.exit_code == 0, res.output
    k = read_peak_list(tmp_path / "results.txt")
    s, _ = compare_peak_lists(k, read_peak_list(tmp_path / "a"), max_distance_m=5)
    assert s["location_recall"] == 1.0 and s["matched_values_agree"] == 1.0
    again = CliRunner().invoke(cli, ["compare", str(tmp_path / "a"), str(tmp_path / "a"), "--csv",
                                     str(tmp_path / "c.csv")])
    assert again.exit_code == 2 and "--overwrite" in again.output


def test_cli_compare_bad_input(tmp_path):
    p = tmp_path / "x.foo"
    p.write_text("1")
    res = CliRunner().invoke(cli, ["compare", str(p), str(p)])
    assert res.exit_code != 0 and "unknown peak list format" in res.output



@pytest.mark.parametrize("name, text, says", [
    ("a.csv", "a,b\n", "no peak_id column"),                               # was pandas' "unsupported operand"
    ("b.csv", "peak_id,x\n0,1\n", "no y column"),
    ("c.csv", "peak_id,x,y\n0,1,2\n", "no elevation or prominence column"),  # was "NoneType has no len()"
    ("d.csv", "peak_id,x,y,elevation,prominence\n0,1,2,high,3\n", "not numeric"),
    ("e.parquet", "junk", "not a readable peaks table"),
    ("f.csv", b"\xff\xfe\x00bin", "not a readable peaks table"),
])
def test_cli_compare_a_table_that_is_no_peak_list(tmp_path, name, text, says):
    """A CSV or Parquet file that is not a peaks table: one line naming the file and what it lacks, exit 1
    (a traceback before)."""
    p = tmp_path / name
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    res = CliRunner().invoke(cli, ["compare", str(p), str(p), "--no-progress"])
    assert res.exit_code == 1 and res.exception is not None and isinstance(res.exception, SystemExit), res.output
    assert says in res.output and str(p) in res.output and "orokit analyze" in res.output


@pytest.mark.realdata
def test_reference_tree_against_orokit(real_data, tmp_path):
    """The paper's reference tree of gobi against orokit at eps 0 (benchmark: >= 97.6 % next to ours)."""
    from orokit.data import open_dataset_dem

    dem = open_dataset_dem("gobi")
    txt = real_data("dems/gobi.txt")
    write_analysis(orokit.analyze(dem, min_prominence_m=0, isolation=False), tmp_path / "ours")
    ref = read_peak_list(txt, cell_size_m=92.61, z_units="ft", height=dem.shape[0])
    s, _ = compare_peak_lists(read_peak_list(tmp_path / "ours"), ref, max_cells=1.5, z_tolerance_m=0.5)
    assert s["match_unit"] == "cells" and s["location_recall"] >= 0.97
    res = CliRunner().invoke(cli, ["compare", str(tmp_path / "ours"), str(txt), "--cell-size", "92.61m",
                                   "--tree-rows", str(dem.shape[0]), "--cells", "1.5"])
    assert res.exit_code == 0, res.output
    assert f"{100 * s['location_recall']:.1f} %" in res.output
