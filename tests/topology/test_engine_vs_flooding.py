"""The exact engine against an explicit flooding oracle on tiny grids with many ties.

Peaks, key-saddle elevations, prominences, parents, roots and the ``prominence_exact``
flag of ``orokit.analyze`` are compared with :func:`brute_prominence`, which floods the
superlevel sets level by level (see ``helpers/orometry_oracles.py`` for the conventions).
"""
from __future__ import annotations

import numpy as np
import pytest
from helpers.orometry_oracles import brute_prominence, flat_domain_cells, grids, make_dem, n_domains
from hypothesis import example, given, settings
from hypothesis import strategies as st

import orokit

# grids pinned as examples (found while writing the oracles)
NAN_SPLIT = np.array(
    [[0, 1, np.nan, 1], [1, 1, 1, 1], [0, 0, 1, 0], [np.nan, np.nan, 1, np.nan], [1, np.nan, 2, 1]], np.float32
)
EQUAL_PEAKS = np.array([[5, 1, 5], [1, 1, 1], [5, 1, 5]], np.float32)


def _analyze(z, **kw):
    return orokit.analyze(make_dem(z), isolation=False, **kw)


def _oracle(z):
    """Oracle peaks except those of entirely flat domains (tested apart)."""
    flat = flat_domain_cells(z).ravel()
    return [p for p in brute_prominence(z) if not flat[p.rep]]


def _higher(a, b) -> bool:
    """True if peak a counts higher than peak b (elevation, then raster order)."""
    return (a.elevation > b.elevation) or (a.elevation == b.elevation and a.rep < b.rep)


def check_against_flooding(z: np.ndarray, outside: str = "unknown") -> None:
    z = np.asarray(z, np.float32)
    h, w = z.shape
    peaks = _analyze(z, min_prominence_m=0.0, outside=outside).peaks
    oracle = _oracle(z.astype(np.float64))
    by_rc = {(p.row, p.col): p for p in oracle}
    got = list(zip(peaks["row"].astype(int), peaks["col"].astype(int)))
    assert sorted(got) == sorted(by_rc), f"peak cells differ for\n{z!r}"
    assert peaks.index.is_unique
    rc_of_id = dict(zip(peaks.index, got))
    for pid, row in peaks.iterrows():
        p = by_rc[(int(row["row"]), int(row["col"]))]
        assert row["elevation"] == p.elevation
        assert row["x"] == pytest.approx(500000.0 + 10.0 * (p.col + 0.5))
        assert row["y"] == pytest.approx(5000000.0 - 10.0 * (p.row + 0.5))
        if p.is_root:
            assert row["prominence"] == p.elevation, f"root {p.row, p.col} of\n{z!r}"
            assert np.isnan(row["saddle_elevation"]) and np.isnan(row["saddle_x"])
            assert row["island_parent"] == -1
            assert bool(row["prominence_exact"]) == (outside == "sea")
            continue
        assert row["saddle_elevation"] == p.saddle, f"key saddle of {p.row, p.col} in\n{z!r}"
        assert row["prominence"] == pytest.approx(p.elevation - p.saddle, abs=1e-9)
        # the reported saddle cell is at the saddle height, on P's superlevel component
        sr, sc = int(row["saddle_row"]), int(row["saddle_col"])
        assert 0 <= sr < h and 0 <= sc < w
        assert z[sr, sc] == p.saddle
        assert p.component[sr, sc]
        # the parent counts higher than P and is reachable above the saddle
        par = int(row["island_parent"])
        assert par in rc_of_id, f"parent {par} of {p.row, p.col} is not a peak"
        q = by_rc[rc_of_id[par]]
        assert (int(row["island_parent_row"]), int(row["island_parent_col"])) == (q.row, q.col)
        assert _higher(q, p)
        assert p.component.ravel()[q.rep]
        expected_exact = True if outside == "sea" else p.exact
        assert bool(row["prominence_exact"]) == expected_exact, f"prominence_exact of {p.row, p.col} in\n{z!r}"
    roots = peaks[peaks["island_parent"] == -1]
    assert len(roots) == n_domains(np.where(flat_domain_cells(z), np.nan, z))


@settings(max_examples=200, deadline=None)
@given(z=grids(10))
@example(z=NAN_SPLIT)
@example(z=EQUAL_PEAKS)
def test_prominence_matches_flooding(z):
    check_against_flooding(z)


@settings(max_examples=60, deadline=None)
@given(z=grids(8))
def test_outside_sea_only_changes_flags(z):
    check_against_flooding(z, outside="sea")


@settings(max_examples=100, deadline=None)
@given(z=grids(9, nan=False), eps=st.sampled_from([0.5, 1.0, 3.0, 10.0, 100.0]))
def test_threshold_keeps_exactly_the_prominent(z, eps):
    oracle = _oracle(z.astype(np.float64))
    peaks = _analyze(z, min_prominence_m=eps).peaks
    expected = {(p.row, p.col) for p in oracle if p.prominence >= eps}
    roots = [p for p in oracle if p.is_root]
    if expected and roots:  # one domain (no NaN): its root is kept with any kept peak
        expected |= {(p.row, p.col) for p in roots}
    expected = sorted(expected)
    assert sorted(zip(peaks["row"].astype(int), peaks["col"].astype(int))) == expected


def test_equal_height_peaks_first_in_raster_order_is_higher():
    peaks = _analyze(EQUAL_PEAKS, min_prominence_m=0).peaks.set_index(["row", "col"])
    assert peaks.loc[(0, 0), "island_parent"] == -1
    assert peaks.loc[(0, 0), "prominence"] == 5
    for rc in [(0, 2), (2, 0), (2, 2)]:
        assert peaks.loc[rc, "prominence"] == 4
        assert peaks.loc[rc, "saddle_elevation"] == 1


def test_plateau_reported_at_first_cell_in_raster_order():
    z = np.array([[1, 1, 1, 1, 1, 1], [1, 1, 4, 4, 1, 1], [1, 4, 4, 1, 1, 1], [1, 1, 1, 1, 1, 2]], np.float32)
    peaks = _analyze(z, min_prominence_m=0).peaks
    top = peaks[peaks["elevation"] == 4]
    assert list(zip(top["row"], top["col"])) == [(1, 2)]
    low = peaks[peaks["elevation"] == 2]
    assert list(zip(low["row"], low["col"])) == [(3, 5)]
    assert low["prominence"].iloc[0] == 1.0


def test_nan_never_carries_a_path():
    # two summits separated only by a NaN column: two domains, two roots
    z = np.array([[1, 5, np.nan, 6, 1], [1, 2, np.nan, 2, 1]], np.float32)
    peaks = _analyze(z, min_prominence_m=0).peaks
    assert sorted(peaks["prominence"]) == [5.0, 6.0]
    assert (peaks["island_parent"] == -1).all()


def test_root_below_threshold_with_prominent_child():
    # root (0, 0) has prominence = elevation = 0 < eps; peak (0, 2) has prominence 1 >= eps:
    # the root is kept as the parent of a kept peak
    z = np.array([[0, -1, 0]], np.float32)
    peaks = _analyze(z, min_prominence_m=0.5).peaks
    assert list(zip(peaks["row"], peaks["col"], peaks["prominence"], peaks["island_parent"])) == [(0, 0, 0.0, -1), (0, 2, 1.0, 0)]
    assert peaks["saddle_elevation"].iloc[1] == -1.0
