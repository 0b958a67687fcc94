"""Files that hold no valid Divide Tree are refused by every reader, in one place (issue 15).

Messages name the file and quote its own ids (1-based ``id`` of the TXT format)."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from orokit.cli.main import cli
from orokit.errors import DivideTreeError
from orokit.io.divide_tree_io import read_divide_tree_gpkg, read_divide_tree_txt, write_divide_tree_gpkg
from orokit.topology.divide_tree import DivideTree

C = 92.61


def _txt(path, saddle_ft=2600.0, extra_edge=None, peak3_ft=3000.0):
    """Three peaks (ids 1..3, feet) and two saddles (ids 1..2) on a 10-row grid."""
    lines = ["Peaks 3",
             f"1 {1 * 3 / 3600:.6f} {9 * 3 / 3600:.6f} 3300 1 9",
             f"2 {5 * 3 / 3600:.6f} {7 * 3 / 3600:.6f} 3100 5 7",
             f"3 {8 * 3 / 3600:.6f} {3 * 3 / 3600:.6f} {peak3_ft:g} 8 3",
             "PromSaddles 2",
             f"1 {3 * 3 / 3600:.6f} {8 * 3 / 3600:.6f} 2800 3 8",
             f"2 {7 * 3 / 3600:.6f} {5 * 3 / 3600:.6f} {saddle_ft:g} 7 5",
             f"Edges {2 + (extra_edge is not None)}", "1 2 1", "2 3 2"]
    if extra_edge:
        lines.append(extra_edge)
    path.write_text("\n".join(lines) + "\n")
    return path


def test_valid_txt_reads(tmp_path):
    t = read_divide_tree_txt(_txt(tmp_path / "ok.txt"))
    assert t.n_peaks == 3 and len(t.edges) == 2


def test_txt_saddle_above_its_peaks_names_file_and_1_based_ids(tmp_path):
    p = _txt(tmp_path / "bad.txt", saddle_ft=3200.0)
    with pytest.raises(DivideTreeError, match=r"bad.txt: saddle 2 \(975.36 m\) is above a peak of its ridge 2 "
                                              r"\(peak 2: 944.88 m, peak 3: 914.40 m\)"):
        read_divide_tree_txt(p)


@pytest.mark.parametrize("command", ["type", "render"])
def test_every_command_refuses_the_same_bad_tree(tmp_path, command):
    p = _txt(tmp_path / "bad.txt", saddle_ft=3200.0)
    args = {"type": ["type", str(p), "-o", str(tmp_path / "t.json")],
            "render": ["render", str(p), "-o", str(tmp_path / "r.tif"), "--no-erosion"]}[command]
    res = CliRunner().invoke(cli, args)
    assert res.exit_code == 1, res.output
    assert "bad.txt: saddle 2" in res.output and "Traceback" not in res.output
    assert [q.name for q in tmp_path.iterdir()] == ["bad.txt"]


def test_txt_cycle_quotes_file_ids(tmp_path):
    p = _txt(tmp_path / "cyc.txt", extra_edge="1 3 1")
    with pytest.raises(DivideTreeError, match=r"cyc.txt: 3 ridges for 3 peaks"):
        read_divide_tree_txt(p)


def test_gpkg_nan_elevation_and_saddle_above(tmp_path):
    good = DivideTree.from_arrays([[0.0, 0.0, 1000.0], [1000.0, 0.0, 900.0]], [[500.0, 0.0, 800.0]], [[0, 1, 0]])
    bad_saddle = DivideTree.from_arrays([[0.0, 0.0, 1000.0], [1000.0, 0.0, 900.0]], [[500.0, 0.0, 950.0]],
                                        [[0, 1, 0]])
    p = tmp_path / "t.gpkg"
    write_divide_tree_gpkg(good, p)
    assert read_divide_tree_gpkg(p).n_peaks == 2
    # the writer refuses nothing about elevations, so write the bad one through a patched check
    import orokit.topology.divide_tree as dt

    orig = dt.DivideTree.validate
    try:
        dt.DivideTree.validate = lambda self, **kw: None
        write_divide_tree_gpkg(bad_saddle, tmp_path / "above.gpkg")
        nan_tree = DivideTree.from_arrays([[0.0, 0.0, np.nan], [1000.0, 0.0, 900.0]], [[500.0, 0.0, 800.0]],
                                          [[0, 1, 0]])
        write_divide_tree_gpkg(nan_tree, tmp_path / "nan.gpkg")
    finally:
        dt.DivideTree.validate = orig
    with pytest.raises(DivideTreeError, match=r"above.gpkg: saddle 0 \(950.00 m\) is above a peak"):
        read_divide_tree_gpkg(tmp_path / "above.gpkg")
    with pytest.raises(DivideTreeError, match=r"nan.gpkg: peak 0 has elevation nan"):
        read_divide_tree_gpkg(tmp_path / "nan.gpkg")
