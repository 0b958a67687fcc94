"""Kirmse's text formats (issue 16): peak lists and .dvt divide trees, round trips and errors."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from orokit.errors import DivideTreeError, InputError
from orokit.io.kirmse_io import (
    KIRMSE_PEAK_COLUMNS,
    kirmse_columns,
    read_kirmse_peaks,
    read_kirmse_tree,
    write_kirmse_peaks,
    write_kirmse_tree,
)
from orokit.topology.divide_tree import DivideTree

#: a .dvt as Kirmse's prominence program writes it (layout from its documentation)
DVT = """# Prominence divide tree generated at Mon Nov 30 12:00:00 2026
G,46.000000,7.000000,3600,3600,47.000000,8.000000
P,1,100,200,4000.00
P,2,130,260,3500.00
P,3,90,400,3800.00
S,1,p,115,230,3300.00
S,2,p,95,300,3100.00
N,0,-1,-1
N,1,-1,-1
N,2,1,1
N,3,1,2
"""


def test_read_dvt_by_hand(tmp_path):
    p = tmp_path / "t.dvt"
    p.write_text(DVT)
    t = read_kirmse_tree(p)
    assert t.n_peaks == 3 and t.n_saddles == 2
    assert sorted(map(tuple, t.edges[["peak_a", "peak_b", "saddle"]].to_numpy().tolist())) == [(1, 0, 0), (2, 0, 1)]
    np.testing.assert_allclose(t.peaks["lat"], 47 - np.array([200, 260, 400]) / 3600)
    np.testing.assert_allclose(t.peaks["lon"], 7 + np.array([100, 130, 90]) / 3600)
    table = t.prominence_table()
    np.testing.assert_allclose(table["prominence"], [4000, 200, 700])


def test_dvt_round_trip(tmp_path):
    p = tmp_path / "t.dvt"
    p.write_text(DVT)
    t = read_kirmse_tree(p)
    write_kirmse_tree(t, tmp_path / "u.dvt")
    u = read_kirmse_tree(tmp_path / "u.dvt")
    assert t.equals(u)
    pd.testing.assert_frame_equal(t.peaks, u.peaks)
    pd.testing.assert_frame_equal(t.saddles.drop(columns="type"), u.saddles.drop(columns="type"))


def test_dvt_round_trip_random_tree(tmp_path):
    rng = np.random.default_rng(4)
    n = 40
    z = rng.integers(100, 3000, n).astype(float)
    edges, sad = [], []
    for i in range(1, n):
        j = int(rng.integers(0, i))
        sad.append([int(rng.integers(0, 3600)), int(rng.integers(0, 3600)), float(min(z[i], z[j]) - rng.integers(0, 90))])
        edges.append([i, j, i - 1])
    peaks = np.column_stack([rng.integers(0, 3600, n), rng.integers(0, 3600, n), z])
    t = DivideTree.from_arrays(peaks, np.array(sad), np.array(edges), attrs={"kirmse_coordinate_system": DVT.splitlines()[1]})
    write_kirmse_tree(t, tmp_path / "r.dvt")
    u = read_kirmse_tree(tmp_path / "r.dvt")
    assert t.equals(u)
    np.testing.assert_allclose(t.prominence(), u.prominence())


def test_peak_list_round_trip(tmp_path):
    frame = pd.DataFrame({"lat": [46.5, 46.25], "lon": [7.125, 7.5], "elevation": [4000.0, 3500.0],
                          "saddle_lat": [np.nan, 46.3], "saddle_lon": [np.nan, 7.3], "prominence": [4000.0, 200.25]})
    write_kirmse_peaks(frame, tmp_path / "results.txt")
    text = (tmp_path / "results.txt").read_text()
    assert text.splitlines()[0] == "46.500000,7.125000,4000.00,0.000000,0.000000,4000.00"
    back = read_kirmse_peaks(tmp_path / "results.txt")
    pd.testing.assert_frame_equal(back, frame[KIRMSE_PEAK_COLUMNS])


def test_compute_parents_file(tmp_path):
    p = tmp_path / "parents.txt"
    p.write_text("# Prominence and line parents generated at x\nCommand line: compute_parents a b\n"
                 "46.1000,7.2000,46.1500,7.2500,3500.00,200.00,46.2000,7.3000,4000.00,46.3000,7.4000,3800.00\n")
    t = read_kirmse_peaks(p)
    assert t.loc[0, "elevation"] == 3500 and t.loc[0, "prominence"] == 200
    assert t.loc[0, "line_parent_elevation"] == 3800 and t.loc[0, "prominence_parent_prominence"] == 4000


@pytest.mark.parametrize("text, match", [
    ("1,2,3\n", "fields"),
    ("46,7,x,0,0,5\n", "numbers"),
    ("46,7,100,0,0,5\n46,7,100,0,0,5,1,2,3,4,5,6\n", "fields"),
])
def test_bad_peak_lists(tmp_path, text, match):
    p = tmp_path / "bad.txt"
    p.write_text(text)
    with pytest.raises(InputError, match=match) as err:
        read_kirmse_peaks(p)
    assert "bad.txt:" in str(err.value)


@pytest.mark.parametrize("edit, err, match", [
    (lambda s: s.replace("G,46.000000", "X,46.000000"), InputError, "coordinate-system"),
    (lambda s: s.replace("P,2,130,260,3500.00", "P,2,130,260"), InputError, "P record"),
    (lambda s: s.replace("N,3,1,2", "N,3,9,2"), DivideTreeError, "node 3"),
    (lambda s: s.replace("S,2,p,95,300,3100.00", "S,2,p,95,300,3900.00"), DivideTreeError, "above"),
])
def test_bad_dvt(tmp_path, edit, err, match):
    p = tmp_path / "bad.dvt"
    p.write_text(edit(DVT))
    with pytest.raises(err, match=match):
        read_kirmse_tree(p)


def test_orokit_analysis_to_results_txt(make_dem, tmp_path):
    import orokit

    rng = np.random.default_rng(2)
    z = rng.normal(size=(60, 50)).cumsum(0).cumsum(1)
    r = orokit.analyze(make_dem(z, res=0.001, crs="EPSG:4326"), min_prominence_m=5, isolation=False)
    k = kirmse_columns(r.peaks)
    write_kirmse_peaks(k, tmp_path / "results.txt")
    back = read_kirmse_peaks(tmp_path / "results.txt")
    np.testing.assert_allclose(back["prominence"], r.peaks["prominence"], atol=0.005)
    np.testing.assert_allclose(back["lat"], r.peaks["lat"], atol=1e-6)
    assert back["saddle_lat"].isna().sum() == (r.peaks["saddle_row"] < 0).sum()
