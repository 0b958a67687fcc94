"""The disks' median elevation rank (issue 11, session 18): a type records how low its lowest 10 km disks lie
among its peaks, and ``follow_disk_rank`` keeps a twin's lowest disks from lying far lower. Disk medians are
re-measured here by brute force on the synthesized trees' own peaks."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from helpers.peak_fields import random_peak_field
from orokit.errors import InputError, OrokitWarning, SchemaError
from orokit.synthesis.disks import DISK_RADIUS_M, disk_centres, disk_statistics
from orokit.synthesis.terrain_type import TerrainType
from orokit.synthesis.tree import DISK_RANK_LEVELS, SynthesisParams, peaks_table, synthesize_divide_tree


def _median_ranks_by_hand(x, y, z, extent, step_m: float = 2_500.0) -> np.ndarray:
    """Per disk inside ``extent``: median over its peaks of (number of peaks lower + 0.5) / n (ties apart)."""
    n = z.size
    rank = (np.array([np.sum(z < v) for v in z]) + 0.5) / n
    cx, cy, _ = disk_centres(extent, DISK_RADIUS_M, step_m)
    out = []
    for px, py in zip(cx, cy):
        inside = np.hypot(x - px, y - py) <= DISK_RADIUS_M
        out.append(np.median(rank[inside]) if inside.any() else np.nan)
    return np.asarray(out)


def _tree_ranks(tree, eps: float = 30.0) -> np.ndarray:
    pk = peaks_table(tree)
    pk = pk[pk["prominence"].to_numpy(float) >= eps]
    d = tree.attrs["domain"]
    m = _median_ranks_by_hand(pk["x"].to_numpy(float), pk["y"].to_numpy(float), pk["elevation"].to_numpy(float),
                              (d["x0"], d["y0"], d["x0"] + d["width"], d["y0"] + d["height"]))
    return m[np.isfinite(m)]


def _shortfall(ranks: np.ndarray, ttype: TerrainType) -> float:
    """How far the tree's low quantiles of the disks' median rank fall under the type's (<= 0: short)."""
    target = np.interp(DISK_RANK_LEVELS, ttype.disks["levels"], ttype.disks["median_rank"])
    return float(np.min(np.quantile(ranks, DISK_RANK_LEVELS) - target))


def _digest(tree) -> str:
    parts = [tree.peaks[["x", "y", "elevation"]], tree.saddles[["x", "y", "elevation"]], tree.edges]
    return hashlib.sha256(b"".join(np.ascontiguousarray(p.to_numpy()).tobytes() for p in parts)).hexdigest()


def test_median_rank_matches_brute_force():
    x, y, z, prom = random_peak_field(11, 250, 40_000, 30_000)
    ext = (0, 0, 40_000, 30_000)
    s = disk_statistics(x, y, z, prom, ext, min_prominence_m=30.0, step_m=2_500)
    keep = prom >= 30
    hand = _median_ranks_by_hand(x[keep], y[keep], z[keep], ext)
    assert s["median_rank"].shape == hand.shape
    assert np.allclose(s["median_rank"], hand, equal_nan=True)
    # an empty disk has no median
    e = disk_statistics(np.array([5_000.0]), np.array([5_000.0]), np.ones(1), np.full(1, 50.0), (0, 0, 60_000, 20_000),
                        step_m=5_000)
    assert np.isnan(e["median_rank"][-1]) and e["median_rank"][0] == 0.5


def test_type_records_median_rank_and_old_types_are_unchanged(small_type):
    mr = small_type.disks["median_rank"]
    assert len(mr) == len(small_type.disks["levels"]) and 0 <= mr[0] <= mr[-1] <= 1 and np.all(np.diff(mr) >= 0)
    assert TerrainType.from_dict(small_type.to_dict()).disks == small_type.disks
    bad = small_type.to_dict()
    bad["disks"] = dict(bad["disks"], median_rank=list(reversed(mr)))
    with pytest.raises(SchemaError, match="median_rank"):
        TerrainType.from_dict(bad)
    # a type written before the record: the option changes nothing
    old = small_type.to_dict()
    old["disks"] = {k: v for k, v in old["disks"].items() if k != "median_rank"}
    old_type = TerrainType.from_dict(old)
    assert "median_rank" not in old_type.disks
    fast = {"follow_neighbour_gradient": False}
    plain = synthesize_divide_tree(old_type, size_m=30_000, rng=4, params=SynthesisParams(**fast))
    with pytest.warns(OrokitWarning, match="follow_disk_rank does nothing here.*median_rank"):
        on = synthesize_divide_tree(old_type, size_m=30_000, rng=4,
                                    params=SynthesisParams(follow_disk_rank=True, **fast))
    assert _digest(on) == _digest(plain) and on.attrs["disk_rank"] is None
    with pytest.warns(OrokitWarning, match="no automatic C_H"):
        synthesize_divide_tree(small_type, size_m=30_000, rng=4,
                               params=SynthesisParams(follow_disk_rank=True, auto_elevation_m=None, **fast))
    for bad_params in ({"follow_disk_rank": 1}, {"disk_rank_draws": 0}):
        with pytest.raises(InputError):
            SynthesisParams(**bad_params)


def test_follow_disk_rank_keeps_the_lowest_disks_up(peak_factory):
    """A source whose peak elevations do not cluster (every 10 km disk's median near the middle): the default
    smooth C_H gathers the low peaks in basins, so some twin disks lie far lower (lowest disk 0.18-0.32 on these
    seeds against the source's 0.43); with the option the tree's low quantiles, re-measured by hand, come closer."""
    ttype = TerrainType.from_peaks(peak_factory(400, seed=4, side_m=40_000.0), area_km2=1600.0, name="even")
    fast = {"follow_neighbour_gradient": False}
    plain, fitted = [], []
    for seed in range(3):
        p0 = synthesize_divide_tree(ttype, size_m=40_000, rng=seed, params=SynthesisParams(**fast))
        p1 = synthesize_divide_tree(ttype, size_m=40_000, rng=seed, params=SynthesisParams(follow_disk_rank=True, **fast))
        p1.validate()
        rec = p1.attrs["disk_rank"]
        assert 1 <= rec["draws"] <= SynthesisParams().disk_rank_draws and rec["levels"] == list(DISK_RANK_LEVELS)
        plain.append(_shortfall(_tree_ranks(p0), ttype))
        fitted.append(_shortfall(_tree_ranks(p1), ttype))
    assert np.mean(fitted) > np.mean(plain) + 0.05
