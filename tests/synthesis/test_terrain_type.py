"""Terrain types: construction, versioned files, editing, sampling."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from orokit.errors import InputError, SchemaError
from orokit.synthesis.terrain_type import (
    FEATURES,
    TYPE_VERSION,
    FeatureHistogram,
    TerrainType,
    load_terrain_type,
)


def test_from_peaks_counts_and_density(peak_table, small_type):
    keyed = peak_table["saddle_x"].notna()
    assert set(small_type.histograms) == set(FEATURES)
    assert small_type.peak_density_per_km2 == pytest.approx(len(peak_table) / 1600.0)
    assert sum(small_type.histograms["elevation"].counts) == len(peak_table)
    assert sum(small_type.histograms["prominence"].counts) == keyed.sum()
    # every peak but the highest has a higher peak, hence an isolation
    assert sum(small_type.histograms["isolation_distance"].counts) == len(peak_table) - 1
    assert small_type.histograms["prominence"].edges[0] == 30.0


def test_threshold_filters_peaks(peak_table):
    t = TerrainType.from_peaks(peak_table, area_km2=1600.0, min_prominence_m=100.0)
    assert sum(t.histograms["elevation"].counts) == (peak_table["prominence"] >= 100).sum()


def test_too_few_peaks_and_missing_columns(peak_table):
    with pytest.raises(InputError, match="too few"):
        TerrainType.from_peaks(peak_table.iloc[:2], area_km2=10.0)
    with pytest.raises(InputError, match="lacks columns"):
        TerrainType.from_peaks(peak_table.drop(columns="saddle_x"), area_km2=10.0)
    with pytest.raises(InputError, match="area_km2"):
        TerrainType.from_peaks(peak_table, area_km2=0.0)


def test_save_load_round_trip(tmp_path, small_type):
    path = small_type.save(tmp_path / "t.json")
    back = load_terrain_type(path)
    assert back.to_dict() == small_type.to_dict()


def test_other_version_is_refused(tmp_path, small_type):
    data = small_type.to_dict()
    data["version"] = TYPE_VERSION + 1
    (tmp_path / "t.json").write_text(json.dumps(data))
    with pytest.raises(SchemaError, match="version"):
        load_terrain_type(tmp_path / "t.json")
    data["format"] = "something-else"
    (tmp_path / "u.json").write_text(json.dumps(data))
    with pytest.raises(SchemaError, match="not an orokit terrain type"):
        load_terrain_type(tmp_path / "u.json")
    (tmp_path / "v.json").write_text("{not json")
    with pytest.raises(SchemaError, match="not valid JSON"):
        load_terrain_type(tmp_path / "v.json")


def test_malformed_histogram_in_file(tmp_path, small_type):
    data = small_type.to_dict()
    data["histograms"]["prominence"]["counts"] = [0.0] * len(data["histograms"]["prominence"]["counts"])
    (tmp_path / "t.json").write_text(json.dumps(data))
    with pytest.raises(SchemaError, match="empty"):
        load_terrain_type(tmp_path / "t.json")


@pytest.mark.parametrize(
    "edges, counts, match",
    [
        ((0.0, 1.0, 1.0), (1.0, 1.0), "increasing"),
        ((0.0,), (), "increasing"),
        ((0.0, 1.0, 2.0), (1.0,), "needs 2 counts"),
        ((0.0, 1.0), (-1.0,), ">= 0"),
        ((0.0, 1.0), (0.0,), "empty"),
        ((0.0, np.nan), (1.0,), "finite"),
    ],
)
def test_degenerate_histograms(edges, counts, match):
    with pytest.raises(SchemaError, match=match):
        FeatureHistogram(edges, counts)


def test_edits_make_valid_new_types(small_type):
    doubled = small_type.scaled("prominence", 2.0)
    assert np.allclose(doubled.histograms["prominence"].edges, 2 * np.asarray(small_type.histograms["prominence"].edges))
    assert doubled.histograms["prominence"].counts == small_type.histograms["prominence"].counts
    assert "scale prominence x2" in doubled.provenance["edits"]
    shifted = small_type.shifted("elevation", 500.0)
    s = shifted.histograms["elevation"].sample(500, rng=1)
    o = small_type.histograms["elevation"].sample(500, rng=1)
    assert np.allclose(s - o, 500.0)
    counts = np.ones(small_type.histograms["saddle_direction"].n_bins)
    edited = small_type.with_counts("saddle_direction", counts)
    assert np.allclose(edited.histograms["saddle_direction"].probabilities(), 1 / counts.size)
    # the original is unchanged (frozen)
    assert small_type.provenance["edits"] == []


def test_bad_edits(small_type):
    with pytest.raises(InputError):
        small_type.scaled("prominence", -1.0)
    with pytest.raises(InputError):
        small_type.scaled("isolation_direction", 2.0)
    with pytest.raises(InputError, match="unknown feature"):
        small_type.scaled("height", 2.0)
    with pytest.raises(SchemaError):
        small_type.shifted("elevation", -1e6)
    with pytest.raises(SchemaError):
        small_type.with_histogram("dominance", [0.0, 0.5, 2.0], [1, 1])
    with pytest.raises(SchemaError):
        small_type.with_counts("dominance", [0.0] * small_type.histograms["dominance"].n_bins)


def test_dominance_scaling_is_clipped_to_one(small_type):
    t = small_type.scaled("dominance", 3.0)
    h = t.histograms["dominance"]
    assert h.edges[-1] == 1.0
    assert sum(h.counts) == pytest.approx(sum(small_type.histograms["dominance"].counts))


@settings(max_examples=40, deadline=None)
@given(
    counts=st.lists(st.integers(0, 50), min_size=1, max_size=30).filter(lambda c: sum(c) > 0),
    n=st.integers(1, 400),
    seed=st.integers(0, 2**32 - 1),
)
def test_stratified_sample_matches_histogram(counts, n, seed):
    edges = np.arange(len(counts) + 1, dtype=float)
    h = FeatureHistogram(tuple(edges), tuple(float(c) for c in counts))
    v = h.sample(n, rng=seed)
    assert v.size == n and np.all((v >= 0) & (v <= len(counts)))
    got = np.bincount(h.bin_index(v), minlength=len(counts))
    # one value per stratum of width 1/n: a bin spanning n*p strata gets fewer than
    # two values more or less than n*p (one partial stratum at each end)
    assert np.all(np.abs(got - h.probabilities() * n) < 2.0)
    assert np.all(got[np.asarray(counts) == 0] == 0)


def test_isolation_basis_terrain(peak_table):
    frame = peak_table.copy()
    frame["isolation"] = 1000.0
    frame["isolation_x"] = frame["x"] + 1000.0
    frame["isolation_y"] = frame["y"]
    t = TerrainType.from_peaks(frame, area_km2=1600.0, isolation_basis="terrain")
    assert t.isolation_basis == "terrain"
    d = t.histograms["isolation_direction"].probabilities()
    assert d[0] == pytest.approx(1.0)  # every target due east


def test_rho_estimate_prefers_matching_exponent(peak_factory):
    from orokit.synthesis.ridges import delaunay_mst
    from orokit.synthesis.terrain_type import estimate_rho
    from orokit.topology.divide_tree import DivideTree

    frame = peak_factory(150, seed=3)
    x, y, z = (frame[c].to_numpy() for c in ("x", "y", "elevation"))
    for rho in (0.0, 2.0):
        a, b = delaunay_mst(x, y, z, rho=rho)
        sz = np.minimum(z[a], z[b]) - 100.0
        tree = DivideTree.from_arrays(np.column_stack([x, y, z]),
                                      np.column_stack([(x[a] + x[b]) / 2, (y[a] + y[b]) / 2, sz]),
                                      np.column_stack([a, b, np.arange(a.size)]))
        assert estimate_rho(tree, min_prominence_m=0.0) == rho


def test_elevation_bands_partition_the_peaks(peak_table, small_type):
    from orokit.synthesis.terrain_type import band_histograms

    b = small_type.bands
    assert b is not None and b["elevation_bins"][0] == 0
    assert b["elevation_bins"][-1] == small_type.histograms["elevation"].n_bins
    # band counts add up to the marginal histograms
    assert np.allclose(np.sum(b["prominence"], axis=0), small_type.histograms["prominence"].counts)
    assert np.allclose(np.sum(b["dominance"], axis=0), small_type.histograms["dominance"].counts)
    edges, ph, dh = band_histograms(small_type)
    assert len(edges) == len(ph) + 1 == len(dh) + 1 and np.all(np.diff(edges) > 0)
    # hand-editing a paired histogram drops the joint statistics; other edits keep them
    assert small_type.with_counts("prominence", small_type.histograms["prominence"].counts).bands is None
    assert small_type.shifted("elevation", 100.0).bands == b
    data = small_type.to_dict()
    data["bands"]["elevation_bins"] = [0, 5]
    with pytest.raises(SchemaError, match="bands"):
        TerrainType.from_dict(data)


def test_source_location_and_texture_survive_json_and_bad_ones_are_refused(tmp_path):
    from orokit.errors import SchemaError
    from orokit.synthesis.terrain_type import TerrainType, load_terrain_type

    rng = np.random.default_rng(2)
    n = 60
    z = rng.uniform(500, 1500, n)
    peaks = pd.DataFrame({"x": rng.uniform(0, 2e4, n), "y": rng.uniform(0, 2e4, n), "elevation": z,
                          "prominence": np.minimum(30 + rng.exponential(80, n), z)})
    peaks["saddle_x"], peaks["saddle_y"] = peaks["x"] + 300.0, peaks["y"]
    tt = TerrainType.from_peaks(peaks, area_km2=400.0, crs="EPSG:32633").with_texture(25.0, 4.2)
    assert tt.source_center is not None and tt.source_crs.startswith("PROJCRS")
    back = load_terrain_type(tt.save(tmp_path / "t.json"))
    assert back.source_center == pytest.approx(tt.source_center) and back.source_crs == tt.source_crs
    assert back.texture == {"rms_m": 25.0, "beta": 4.2, "largest_m": 1000.0}
    assert TerrainType.from_peaks(peaks, area_km2=400.0).source_center is None  # local metres: nowhere
    with pytest.raises(SchemaError, match="source_center"):
        TerrainType.from_dict({**tt.to_dict(), "source_center": [15.0, 95.0]})
    with pytest.raises(SchemaError, match="texture"):
        TerrainType.from_dict({**tt.to_dict(), "texture": {"rms_m": -1.0, "beta": 4.0}})
