"""Per-disk statistics (orokit.synthesis.disks) and the per-disk target of the dart throwing."""
from __future__ import annotations

import numpy as np
import pytest

from helpers.peak_fields import random_peak_field
from orokit.errors import InputError, SchemaError
from orokit.synthesis.disks import (
    DISK_RADIUS_M,
    coverage_targets,
    disk_centres,
    disk_quantiles,
    disk_statistics,
)
from orokit.synthesis.terrain_type import TerrainType, loads_terrain_type
from orokit.synthesis.tree import SynthesisParams, peaks_table, synthesize_divide_tree

R = DISK_RADIUS_M


def test_disk_centres_lie_inside_and_none_fit_a_narrow_extent():
    cx, cy, step = disk_centres((100.0, -50.0, 100.0 + 45_000, -50.0 + 31_000))
    assert cx.size > 0 and step == R / 10
    assert np.all(cx - R >= 100.0 - 1e-6) and np.all(cx + R <= 45_100.0 + 1e-6)
    assert np.all(cy - R >= -50.0 - 1e-6) and np.all(cy + R <= 30_950.0 + 1e-6)
    # the grid is full: (25 km / 1 km + 1) x (11 km / 1 km + 1) centres
    assert cx.size == 26 * 12
    assert disk_centres((0, 0, 19_999, 50_000))[0].size == 0
    # a huge extent keeps at most MAX_CENTRES centres
    from orokit.synthesis.disks import MAX_CENTRES

    assert disk_centres((0, 0, 1e6, 1e6))[0].size <= MAX_CENTRES


def test_disk_statistics_match_brute_force():
    x, y, z, prom = random_peak_field(3, 300, 40_000, 35_000)
    s = disk_statistics(x, y, z, prom, (0, 0, 40_000, 35_000), min_prominence_m=30.0, step_m=2_500)
    keep = prom >= 30
    order = np.sort(z[keep])
    for i in range(0, s["x"].size, 7):
        inside = keep & (np.hypot(x - s["x"][i], y - s["y"][i]) <= R)
        assert s["peaks"][i] == inside.sum()
        assert s["max_prominence_m"][i] == (prom[inside].max() if inside.any() else 0.0)
        if inside.any():
            higher = np.sum(order > z[inside].max())
            assert s["top_rank"][i] == pytest.approx(higher / keep.sum())
        else:
            assert s["top_rank"][i] == 1.0


def test_coverage_targets_analytic():
    levels = np.linspace(0, 1, 21)
    # every disk holds the highest peak: everything is covered from the first peak on
    rec = {"radius_m": R, "levels": levels, "top_rank": np.zeros(21)}
    assert np.allclose(coverage_targets(rec, 50), 1.0)
    # top_rank uniform on [0, 1]: after the k-th peak the share is the rank (k + 0.5) / n
    rec["top_rank"] = levels
    t = coverage_targets(rec, 40)
    assert np.allclose(t, (np.arange(40) + 0.5) / 40)
    rec["top_rank"] = levels**2
    t = coverage_targets(rec, 100)
    assert np.all(np.diff(t) >= 0) and 0 <= t[0] and t[-1] <= 1
    assert np.allclose(t, np.sqrt((np.arange(100) + 0.5) / 100), atol=0.02)


def test_type_records_disks_and_old_files_still_load(small_type):
    d = small_type.disks
    assert d is not None and d["radius_m"] == R and len(d["top_rank"]) == len(d["levels"]) == 21
    assert d["n_disks"] > 0 and d["peaks"][0] >= 0 and 0 <= d["top_rank"][0] <= d["top_rank"][-1] <= 1
    back = TerrainType.from_dict(small_type.to_dict())
    assert back.disks == small_type.disks
    old = small_type.to_dict()
    del old["disks"]  # a type written before the per-disk record
    assert TerrainType.from_dict(old).disks is None
    # a type still synthesizes without it (per-disk target off)
    t = synthesize_divide_tree(TerrainType.from_dict(old), size_m=25_000, rng=1,
                               params=SynthesisParams(disk_weight=32.0))
    t.validate()
    bad = small_type.to_dict()
    bad["disks"] = dict(bad["disks"], top_rank=list(reversed(bad["disks"]["top_rank"])))
    with pytest.raises(SchemaError, match="top_rank"):
        TerrainType.from_dict(bad)
    import json

    bad["disks"] = {"radius_m": R}
    with pytest.raises(SchemaError, match="disks record"):
        loads_terrain_type(json.dumps(bad))
    with pytest.raises(InputError, match="disk_weight"):
        SynthesisParams(disk_weight=-1)


def test_narrow_data_gives_no_disk_record(peak_factory):
    t = TerrainType.from_peaks(peak_factory(60, seed=1, side_m=15_000.0), area_km2=225.0)
    assert t.disks is None
    assert disk_quantiles(disk_statistics(np.zeros(1), np.zeros(1), np.ones(1), np.full(1, 50.0),
                                          (0, 0, 15_000, 15_000))) is None


def _disk_distance(tree, ttype, column: str) -> float:
    """Wasserstein distance between the tree's per-disk ``column`` (``top_rank``, ``peaks``) and the type's record."""
    from scipy.stats import wasserstein_distance

    pk = peaks_table(tree)
    dom = tree.attrs["domain"]
    s = disk_statistics(pk["x"].to_numpy(), pk["y"].to_numpy(), pk["elevation"].to_numpy(),
                        pk["prominence"].to_numpy(), (dom["x0"], dom["y0"], dom["x0"] + dom["width"],
                                                      dom["y0"] + dom["height"]),
                        min_prominence_m=ttype.min_prominence_m)
    return float(wasserstein_distance(s[column], ttype.disks[column]))


def test_disk_weight_brings_the_per_disk_highest_peaks_to_the_type(peak_factory):
    """A source whose highest peaks stand in the middle (every 10 km disk holds one of them):
    with the per-disk target the synthesized trees' top_rank distribution, measured on their
    own peaks by disk_statistics (not by the synthesis), comes closer to the source's. With the
    paper's C_H acceptance (1/20 of its range): the default, tighter one lets C_H place the highest
    peaks by itself more (plain 0.070, with the target 0.059 on these seeds)."""
    rng = np.random.default_rng(5)
    p = peak_factory(700, seed=4, side_m=50_000.0)
    # raise the peaks near the centre: the high ground is central, as in the region crops
    r = np.hypot(p["x"] - 25_000, p["y"] - 25_000)
    p["elevation"] = p["elevation"] + 2500 * np.exp(-(r / 8000) ** 2) + rng.uniform(0, 1, len(p))
    p["prominence"] = np.minimum(p["prominence"], p["elevation"])
    ttype = TerrainType.from_peaks(p, area_km2=2500.0, name="central")
    assert ttype.disks["top_rank"][10] < 0.05  # half of the disks hold one of the top 5 % peaks
    plain, target = [], []
    for seed in range(3):
        p0 = SynthesisParams(disk_weight=0.0, elevation_tolerance=0.05)
        plain.append(_disk_distance(synthesize_divide_tree(ttype, size_m=50_000, rng=seed, params=p0), ttype, "top_rank"))
        t = synthesize_divide_tree(ttype, size_m=50_000, rng=seed,
                                   params=SynthesisParams(disk_weight=32.0, elevation_tolerance=0.05))
        t.validate()
        target.append(_disk_distance(t, ttype, "top_rank"))
    assert np.mean(target) < 0.6 * np.mean(plain)


def test_disk_count_targets_follow_the_record_and_the_border():
    from orokit.synthesis.controls import build_controls
    from orokit.synthesis.darts import disk_count_targets
    from orokit.synthesis.tree import _resolve_domain

    levels = np.linspace(0, 1, 21)
    rec = {"radius_m": R, "levels": levels, "peaks": 20 + 60 * levels, "top_rank": levels}
    domain = _resolve_domain(None, size_m=60_000, crs=None, center=None, grid_cells=256)
    controls = build_controls(domain, control_density=None, control_elevation=None, type_map=None, n_types=1)
    x0, y0, nx, ny, t = disk_count_targets([rec], controls, domain, 1000.0, R, np.random.default_rng(0))
    x, y = (v.ravel() for v in np.meshgrid(x0 + np.arange(nx) * 1000.0, y0 + np.arange(ny) * 1000.0))
    assert t.size == nx * ny == 60 * 60 and x.min() > 0 and x.max() < 60_000
    inside = (x >= R) & (x <= 50_000) & (y >= R) & (y <= 50_000)
    # disks inside the domain: the record's counts (uniform 20..80), spread over the whole range
    assert 19 < t[inside].min() < 30 and 70 < t[inside].max() < 81 and abs(np.median(t[inside]) - 50) < 10
    # a disk centred on a corner keeps about a quarter of its count, on a side about half
    corner = (x < 1000) & (y < 1000)
    assert np.all(t[corner] < 0.32 * 80) and np.all(t[corner] > 0.2 * 20)
    # with the number of peaks given, the border strip takes what the interior's density leaves:
    # fewer peaks than the record's mean count spread evenly -> a sparser strip, same interior
    even = 50.0 / (np.pi * R**2) * 60_000**2
    t2 = disk_count_targets([rec], controls, domain, 1000.0, R, np.random.default_rng(0), n=int(0.7 * even))[4]
    centre = (np.abs(x - 30_000) < 600) & (np.abs(y - 30_000) < 600)
    side = (np.abs(x - 30_000) < 600) & (y < 1000)
    assert np.all(t2[side] < 0.8 * t[side]) and np.all(t2[corner] < 0.8 * t[corner])
    assert np.allclose(t2[centre], t[centre])  # a disk clear of the strip keeps its count
    t3 = disk_count_targets([rec], controls, domain, 1000.0, R, np.random.default_rng(0), n=int(even))[4]
    assert np.all(np.abs(t3[side] / t[side] - 1) < 0.05)
    # neighbouring centres want similar counts (overlapping disks), distant ones need not
    g = t.reshape(ny, nx)
    assert np.median(np.abs(np.diff(g[10:50, 10:50], axis=1))) < 0.1 * np.ptp(g[10:50, 10:50])


def test_disk_count_weight_brings_the_per_disk_peak_counts_to_the_type(peak_factory):
    """A source whose peaks crowd in a few clusters (some 10 km disks hold many peaks, some few):
    with the per-disk count target the synthesized trees' per-disk counts, measured by
    disk_statistics on their own peaks, come closer to the source's than without it (seed 0:
    Wasserstein distance 35.2 peaks without, 21.6 with weight 3)."""
    rng = np.random.default_rng(7)
    p = peak_factory(900, seed=6, side_m=60_000.0)
    centres = rng.uniform(12_000, 48_000, (4, 2))
    half = np.arange(len(p)) % 2 == 0
    pick = rng.integers(0, 4, half.sum())
    p.loc[half, "x"] = np.clip(centres[pick, 0] + rng.normal(0, 4000, half.sum()), 0, 60_000)
    p.loc[half, "y"] = np.clip(centres[pick, 1] + rng.normal(0, 4000, half.sum()), 0, 60_000)
    ttype = TerrainType.from_peaks(p, area_km2=3600.0, name="clustered")
    plain, target = [], []
    for seed in range(3):
        plain.append(_disk_distance(synthesize_divide_tree(ttype, size_m=60_000, rng=seed), ttype, "peaks"))
        t = synthesize_divide_tree(ttype, size_m=60_000, rng=seed, params=SynthesisParams(disk_count_weight=3.0))
        t.validate()
        target.append(_disk_distance(t, ttype, "peaks"))
    assert np.mean(target) < 0.75 * np.mean(plain)
    with pytest.raises(InputError, match="disk_count_weight"):
        SynthesisParams(disk_count_weight=-1)
