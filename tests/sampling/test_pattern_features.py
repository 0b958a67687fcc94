"""Spatial pattern features of a disk (spacing, alignment, steepness) on analytic layouts (issue 12)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from orokit.classify.features import feature_table, nearest_peak_distance
from orokit.metrics.disk import axial_resultant
from orokit.sampling.feature_sets import PATTERN_GROUPS, FeatureSet, disk_feature_vector

FS = dataclasses.replace(FeatureSet.orometry(), name="p", histograms=(), summaries=False, elevation=False, saddles=False,
                         pattern=True)


def _pattern(values: np.ndarray) -> dict[str, float]:
    return dict(zip(FS.columns, values))


def test_pattern_columns_follow_groups():
    assert FS.columns == [c for cols in PATTERN_GROUPS.values() for c in cols]
    assert FeatureSet.from_dict(FS.to_dict()) == FS
    assert "pattern" not in FeatureSet.orometry().to_dict()  # older tables and models compare equal


@pytest.mark.parametrize("angle", [0.0, 17.0, 90.0, 133.0])
def test_axial_resultant_lines_and_crosses(angle):
    assert abs(axial_resultant(np.array([angle, angle + 180.0, angle, np.nan]))) == pytest.approx(1.0)
    assert abs(axial_resultant(np.array([angle, angle + 90.0]))) == pytest.approx(0.0, abs=1e-12)
    assert axial_resultant(np.array([np.nan])) == 0j
    # rotating every direction by `angle` keeps the modulus
    d = np.array([10.0, 40.0, 200.0, 300.0])
    assert abs(axial_resultant(d + angle)) == pytest.approx(abs(axial_resultant(d)))


def test_square_lattice_spacing_and_clark_evans():
    """Peaks on a 1 km square lattice: every spacing is 1 km, Clark-Evans ratio 2 (1 for random points)."""
    g = np.arange(-12, 13) * 1000.0
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    peaks = pd.DataFrame({"x": x, "y": y})
    s = nearest_peak_distance(peaks, geographic=False)
    np.testing.assert_allclose(s, 1000.0)
    r = 10_000.0
    inside = np.hypot(x, y) <= r
    n = int(inside.sum())
    h = np.full(n, 1000.0) + np.arange(n)  # distinct, elevation = prominence + 500 (rank correlation 1)
    p = h - 500.0
    d = np.full(n, 2000.0)
    v = _pattern(disk_feature_vector(h, p, d, np.zeros(n), np.full(n, 3000.0), np.full(n, 180.0), radius_m=r,
                                     feature_set=FS, spacing_m=s[inside]))
    for q in ("q25", "q50", "q75", "q90"):
        assert v[f"{q}_log_spacing_m"] == pytest.approx(3.0)
        assert v[f"{q}_log_steepness"] == pytest.approx(np.quantile(np.log10(p / 2000.0), float(q[1:]) / 100))
    # density n / (pi r^2) is ~1 per km2: expected nearest-neighbour distance 0.5 km for random points
    assert v["clark_evans"] == pytest.approx(1000.0 / (0.5 / np.sqrt(n / (np.pi * r * r))))
    assert v["clark_evans"] == pytest.approx(2.0, rel=0.02)
    assert v["saddle_alignment"] == pytest.approx(1.0)  # all key saddles east of their peaks
    assert v["elevation_prominence_rank_correlation"] == pytest.approx(1.0)


def test_random_points_and_directions():
    rng = np.random.default_rng(0)
    n = 4000
    r = 10_000.0
    rho = r * np.sqrt(rng.random(n))
    t = rng.uniform(0, 2 * np.pi, n)
    x, y = rho * np.cos(t), rho * np.sin(t)
    s = nearest_peak_distance(pd.DataFrame({"x": x, "y": y}), geographic=False)
    h = rng.uniform(500, 3000, n)
    p = rng.uniform(30, 400, n)
    v = _pattern(disk_feature_vector(h, p, np.full(n, 1e3), rng.uniform(0, 360, n), np.full(n, 1e3),
                                     np.full(n, 90.0), radius_m=r, feature_set=FS, spacing_m=s))
    # Clark-Evans of a Poisson pattern is 1 (edge effects of the disk raise it by a few percent)
    assert 0.95 < v["clark_evans"] < 1.1
    assert v["saddle_alignment"] < 0.05  # random directions: no axis (expected modulus ~ 1 / sqrt(n))
    assert abs(v["elevation_prominence_rank_correlation"]) < 0.1


def test_geographic_spacing_is_geodesic():
    from orokit.geodesy import WGS84

    lon = np.array([10.0, 10.01, 10.05])
    lat = np.array([45.0, 45.0, 45.02])
    s = nearest_peak_distance(pd.DataFrame({"x": lon, "y": lat}), geographic=True)
    d01 = WGS84.inv(10.0, 45.0, 10.01, 45.0)[2]
    d12 = WGS84.inv(10.01, 45.0, 10.05, 45.02)[2]
    np.testing.assert_allclose(s, [d01, d01, min(d12, WGS84.inv(10.0, 45.0, 10.05, 45.02)[2])])


def test_feature_table_pattern_needs_no_extra_columns():
    """A normalized peak list (no tree) is enough: the spacing is computed from the peaks' positions."""
    rng = np.random.default_rng(1)
    n = 300
    peaks = pd.DataFrame({"x": rng.uniform(0, 20_000, n), "y": rng.uniform(0, 20_000, n),
                          "elevation": rng.uniform(500, 2000, n), "prominence": rng.uniform(30, 400, n),
                          "saddle_distance_m": rng.uniform(200, 3000, n), "saddle_direction_deg": rng.uniform(0, 360, n),
                          "isolation_m": rng.uniform(200, 3000, n), "isolation_direction_deg": rng.uniform(0, 360, n),
                          "prominence_exact": np.ones(n, bool)})
    disks = pd.DataFrame({"disk_id": [0], "x": [10_000.0], "y": [10_000.0], "radius_m": [8000.0]})
    f = feature_table(peaks, disks, feature_set=FS, min_peaks=5, label="a")
    assert len(f) == 1 and np.isfinite(f[FS.columns].to_numpy()).all()
    with pytest.raises(Exception, match="spacing_m"):
        disk_feature_vector(np.ones(3), np.ones(3), np.ones(3), np.ones(3), np.ones(3), np.ones(3), radius_m=1.0,
                            feature_set=FS)
