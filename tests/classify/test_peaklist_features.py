from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import shapely
from pyproj import Geod

from orokit.classify.features import feature_table, features_from_region, peaks_in_disks
from orokit.io.model_io import read_feature_table as read_features
from orokit.io.model_io import write_feature_table as write_features
from orokit.classify.peaklist import peak_geometry, read_kirmse_peaks, read_peaks
from orokit.errors import InputError, OrokitWarning, SchemaError
from orokit.sampling.disks import sample_disks_in_polygon
from orokit.sampling.feature_sets import FeatureSet


def test_directions_ccw_from_east():
    from orokit.geodesy import point_distance

    d, a = point_distance(np.zeros(4), np.zeros(4), np.array([1.0, 0, -1, 0]), np.array([0, 1.0, 0, -1]),
                          crs="EPSG:32633")
    assert d.tolist() == [1, 1, 1, 1] and a.tolist() == [0, 90, 180, 270]
    d, a = point_distance(np.array([10.0]), np.array([45.0]), np.array([10.0]), np.array([45.01]), crs="EPSG:4326")
    assert a[0] == pytest.approx(90.0) and d[0] == pytest.approx(1111.5, abs=2)
    d, a = point_distance(np.array([179.999]), np.array([0.0]), np.array([-179.999]), np.array([0.0]),
                          crs="EPSG:4326")  # across the antimeridian: short way, eastwards
    assert d[0] < 300 and a[0] == pytest.approx(0.0, abs=1e-6)
    d, a = point_distance(np.array([0.0, 1.0, np.nan]), np.zeros(3), np.array([0.0, np.nan, 1.0]), np.ones(3))
    assert d[0] == 1.0 and a[0] == 90.0 and np.isnan(d[1:]).all() and np.isnan(a[1:]).all()


def _kirmse_files(tmp_path):
    prom = tmp_path / "prominence.txt"
    prom.write_text("45.0000,10.0000,9000,45.0100,10.0000,1000\n"
                    "45.0200,10.0200,6000,45.0200,10.0300,300\n"
                    "45.0300,10.0400,3000,45.0300,10.0400,3000\n")
    iso = tmp_path / "isolation.txt"
    iso.write_text("45.0000,10.0000,9000,45.1000,10.0000,11.1\n45.0300,10.0400,3000,45.0300,10.1400,7.9\n")
    return prom, iso


def test_kirmse_lists(tmp_path):
    prom, iso = _kirmse_files(tmp_path)
    p = read_kirmse_peaks(prom, iso)
    assert p.crs.to_epsg() == 4326
    assert p["elevation"].tolist() == pytest.approx([9000 * 0.3048, 6000 * 0.3048, 3000 * 0.3048])
    assert p["saddle_direction_deg"].iloc[0] == pytest.approx(90.0)  # saddle due north
    assert p["saddle_direction_deg"].iloc[1] == pytest.approx(0.0, abs=0.01)  # due east
    assert np.isnan(p["saddle_distance_m"].iloc[2])  # saddle == peak: highest of its landmass
    assert p["isolation_m"].tolist() == pytest.approx([11100.0, 500.0, 7900.0])  # missing -> 500 m
    assert np.isnan(p["isolation_direction_deg"].iloc[1])
    assert read_peaks(prom, isolation=iso)["isolation_m"].tolist() == pytest.approx([11100.0, 500.0, 7900.0])
    with pytest.warns(OrokitWarning, match="isolation"):
        read_kirmse_peaks(prom)


def test_kirmse_bad_lines(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("45,10,9000,45.1,10,1000\n46,abc,1,2,3,4\n")
    with pytest.raises(InputError, match="line 2"):
        read_kirmse_peaks(bad)
    short = tmp_path / "short.txt"
    short.write_text("45,10,9000\n")
    with pytest.raises(InputError, match="columns"):
        read_kirmse_peaks(short)
    swapped = tmp_path / "swapped.txt"
    swapped.write_text("120,45,9000,120,45,1000\n")
    with pytest.raises(InputError, match="latitude"):
        read_kirmse_peaks(swapped)


def test_geodesic_disk_membership_matches_bruteforce():
    g = np.random.default_rng(0)
    lon, lat = g.uniform(9, 11, 3000), g.uniform(45, 46, 3000)
    peaks = pd.DataFrame({"x": lon, "y": lat})
    centres = np.array([[10.0, 45.5], [9.5, 45.2]])
    got = peaks_in_disks(peaks, centres, 20_000.0, geographic=True)
    for (cx, cy), idx in zip(centres, got):
        _, _, d = Geod(ellps="WGS84").inv(np.full(3000, cx), np.full(3000, cy), lon, lat)
        assert idx.tolist() == np.flatnonzero(d <= 20_000.0).tolist()


def test_feature_table_counts_eps_and_skips(peaks_factory):
    raw = peaks_factory(800, rng=1)
    peaks = peak_geometry(raw)
    disks = pd.DataFrame({"disk_id": [0, 1, 2], "x": [30_000.0, 15_000.0, -500_000.0],
                          "y": [-30_000.0, -15_000.0, 0.0], "radius_m": 10_000.0})
    with pytest.warns(OrokitWarning, match="1 of 3 disks"):
        f = feature_table(peaks, disks, label="a", min_prominence_m=60.0, feature_set=FeatureSet.paper())
    assert f.attrs["n_disks_skipped"] == 1 and len(f) == 2
    for _, row in f.iterrows():
        d = np.hypot(raw["x"] - row["x"], raw["y"] - row["y"])
        assert row["n_peaks"] == int(((d <= 10_000) & (raw["prominence"] >= 60.0)).sum())
    assert f[[c for c in f.columns if c.startswith("dominance_") and not c.startswith("dominance_g")]].sum(
        axis=1).to_numpy() == pytest.approx(1.0)
    with pytest.warns(OrokitWarning, match="1 of 3 disks"):
        g = feature_table(peaks, disks, label="a", min_prominence_m=60.0)  # default: orometry
    assert g["dominance_19"].to_numpy() == pytest.approx(1.0)  # cumulative histograms end at 1
    np.testing.assert_array_equal(g["n_peaks"], f["n_peaks"])
    area = np.pi * 10.0 ** 2
    np.testing.assert_allclose(10 ** g["log_density"] - 1e-3, g["n_peaks"] / area)  # peaks >= eps per km2


def test_features_parquet_roundtrip(tmp_path, peaks_factory):
    peaks = peak_geometry(peaks_factory(600, rng=2))
    disks = sample_disks_in_polygon(shapely.box(0, -60_000, 60_000, 0), radius_m=10_000, rng=0)
    f = feature_table(peaks, disks, label="x")
    write_features(f, tmp_path / "f.parquet")
    g = read_features(tmp_path / "f.parquet")
    pd.testing.assert_frame_equal(f, g, check_dtype=False)
    assert g.attrs["spec"] == f.attrs["spec"] and g.attrs["radius_m"] == 10_000.0
    pd.DataFrame({"a": [1]}).to_parquet(tmp_path / "other.parquet")
    with pytest.raises(SchemaError):
        read_features(tmp_path / "other.parquet")


def test_region_outside_data_and_too_small(peaks_factory):
    peaks = peak_geometry(peaks_factory(300, rng=3))
    # each call warns twice: the region's own problem, then the skipped disks (both are OrokitWarnings)
    with pytest.warns(OrokitWarning) as rec:
        f = features_from_region(peaks, shapely.box(1e6, 1e6, 1.1e6, 1.1e6), radius_m=10_000, label="far", rng=0)
    assert len(f) == 0 and any("contains none" in str(w.message) for w in rec)
    with pytest.warns(OrokitWarning) as rec:
        f = features_from_region(peaks, shapely.box(0, -5000, 5000, 0), radius_m=10_000, label="tiny", rng=0)
    assert len(f) == 0 and any("smaller than a disk" in str(w.message) for w in rec)
