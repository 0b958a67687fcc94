"""Key-saddle features of a disk (relief, col ratio, saddle height) on analytic inputs (issue 12)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from orokit.classify.features import feature_table
from orokit.sampling.feature_sets import SADDLE_GROUPS, FeatureSet, disk_feature_vector, saddle_features

FS = dataclasses.replace(FeatureSet.orometry(), name="s", histograms=(), summaries=False, elevation=False,
                         saddles=True)


def _named(values: np.ndarray) -> dict[str, float]:
    return dict(zip(FS.columns, values))


def test_saddle_columns_follow_groups_and_round_trip():
    assert FS.columns == [c for cols in SADDLE_GROUPS.values() for c in cols]
    assert FeatureSet.from_dict(FS.to_dict()) == FS
    assert "saddles" not in dataclasses.replace(FS, saddles=False).to_dict()  # older tables and models compare equal


def test_one_massif_by_hand():
    """A 2000 m summit (prominence 1500: its col at 500 m is the disk's lowest) and three subpeaks on its flanks."""
    h = np.array([2000.0, 1500.0, 1200.0, 900.0])
    p = np.array([1500.0, 300.0, 100.0, 400.0])
    s = h - p  # 500, 1200, 1100, 500
    v = _named(saddle_features(h, p))
    assert v["relief_max_km"] == pytest.approx(1.5)  # 2000 - 500
    assert v["relief_median_km"] == pytest.approx((np.median(h) - np.median(s)) / 1000)
    assert v["relief_q90_q10_km"] == pytest.approx((np.quantile(h, 0.9) - np.quantile(s, 0.1)) / 1000)
    col = np.array([0.0, 700 / 1000, 600 / 700, 0.0])  # (s - 500) / (h - 500)
    height = np.array([0.0, 700 / 1500, 600 / 1500, 0.0])  # (s - 500) / (2000 - 500)
    for q in (25, 50, 75, 90):
        assert v[f"q{q}_col_ratio"] == pytest.approx(np.quantile(col, q / 100))
        assert v[f"q{q}_saddle_height"] == pytest.approx(np.quantile(height, q / 100))


def test_scale_invariance_of_the_ratios():
    """Doubling every elevation and prominence doubles the relief and keeps the ratios."""
    rng = np.random.default_rng(0)
    h = rng.uniform(800, 3000, 50)
    p = rng.uniform(30, 700, 50)
    a, b = _named(saddle_features(h, p)), _named(saddle_features(2 * h, 2 * p))
    for c in FS.columns:
        assert b[c] == pytest.approx(2 * a[c] if c.startswith("relief") else a[c]), c
    # raising the whole terrain by 1 km changes nothing
    assert np.allclose(saddle_features(h + 1000, p), saddle_features(h, p))


def test_empty_and_flat_disks_are_finite():
    assert np.array_equal(saddle_features(np.zeros(0), np.zeros(0)), np.zeros(len(FS.columns)))
    v = saddle_features(np.full(5, 100.0), np.full(5, 0.0))  # all peaks at their col: no relief
    assert np.isfinite(v).all() and np.allclose(v, 0.0)
    assert np.isfinite(disk_feature_vector(np.zeros(0), *(np.zeros(0),) * 5, radius_m=1e4, feature_set=FS)).all()


def test_feature_table_saddles_need_only_elevation_and_prominence():
    """A peak list without tree (no parent, no saddle position) is enough, and moving the peaks changes nothing."""
    rng = np.random.default_rng(1)
    n = 300
    peaks = pd.DataFrame({"x": rng.uniform(0, 20_000, n), "y": rng.uniform(0, 20_000, n),
                          "elevation": rng.uniform(500, 2000, n), "prominence": rng.uniform(30, 400, n),
                          "saddle_distance_m": np.nan, "saddle_direction_deg": np.nan,
                          "isolation_m": np.nan, "isolation_direction_deg": np.nan,
                          "prominence_exact": np.ones(n, bool)})
    disks = pd.DataFrame({"disk_id": [0], "x": [10_000.0], "y": [10_000.0], "radius_m": [8000.0]})
    f = feature_table(peaks, disks, feature_set=FS, min_peaks=5, label="a")
    inside = np.hypot(peaks["x"] - 10_000.0, peaks["y"] - 10_000.0) <= 8000.0
    want = saddle_features(peaks.loc[inside, "elevation"].to_numpy(), peaks.loc[inside, "prominence"].to_numpy())
    np.testing.assert_allclose(f[FS.columns].to_numpy()[0], want)
    # mirror the peaks about the disk centre and turn them by 90 degrees: same features
    moved = peaks.assign(x=20_000.0 - peaks["y"], y=peaks["x"])
    g = feature_table(moved, disks, feature_set=FS, min_peaks=5, label="a")
    np.testing.assert_allclose(g[FS.columns].to_numpy(), f[FS.columns].to_numpy())
