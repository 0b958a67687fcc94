"""Where the highest peaks stand relative to the data border (issue 11).

The real DEMs are cropped around their relief, so they hold their highest peaks inside;
a stationary automatic C_H put the twins' highest peaks anywhere, often along the border.
A type records the mean elevation rank of its peaks by distance to the border
(``disks["border_rank"]``) and the automatic C_H follows it.
"""
from __future__ import annotations

import numpy as np
import pytest

from orokit.errors import InputError, SchemaError
from orokit.synthesis.controls import make_domain, random_elevation_field
from orokit.synthesis.disks import BORDER_BANDS, border_distance, border_rank, interior_share
from orokit.synthesis.terrain_type import FeatureHistogram, TerrainType
from orokit.synthesis.tree import SynthesisParams, synthesize_divide_tree


def test_border_distance_is_the_normalised_distance_to_the_nearest_side():
    ext = (1000.0, 2000.0, 41_000.0, 32_000.0)  # 40 x 30 km: half the shorter side is 15 km
    rng = np.random.default_rng(0)
    x, y = rng.uniform(1000, 41_000, 500), rng.uniform(2000, 32_000, 500)
    brute = np.array([min(a - 1000, 41_000 - a, b - 2000, 32_000 - b) for a, b in zip(x, y)]) / 15_000
    assert np.allclose(border_distance(x, y, ext), brute)
    # the bands have equal areas on a square: 1 - (1 - t)^2 = 0.2, 0.4, ...
    area = 1 - (1 - np.asarray(BORDER_BANDS)) ** 2
    assert np.allclose(np.diff(area), 0.2, atol=0.002)


def test_border_rank_of_a_central_massif_and_of_unrelated_elevations():
    g = (np.arange(60) + 0.5) * 1000.0
    x, y = (v.ravel() for v in np.meshgrid(g, g))
    ext = (0.0, 0.0, 60_000.0, 60_000.0)
    # elevation falling with the distance to the centre: every band is higher than the one outside it,
    # and the ranks are those of the band's cells among all (brute force)
    z = -np.hypot(x - 30_000, y - 30_000) + 1e-6 * np.arange(x.size)  # no ties
    br = border_rank(x, y, z, ext)
    assert np.all(np.diff(br) > 0)
    rank = (np.argsort(np.argsort(z)) + 0.5) / z.size
    t = border_distance(x, y, ext)
    assert br[0] == pytest.approx(rank[t < BORDER_BANDS[1]].mean())
    assert br[-1] == pytest.approx(rank[t >= BORDER_BANDS[-2]].mean())
    # elevations independent of the position: 0.5 in every band
    z = np.random.default_rng(1).uniform(0, 1000, x.size)
    assert np.allclose(border_rank(x, y, z, ext), 0.5, atol=0.03)


def test_interior_share_matches_brute_force():
    rng = np.random.default_rng(2)
    x, y, z = rng.uniform(0, 50_000, 400), rng.uniform(0, 40_000, 400), rng.uniform(0, 4000, 400)
    for top in (0.02, 0.1, 1.0):
        k = max(1, round(top * 400))
        hi = np.argsort(-z)[:k]
        inside = (x[hi] >= 10_000) & (x[hi] <= 40_000) & (y[hi] >= 10_000) & (y[hi] <= 30_000)
        assert interior_share(x, y, z, (0, 0, 50_000, 40_000), top=top) == pytest.approx(inside.mean())


def _band_means(field: np.ndarray, domain) -> np.ndarray:
    """Mean rank of the field's cells per border band, measured apart from the synthesis code."""
    ny, nx = field.shape
    cx, cy = domain.cell
    xs, ys = np.meshgrid(domain.x0 + (np.arange(nx) + 0.5) * cx, domain.y0 + (np.arange(ny) + 0.5) * cy)
    t = border_distance(xs.ravel(), ys.ravel(), (domain.x0, domain.y0, domain.x0 + domain.width,
                                                 domain.y0 + domain.height))
    v = field.ravel()
    rank = (np.argsort(np.argsort(v + 1e-9 * np.arange(v.size))) + 0.5) / v.size
    band = np.clip(np.searchsorted(BORDER_BANDS, t, side="right") - 1, 0, len(BORDER_BANDS) - 2)
    return np.array([rank[band == b].mean() for b in range(len(BORDER_BANDS) - 1)])


def test_elevation_field_follows_the_border_rank_and_keeps_its_histogram():
    domain = make_domain((60_000.0, 45_000.0), grid_cells=128)
    hist = FeatureHistogram.from_values(np.linspace(200, 3000, 500), np.linspace(200, 3000, 15))
    target = [0.3, 0.42, 0.5, 0.6, 0.75]
    plain = random_elevation_field(domain, hist, correlation_m=8000.0, rng=3)
    trend = random_elevation_field(domain, hist, correlation_m=8000.0, rng=3, border_rank=target)
    # the same values (the histogram's quantiles), only placed differently
    assert np.allclose(np.sort(plain.ravel()), np.sort(trend.ravel()))
    # every field's mean rank is 0.5: the target is met up to the shift that makes its mean over
    # this (rectangular) domain's band areas 0.5
    got = _band_means(trend, domain)
    ny, nx = trend.shape
    xs, ys = np.meshgrid((np.arange(nx) + 0.5) * 60_000 / nx, (np.arange(ny) + 0.5) * 45_000 / ny)
    share = np.histogram(border_distance(xs.ravel(), ys.ravel(), (0, 0, 60_000, 45_000)), BORDER_BANDS)[0]
    shifted = np.asarray(target) - (np.dot(share, target) / share.sum() - 0.5)
    assert np.allclose(got, shifted, atol=0.01)
    assert np.allclose(np.diff(got), np.diff(target), atol=0.01)
    # a flat profile is the stationary field's behaviour: no trend is imposed
    flat = random_elevation_field(domain, hist, correlation_m=2000.0, rng=4, border_rank=[0.5] * 5)
    assert np.allclose(_band_means(flat, domain), 0.5, atol=0.05)


def _central_type(peak_factory) -> TerrainType:
    """A 50 km source whose high ground is in the middle (a crop around a massif)."""
    rng = np.random.default_rng(5)
    p = peak_factory(700, seed=4, side_m=50_000.0)
    r = np.hypot(p["x"] - 25_000, p["y"] - 25_000)
    p["elevation"] = p["elevation"] + 2500 * np.exp(-(r / 12_000) ** 2) + rng.uniform(0, 1, len(p))
    p["prominence"] = np.minimum(p["prominence"], p["elevation"])
    return TerrainType.from_peaks(p, area_km2=2500.0, name="central", extent=(0.0, 0.0, 50_000.0, 50_000.0))


def test_a_twin_of_a_central_massif_holds_its_highest_peaks_inside(peak_factory):
    """Measured on the synthesized trees' own peaks: the highest 5 % stand >= 10 km inside the
    border about as often as in the source (the 30 x 30 km interior is 36 % of the area)."""
    ttype = _central_type(peak_factory)
    src = ttype.disks["border_rank"]
    assert src[-1] > src[0] + 0.2
    on, off = [], []
    for seed in range(3):
        for trend, out in ((True, on), (False, off)):
            t = synthesize_divide_tree(ttype, size_m=50_000, rng=seed, params=SynthesisParams(border_trend=trend))
            pk = t.peaks
            out.append(interior_share(pk["x"].to_numpy(), pk["y"].to_numpy(), pk["elevation"].to_numpy(),
                                      (0, 0, 50_000, 50_000), top=0.05))
        t.validate()
    print("border_trend on", on, "off", off)
    assert np.mean(on) >= 0.8
    assert np.mean(on) > np.mean(off) + 0.15


def test_old_types_without_border_rank_load_and_bad_records_are_refused(small_type):
    d = small_type.to_dict()
    assert len(d["disks"]["border_rank"]) == len(BORDER_BANDS) - 1
    old = dict(d, disks={k: v for k, v in d["disks"].items() if k != "border_rank"})
    assert "border_rank" not in TerrainType.from_dict(old).disks
    synthesize_divide_tree(TerrainType.from_dict(old), size_m=25_000, rng=1).validate()
    with pytest.raises(SchemaError, match="border_rank"):
        TerrainType.from_dict(dict(d, disks=dict(d["disks"], border_rank=[0.5, 0.5])))
    with pytest.raises(SchemaError, match="border_rank"):
        TerrainType.from_dict(dict(d, disks=dict(d["disks"], border_rank=[0.5, 0.5, 1.5, 0.5, 0.5])))
    with pytest.raises(InputError, match="border_trend"):
        SynthesisParams(border_trend="yes")  # type: ignore[arg-type]
