"""Depressions: the engine on -h, checked against sublevel persistence (cripser),
brute-force flooding for the areas, the peaks of h, and the chunked engine."""
from __future__ import annotations

import numpy as np
import pytest
from helpers.orometry_oracles import grids, make_dem, persistence_pairs
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

import orokit
from orokit.topology.depressions import DEPRESSION_COLUMNS, RENAME

CELL_M2 = 10.0 * 10.0  # the oracle make_dem: 10 m cells
WALK = {"spills_into", "spills_into_row", "spills_into_col", "depth_parent", "depth_parent_row", "depth_parent_col"}


def _dep(z, eps=0.0, **kw):
    return orokit.analyze(make_dem(np.ascontiguousarray(z)), min_prominence_m=eps, isolation=False,
                          depressions=True, **kw).depressions


def _brute_area(z, pit, spill):
    """Cells strictly below the spill elevation, 8-connected to the pit."""
    mask = np.nan_to_num(z, nan=np.inf) < z[spill]
    lab, _ = ndimage.label(mask, structure=np.ones((3, 3)))
    return float((lab == lab[pit]).sum()) * CELL_M2


@pytest.mark.slow
@settings(max_examples=150, deadline=None)
@given(z=grids(10), eps=st.sampled_from([0.0, 1.0, 5.0]))
def test_depths_are_sublevel_persistence(z, eps):
    dep = _dep(z, eps)
    assert list(dep.columns[:-1]) == DEPRESSION_COLUMNS and dep.index.name == "pit_id"
    fin, ess = persistence_pairs(-np.asarray(z, np.float64))  # superlevel of -z = sublevel of z
    exp = sorted((-b, -s) for b, s in fin if b - s >= eps)
    spilled = dep["spill_row"].to_numpy() >= 0
    got = sorted(zip(dep["elevation"].to_numpy()[spilled], dep["spill_elevation"].to_numpy()[spilled]))
    assert len(got) == len(exp)
    np.testing.assert_allclose(np.array(got).reshape(-1, 2), np.array(exp).reshape(-1, 2))
    depth = dep["depth"].to_numpy()
    np.testing.assert_allclose(depth[spilled], (dep["spill_elevation"] - dep["elevation"]).to_numpy()[spilled])
    assert np.isnan(depth[~spilled]).all()
    for i in np.flatnonzero(spilled):
        r = dep.iloc[i]
        pit, spill = (int(r["row"]), int(r["col"])), (int(r["spill_row"]), int(r["spill_col"]))
        assert r["area_m2"] == _brute_area(z, pit, spill)


@settings(max_examples=60, deadline=None)
@given(z=grids(9))
def test_depressions_of_minus_h_are_the_peaks_of_h(z):
    peaks = orokit.analyze(make_dem(z), min_prominence_m=0.0, isolation=False).peaks
    dep = _dep(-z)
    root = peaks["island_parent"].to_numpy() < 0
    renamed = peaks.drop(columns="geometry").rename(columns=RENAME)
    for col in DEPRESSION_COLUMNS:
        if col in ("area_m2",) or col not in renamed:
            continue
        a, b = renamed[col].to_numpy(), dep[col].to_numpy()
        if col in ("elevation", "spill_elevation"):
            a = -a
        if col == "depth":
            a, b = a[~root], b[~root]
        np.testing.assert_array_equal(a, b, err_msg=col)


def _same_tables(a, b):
    """Identical depressions tables; area_m2 summed in another order: equal within 1e-12 relative."""
    cols = [c for c in DEPRESSION_COLUMNS if c not in WALK and c != "area_m2"]
    assert a[cols].equals(b[cols])
    np.testing.assert_allclose(b["area_m2"].to_numpy(), a["area_m2"].to_numpy(), rtol=1e-12, atol=0)
    assert np.array_equal(np.isnan(a["area_m2"].to_numpy()), np.isnan(b["area_m2"].to_numpy()))


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(z=grids(12, min_side=2), chunk=st.integers(1, 5), eps=st.sampled_from([0.0, 2.0]),
       sea=st.sampled_from([{}, {"outside": "sea"}, {"sea_level_m": 0.0}, {"outside": "sea", "sea_level_m": 5.0}]))
def test_chunks_give_identical_depressions(z, chunk, eps, sea):
    """area_m2 included: with chunks it comes from the chunked pass (orokit.tiling.depression_area)."""
    a, b = _dep(z, eps, **sea), _dep(z, eps, chunks=chunk, **sea)
    _same_tables(a, b)


def test_chunked_areas_on_a_lon_lat_grid():
    """Row areas shrink with latitude; the chunked pass weighs each row as the in-memory one."""
    rng = np.random.default_rng(5)
    z = np.round(rng.normal(size=(60, 70)).cumsum(0).cumsum(1) / 3).astype(np.float32)
    z[rng.random(z.shape) < 0.03] = np.nan
    dem = make_dem(z, res=(0.01, 0.01), crs="EPSG:4326", x0=10.0, y0=62.0)
    a = orokit.analyze(dem, min_prominence_m=1.0, isolation=False, depressions=True).depressions
    b = orokit.analyze(dem, min_prominence_m=1.0, isolation=False, depressions=True, chunks=(17, 23)).depressions
    area = a["area_m2"].to_numpy()
    assert len(a) > 10 and np.isfinite(area).sum() > 10
    assert len(np.unique(area[np.isfinite(area)] / 1e4)) > 5  # not all one-cell lakes
    _same_tables(a, b)


def test_sea_outside_and_sea_level():
    z = np.array([[5, 5, 5, 5, 5, 5],
                  [5, 1, 3, 5, 2, 5],
                  [5, 3, 3, 5, 5, 5],
                  [5, 5, 5, 4, 0, 5],
                  [5, 5, 5, 5, 5, 5]], np.float32)
    d = _dep(z)
    assert d[["row", "col"]].values.tolist() == [[1, 1], [1, 4], [3, 4]]
    assert d["depth"].tolist()[:2] == [3.0, 3.0] and np.isnan(d["depth"].iloc[2])
    assert d["area_m2"].tolist()[:2] == [4 * CELL_M2, CELL_M2]
    # the 2 m pit overflows into the 1 m pit's basin (deeper): that is where it spills
    assert d["spills_into"].tolist() == [2, 0, -1]
    s = _dep(z, outside="sea")  # the deepest pit now spills over the rim into the sea
    assert s["depth"].tolist() == [3.0, 3.0, 5.0] and s["depth_exact"].all()
    assert s["area_m2"].iloc[2] == 6 * CELL_M2 and s["spills_into"].iloc[2] == -1
    # sea level 1: the 1 m pit and the 0 m pit are sea; the 2 m pit spills into it
    w = _dep(z, sea_level_m=1.0)
    assert w[["row", "col"]].values.tolist() == [[1, 4]]
    assert w["depth"].tolist() == [3.0] and w["spills_into"].tolist() == [-1]


def test_cli_writes_depressions(tmp_path):
    import pyogrio
    from click.testing import CliRunner

    from orokit.cli.main import cli
    from orokit.io.analysis_io import read_analysis
    from orokit.io.raster_io import write_cog

    rng = np.random.default_rng(3)
    z = (rng.normal(size=(40, 50)).cumsum(0).cumsum(1)).astype(np.float32)
    write_cog(make_dem(z), tmp_path / "dem.tif")
    out = tmp_path / "out"
    res = CliRunner().invoke(cli, ["analyze", str(tmp_path / "dem.tif"), "-o", str(out), "--min-prominence", "2",
                                   "--depressions", "--no-isolation", "--no-progress"])
    assert res.exit_code == 0, res.output
    back = read_analysis(out)
    expect = _dep(z, 2.0)
    assert len(back.depressions) == len(expect) > 3
    np.testing.assert_allclose(back.depressions["depth"], expect["depth"])
    layer = pyogrio.read_dataframe(out / "dividetree.gpkg", layer="depressions")
    assert len(layer) == len(expect) and "spills_into" in layer.columns
    res = CliRunner().invoke(cli, ["analyze", str(tmp_path / "dem.tif"), "-o", str(tmp_path / "o2"),
                                   "--sea-level", "0", "--no-progress"])
    assert res.exit_code != 0 and "depressions" in res.output
