"""Bad and degenerate inputs of ``orokit.analyze``: flats, tiny shapes, NaN, int16."""
from __future__ import annotations

import numpy as np
import pytest
from helpers.orometry_oracles import brute_prominence, make_dem

import orokit
from orokit.errors import InputError

# Contract (issue 4, "bad input"): an entirely flat domain of valid cells has no relief and
# therefore no peak; all-flat rasters give empty tables.


@pytest.mark.parametrize("shape", [(1, 1), (5, 7)])
def test_flat_raster_has_no_peak(shape):
    z = np.full(shape, 7.0, np.float32)
    result = orokit.analyze(make_dem(z), min_prominence_m=0)
    assert len(result.peaks) == 0 and len(result.saddles) == 0
    assert result.tree.n_peaks == 0


def test_isolated_cell_is_a_flat_domain():
    # the single cell 5 is cut off by NaN: a flat domain, no peak; the other domain keeps its root
    z = np.array([[5, np.nan, 1, 2]], np.float32)
    peaks = orokit.analyze(make_dem(z), min_prominence_m=0).peaks
    assert sorted(zip(peaks["col"], peaks["prominence"])) == [(3, 2.0)]


@pytest.mark.parametrize("shape", [(1, 1), (4, 6)])
def test_flat_raster_does_not_crash(shape):
    z = np.full(shape, 7.0, np.float32)
    res = orokit.analyze(make_dem(z), min_prominence_m=0)
    assert len(res.peaks) <= 1
    assert set(orokit.analysis.PEAK_COLUMNS) <= set(res.peaks.columns)
    res.tree.validate()


def test_all_nan_is_a_clear_error():
    z = np.full((4, 4), np.nan, np.float32)
    with pytest.raises(InputError, match="valid"):
        orokit.analyze(make_dem(z))


@pytest.mark.parametrize("row", [[1.0, 3.0, 2.0, 5.0, 4.0, 4.0, 0.0], [2.0, 1.0, 2.0], [0.0, 9.0]])
def test_one_by_n_and_n_by_one(row):
    z = np.array([row], np.float32)
    expected = sorted((p.col, p.prominence) for p in brute_prominence(z.astype(np.float64)))
    for arr, key in ((z, "col"), (z.T.copy(), "row")):
        peaks = orokit.analyze(make_dem(arr), min_prominence_m=0).peaks
        assert sorted(zip(peaks[key].astype(int), peaks["prominence"])) == expected


def test_int16_extremes_do_not_overflow():
    z = np.array([[32767, -32768, 32766], [-32768, -32768, -32768]], np.int16)
    peaks = orokit.analyze(make_dem(z), min_prominence_m=0).peaks.set_index(["row", "col"])
    assert peaks.loc[(0, 2), "prominence"] == 65534.0
    assert peaks.loc[(0, 2), "saddle_elevation"] == -32768.0
    assert peaks.loc[(0, 0), "prominence"] == 32767.0


def test_uint16_feet_like_input():
    z = np.array([[7750, 28994, 7750, 0, 100]], np.uint16)
    peaks = orokit.analyze(make_dem(z), min_prominence_m=0).peaks.set_index("col")
    assert peaks.loc[1, "prominence"] == 28994.0
    assert peaks.loc[4, "prominence"] == 100.0


def test_huge_plateau_is_one_peak():
    """A 250,000-cell summit plateau is one peak (at its first cell in raster order); no timed assertion
    (the machine's load decides a wall time)."""
    z = np.zeros((600, 600), np.float32)
    z[50:550, 60:560] = 10.0          # 250 000-cell summit plateau
    z[580, 590] = 3.0                  # a small separate summit
    peaks = orokit.analyze(make_dem(z), min_prominence_m=0).peaks
    assert sorted(zip(peaks["row"], peaks["col"], peaks["prominence"])) == [(50, 60, 10.0), (580, 590, 3.0)]


@pytest.mark.parametrize("bad", [np.inf, -np.inf])
def test_infinite_cell_is_refused_beside_nodata(bad):
    """The engine's check of infinite cells (reductions that skip NaN) finds one among NaN cells."""
    from orokit.topology.engine import saddle_graph

    z = np.array([[np.nan, 1, 2], [3, np.nan, 4]], np.float32)
    saddle_graph(z)  # finite cells and NaN: accepted
    z[1, 2] = bad
    with pytest.raises(InputError, match="infinite"):
        saddle_graph(z)
