"""How many peaks stand near the data border (issue 11, session 15).

The real DEMs are cropped around their relief: pyrenees' tree holds 1.6 times its mean peak
density in the middle fifth of its area and 0.6-0.8 times in the bands around it. A type
records the relative density per border band (``disks["border_density"]``); with
``SynthesisParams(border_density=True)`` the automatic C_P follows it.
"""
from __future__ import annotations

import numpy as np
import pytest

from orokit.errors import InputError, SchemaError
from orokit.synthesis.controls import border_density_map, make_domain, random_elevation_field
from orokit.synthesis.disks import BORDER_BANDS, band_areas, border_density, border_distance
from orokit.synthesis.terrain_type import FeatureHistogram, TerrainType
from orokit.synthesis.tree import SynthesisParams, synthesize_divide_tree


def _bands(x: np.ndarray, y: np.ndarray, extent) -> np.ndarray:
    """Band of every point, measured apart from the synthesis code (brute-force distance to the sides)."""
    xmin, ymin, xmax, ymax = extent
    d = np.minimum.reduce([x - xmin, xmax - x, y - ymin, ymax - y]) / (0.5 * min(xmax - xmin, ymax - ymin))
    return np.clip(np.searchsorted(BORDER_BANDS, d, side="right") - 1, 0, len(BORDER_BANDS) - 2)


def _cells(domain):
    ny, nx = domain.shape
    cx, cy = domain.cell
    xs, ys = np.meshgrid(domain.x0 + (np.arange(nx) + 0.5) * cx, domain.y0 + (np.arange(ny) + 0.5) * cy)
    return xs.ravel(), ys.ravel()


def test_band_areas_are_exact_and_sum_to_the_extent():
    ext = (1000.0, 2000.0, 61_000.0, 47_000.0)  # 60 x 45 km
    area = band_areas(ext)
    assert area.sum() == pytest.approx(60_000.0 * 45_000.0)
    g = np.random.default_rng(0)
    x, y = g.uniform(1000, 61_000, 400_000), g.uniform(2000, 47_000, 400_000)
    share = np.bincount(_bands(x, y, ext), minlength=5) / x.size
    assert np.allclose(share, area / area.sum(), atol=0.003)


def test_border_density_of_an_even_spread_and_of_a_central_cluster():
    ext = (0.0, 0.0, 50_000.0, 40_000.0)
    g = np.random.default_rng(1)
    x, y = g.uniform(0, 50_000, 20_000), g.uniform(0, 40_000, 20_000)
    assert np.allclose(border_density(x, y, ext), 1.0, atol=0.06)
    # half the peaks in a 10 km square in the middle: the innermost band holds them
    cx, cy = g.uniform(20_000, 30_000, 20_000), g.uniform(15_000, 25_000, 20_000)
    bd = np.asarray(border_density(np.r_[x, cx], np.r_[y, cy], ext))
    count = np.bincount(_bands(np.r_[x, cx], np.r_[y, cy], ext), minlength=5)
    area = band_areas(ext)
    assert np.allclose(bd, count / area / (count.sum() / area.sum()))
    assert bd[-1] > 2.0 and np.all(bd[:-1] < 0.8)
    assert border_density(np.empty(0), np.empty(0), ext) == [1.0] * 5


def test_density_map_meets_the_profile_in_every_band():
    domain = make_domain((60_000.0, 45_000.0), grid_cells=128)
    profile = [1.3, 0.6, 0.8, 0.7, 1.6]
    dens = border_density_map(domain, profile)
    assert dens.shape == domain.shape and dens.min() > 0 and dens.mean() == pytest.approx(1.0)
    x, y = _cells(domain)
    band = _bands(x, y, (domain.x0, domain.y0, domain.x0 + domain.width, domain.y0 + domain.height))
    got = np.array([dens.ravel()[band == b].mean() for b in range(5)])
    # the profile, rescaled so its mean over this domain's cells is 1
    share = np.bincount(band, minlength=5) / band.size
    want = np.asarray(profile) / np.dot(share, profile)
    assert np.allclose(got, want, atol=0.01)
    # a flat profile is a uniform C_P; a closed band keeps the floor
    assert np.allclose(border_density_map(domain, [2.0] * 5), 1.0)
    assert border_density_map(domain, [1.0, 0.0, 1.0, 1.0, 1.0]).min() > 0


def test_elevation_field_ranked_by_the_density_follows_the_histogram_where_the_peaks_are():
    domain = make_domain((60_000.0, 45_000.0), grid_cells=128)
    hist = FeatureHistogram.from_values(np.linspace(200, 3000, 500), np.linspace(200, 3000, 15))
    dens = border_density_map(domain, [0.5, 0.5, 1.0, 1.5, 3.0])
    field = random_elevation_field(domain, hist, correlation_m=8000.0, rng=3,
                                   border_rank=[0.3, 0.4, 0.5, 0.6, 0.7])
    from orokit.synthesis.controls import random_elevation_fields

    weighted = next(random_elevation_fields(domain, hist, correlation_m=8000.0, rng=3,
                                            border_rank=[0.3, 0.4, 0.5, 0.6, 0.7], density=dens))
    # the density-weighted quantiles are the histogram's (uniform 200..3000 m): the weighted
    # median is ~1600 m, while the area's median sits lower (the dense middle is high)
    def wmedian(v, w):
        o = np.argsort(v.ravel())
        c = np.cumsum(w.ravel()[o])
        return v.ravel()[o][np.searchsorted(c, 0.5 * c[-1])]
    assert wmedian(weighted, dens) == pytest.approx(1600.0, abs=40.0)
    assert abs(wmedian(field, dens) - 1600.0) > 100.0
    assert np.median(weighted) < 1600.0 - 100.0


def _dense_middle_type(peak_factory) -> TerrainType:
    """A 50 km source with a third of its peaks packed in the middle 16 km."""
    p = peak_factory(700, seed=4, side_m=50_000.0)
    g = np.random.default_rng(6)
    k = 240
    p.loc[: k - 1, "x"] = g.uniform(17_000, 33_000, k)
    p.loc[: k - 1, "y"] = g.uniform(17_000, 33_000, k)
    return TerrainType.from_peaks(p, area_km2=2500.0, name="dense-middle", extent=(0.0, 0.0, 50_000.0, 50_000.0))


def test_a_twin_follows_the_border_density_only_when_asked(peak_factory):
    ttype = _dense_middle_type(peak_factory)
    src = ttype.disks["border_density"]
    assert src[-1] > 1.5 and src[0] < 0.9
    ext = (0.0, 0.0, 50_000.0, 50_000.0)
    on, off = [], []
    for seed in range(3):
        for flag, out in ((True, on), (False, off)):
            t = synthesize_divide_tree(ttype, size_m=50_000, rng=seed, params=SynthesisParams(border_density=flag))
            t.validate()
            out.append(border_density(t.peaks["x"].to_numpy(), t.peaks["y"].to_numpy(), ext))
    on_m, off_m = np.mean(on, axis=0), np.mean(off, axis=0)
    print("source", np.round(src, 2), "on", np.round(on_m, 2), "off", np.round(off_m, 2))
    assert np.abs(on_m - src).mean() < 0.5 * np.abs(off_m - src).mean()
    assert on_m[-1] > off_m[-1] + 0.4


def test_off_or_without_the_record_the_tree_is_unchanged(small_type):
    d = small_type.to_dict()
    assert len(d["disks"]["border_density"]) == len(BORDER_BANDS) - 1
    old = TerrainType.from_dict(dict(d, disks={k: v for k, v in d["disks"].items() if k != "border_density"}))
    assert "border_density" not in old.disks
    a = synthesize_divide_tree(small_type, size_m=25_000, rng=1, params=SynthesisParams(border_density=False))
    b = synthesize_divide_tree(old, size_m=25_000, rng=1, params=SynthesisParams(border_density=True))
    assert a.peaks.equals(b.peaks) and a.saddles.equals(b.saddles)
    # a user C_P wins over the profile
    dens = np.ones((8, 8))
    c = synthesize_divide_tree(small_type, size_m=25_000, rng=1, control_density=dens)
    e = synthesize_divide_tree(small_type, size_m=25_000, rng=1, control_density=dens,
                               params=SynthesisParams(border_density=True))
    assert c.peaks.equals(e.peaks)


def test_bad_border_density_records_and_params_are_refused(small_type):
    d = small_type.to_dict()
    for bad in ([1.0, 1.0], [1.0, -0.5, 1.0, 1.0, 1.0], [0.0] * 5, ["a"] * 5):
        with pytest.raises(SchemaError, match="border_density"):
            TerrainType.from_dict(dict(d, disks=dict(d["disks"], border_density=bad)))
    with pytest.raises(InputError, match="border_density"):
        SynthesisParams(border_density="yes")  # type: ignore[arg-type]


def test_border_distance_bands_agree_with_the_brute_force_helper():
    ext = (0.0, 0.0, 30_000.0, 20_000.0)
    g = np.random.default_rng(3)
    x, y = g.uniform(0, 30_000, 1000), g.uniform(0, 20_000, 1000)
    t = border_distance(x, y, ext)
    band = np.clip(np.searchsorted(BORDER_BANDS, t, side="right") - 1, 0, 4)
    assert np.array_equal(band, _bands(x, y, ext))


def test_a_small_trees_profile_is_shrunk_by_its_noise_and_a_large_ones_kept():
    from orokit.synthesis.disks import shrink_border_density

    ext = (0.0, 0.0, 50_000.0, 50_000.0)
    g = np.random.default_rng(11)
    raw, shrunk = [], []
    for _ in range(200):  # uniform spreads of 150 peaks: every deviation from 1 is noise
        x, y = g.uniform(0, 50_000, 150), g.uniform(0, 50_000, 150)
        b = border_density(x, y, ext)
        raw.append(np.abs(np.subtract(b, 1.0)).mean())
        shrunk.append(np.abs(np.subtract(shrink_border_density(b, 150), 1.0)).mean())
    assert np.mean(shrunk) < 0.5 * np.mean(raw)
    # a real gradient of 2000 peaks (a third in the middle) is far above its noise: nearly kept
    x, y = g.uniform(0, 50_000, 1400), g.uniform(0, 50_000, 1400)
    x, y = np.r_[x, g.uniform(17_000, 33_000, 600)], np.r_[y, g.uniform(17_000, 33_000, 600)]
    b = np.asarray(border_density(x, y, ext))
    s = np.asarray(shrink_border_density(b, 2000))
    assert np.allclose(s - 1.0, b - 1.0, rtol=0.05)
    # the same profile from a handful of peaks is mostly noise
    assert np.abs(np.asarray(shrink_border_density(b, 20)) - 1.0).max() < 0.5 * np.abs(b - 1.0).max()
    assert shrink_border_density([1.0] * 5, 100) == [1.0] * 5
    assert shrink_border_density([1.3, 0.7, 1.0, 1.0, 1.0], 0) == [1.0] * 5
