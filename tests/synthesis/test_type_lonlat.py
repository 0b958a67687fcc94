"""Terrain types from lon/lat analyses are measured in metres (review B1).

The same analytic terrain (a sum of plane waves, statistically homogeneous) is sampled
on a UTM grid and on a lon/lat grid covering the same ground, centred on the UTM zone's
central meridian (grid north = true north there). Both types must agree on density,
distances and directions.
"""
from __future__ import annotations

import numpy as np
import pytest
from pyproj import Transformer

import orokit
from orokit.analysis import write_analysis
from orokit.errors import OrokitError
from orokit.synthesis.terrain_type import TerrainType
from orokit.synthesis.tree import MAX_PEAKS, synthesize_divide_tree

UTM = "EPSG:32632"  # central meridian 9 E
E0, N0 = 500_000.0, 5_095_000.0  # about 9 E, 46 N
SIDE = 30_000.0


def _terrain(e: np.ndarray, n: np.ndarray) -> np.ndarray:
    rng = np.random.default_rng(3)
    k = 7
    ang = np.pi * (np.arange(k) / k + rng.uniform(0, 0.1, k))
    lam = rng.uniform(1800, 4000, k)
    amp = rng.uniform(60, 160, k)
    ph = rng.uniform(0, 2 * np.pi, k)
    z = np.full(np.shape(e), 1500.0)
    for i in range(k):
        z = z + amp[i] * np.cos(2 * np.pi * (np.cos(ang[i]) * e + np.sin(ang[i]) * n) / lam[i] + ph[i])
    return z.astype("float32")


_CACHE: dict[str, tuple[TerrainType, TerrainType]] = {}


@pytest.fixture
def two_types(make_dem, tmp_path_factory):
    if "types" not in _CACHE:  # built once per module (make_dem is function-scoped)
        _CACHE["types"] = _build_types(make_dem, tmp_path_factory)
    return _CACHE["types"]


def _build_types(build_dem, tmp_path_factory):
    res = 90.0
    n = int(SIDE / res)
    e = E0 - SIDE / 2 + res * (np.arange(n) + 0.5)
    nn = N0 + SIDE / 2 - res * (np.arange(n) + 0.5)
    ee, nnn = np.meshgrid(e, nn)
    dem_u = build_dem(_terrain(ee, nnn), res=res, crs=UTM, origin=(E0 - SIDE / 2, N0 + SIDE / 2))

    lon0, lat0 = Transformer.from_crs(UTM, "EPSG:4326", always_xy=True).transform(E0, N0)
    dx, dy = 0.0012, 0.0008  # about 93 x 89 m at 46 N
    nx = int(round(SIDE / (111_320.0 * np.cos(np.radians(lat0))) / dx))
    ny = int(round(SIDE / 111_150.0 / dy))
    west, north = lon0 - nx * dx / 2, lat0 + ny * dy / 2
    lon, lat = np.meshgrid(west + dx * (np.arange(nx) + 0.5), north - dy * (np.arange(ny) + 0.5))
    eg, ng = Transformer.from_crs("EPSG:4326", UTM, always_xy=True).transform(lon, lat)
    dem_g = build_dem(_terrain(eg, ng), res=(dx, dy), crs="EPSG:4326", origin=(west, north))

    t_utm = TerrainType.from_analysis(orokit.analyze(dem_u, min_prominence_m=30.0))
    folder = tmp_path_factory.mktemp("geo") / "analysis"
    write_analysis(orokit.analyze(dem_g, min_prominence_m=30.0), folder)
    t_geo = TerrainType.from_analysis(folder)  # through analysis.json: recorded transform and CRS
    return t_utm, t_geo


def _quantile(h, p: float) -> float:
    cdf = np.concatenate([[0.0], np.cumsum(h.probabilities())])
    return float(np.interp(p, cdf, np.asarray(h.edges)))


def test_lonlat_type_has_the_density_of_the_projected_one(two_types):
    t_utm, t_geo = two_types
    assert t_geo.provenance["area_km2"] == pytest.approx(SIDE**2 / 1e6, rel=0.02)
    assert t_utm.provenance["area_km2"] == pytest.approx(SIDE**2 / 1e6, rel=0.02)
    assert t_utm.provenance["n_peaks"] > 100
    assert t_geo.peak_density_per_km2 == pytest.approx(t_utm.peak_density_per_km2, rel=0.03)


@pytest.mark.parametrize("feature", ["isolation_distance", "saddle_distance"])
def test_lonlat_distances_are_metres(two_types, feature):
    t_utm, t_geo = two_types
    for p in (0.25, 0.5, 0.75):
        assert _quantile(t_geo.histograms[feature], p) == pytest.approx(
            _quantile(t_utm.histograms[feature], p), rel=0.06), p


def test_lonlat_directions_follow_the_ground(two_types):
    t_utm, t_geo = two_types
    for f in ("isolation_direction", "saddle_direction"):
        a = t_utm.histograms[f].probabilities()
        b = t_geo.histograms[f].probabilities()
        # ~150 peaks in 24 bins: sampling noise alone gives an L1 distance of ~0.1-0.25
        assert np.abs(a - b).sum() < 0.35, f


def test_absurd_peak_count_is_refused_before_allocating(small_type):
    dense = small_type.with_density(87_436_339.0)  # what a type in degrees looked like
    with pytest.raises(OrokitError, match="more than the limit"):
        synthesize_divide_tree(dense, size_m=10_000.0, rng=0)
    with pytest.raises(OrokitError, match="more than the limit"):
        synthesize_divide_tree(small_type, size_m=10_000.0, n_peaks=MAX_PEAKS + 1, rng=0)
