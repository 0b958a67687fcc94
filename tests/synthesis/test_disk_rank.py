"""The disks' median elevation rank and peak relief (issue 11, sessions 18-19): a type records how low its lowest
10 km disks lie among its peaks and how far its disks' peak elevations spread, and ``follow_disk_rank`` keeps a
twin's disks inside that span on both tails. Disk medians and reliefs are re-measured here by brute force."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from helpers.peak_fields import random_peak_field
from orokit.errors import InputError, OrokitWarning, SchemaError
from orokit.synthesis.disks import DISK_RADIUS_M, disk_centres, disk_quantiles, disk_statistics, level_quantiles
from orokit.synthesis.terrain_type import TerrainType
from orokit.synthesis.tree import (DISK_RANK_HIGH_LEVELS, DISK_RANK_LEVELS, SynthesisParams, _fit_disk_rank,
                                   disk_rank_margins, peaks_table, synthesize_divide_tree)


def _median_ranks_by_hand(x, y, z, extent, step_m: float = 2_500.0, relief: bool = False) -> np.ndarray:
    """Per disk inside ``extent``: median over its peaks of (number of peaks lower + 0.5) / n (ties apart), or
    with ``relief`` the spread of its peaks' elevations (sorted, 90th minus 10th percentile interpolated by hand)."""
    n = z.size
    rank = (np.array([np.sum(z < v) for v in z]) + 0.5) / n
    cx, cy, _ = disk_centres(extent, DISK_RADIUS_M, step_m)
    out = []
    for px, py in zip(cx, cy):
        inside = np.hypot(x - px, y - py) <= DISK_RADIUS_M
        if not inside.any():
            out.append(np.nan)
        elif relief:
            v = np.sort(z[inside])
            at = [q * (v.size - 1) for q in (0.1, 0.9)]
            lo, hi = (v[int(a)] + (a - int(a)) * (v[min(int(a) + 1, v.size - 1)] - v[int(a)]) for a in at)
            out.append(hi - lo)
        else:
            out.append(np.median(rank[inside]))
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
    relief = _median_ranks_by_hand(x[keep], y[keep], z[keep], ext, relief=True)
    assert np.allclose(s["peak_relief_m"], relief, equal_nan=True) and np.nanmax(relief) > 1000
    # an empty disk has no median
    e = disk_statistics(np.array([5_000.0]), np.array([5_000.0]), np.ones(1), np.full(1, 50.0), (0, 0, 60_000, 20_000),
                        step_m=5_000)
    assert np.isnan(e["median_rank"][-1]) and e["median_rank"][0] == 0.5


def test_type_records_median_rank_and_old_types_are_unchanged(small_type):
    mr = small_type.disks["median_rank"]
    assert len(mr) == len(small_type.disks["levels"]) and 0 <= mr[0] <= mr[-1] <= 1 and np.all(np.diff(mr) >= 0)
    pr = small_type.disks["peak_relief_m"]
    assert len(pr) == len(mr) and 0 <= pr[0] <= pr[-1] and np.all(np.diff(pr) >= 0) and pr[-1] > 0
    assert TerrainType.from_dict(small_type.to_dict()).disks == small_type.disks
    for key, values in (("median_rank", list(reversed(mr))), ("peak_relief_m", [-1.0] + pr[1:]),
                        ("peak_relief_m", list(reversed(pr)))):
        bad = small_type.to_dict()
        bad["disks"] = dict(bad["disks"], **{key: values})
        with pytest.raises(SchemaError, match=key):
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
    for bad_params in ({"follow_disk_rank": 1}, {"disk_rank_draws": 0}, {"disk_rank_tolerance": -0.1}):
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
        assert 1 <= rec["draws"] <= SynthesisParams().disk_rank_draws and rec["low_levels"] == list(DISK_RANK_LEVELS)
        plain.append(_shortfall(_tree_ranks(p0), ttype))
        fitted.append(_shortfall(_tree_ranks(p1), ttype))
    assert np.mean(fitted) > np.mean(plain) + 0.05


def test_a_placement_inside_is_the_one_made_without_the_option(small_type):
    """With a tolerance nothing lies outside of, draw 0 is kept: the tree is the one made without the option,
    byte for byte (the ridges and saddles draw as without it); with none, the option redraws and differs."""
    fast = {"follow_neighbour_gradient": False}
    for seed in (1,):
        plain = synthesize_divide_tree(small_type, size_m=30_000, rng=seed, params=SynthesisParams(**fast))
        on = synthesize_divide_tree(small_type, size_m=30_000, rng=seed, params=SynthesisParams(
            follow_disk_rank=True, disk_rank_tolerance=1e9, **fast))
        assert on.attrs["disk_rank"]["draw"] == 0 and on.attrs["disk_rank"]["draws"] == 1
        assert _digest(on) == _digest(plain)
        strict = synthesize_divide_tree(small_type, size_m=30_000, rng=seed, params=SynthesisParams(
            follow_disk_rank=True, disk_rank_tolerance=0.0, disk_rank_draws=3, **fast))
        rec = strict.attrs["disk_rank"]
        assert (_digest(strict) == _digest(plain)) == (rec["draw"] == 0)
        assert rec["draws"] == 3 or rec["margin"] >= 0.0


def _disk_record(x, y, z, extent) -> dict:
    """A type's ``disks`` record of a peak set (as :meth:`TerrainType.from_peaks` makes it; every peak counted)."""
    stats = disk_statistics(x, y, z, np.full(z.size, 500.0), extent)
    return dict(disk_quantiles(stats), median_rank=level_quantiles(stats["median_rank"]),
                peak_relief_m=level_quantiles(stats["peak_relief_m"]))


def _trend_field(seed: int):
    """400 peaks on 40 km x 40 km rising 4 km from west to east, and the same elevations with the lowest fifth
    moved onto a regular grid (a low peak in every disk: the low tail kept, every disk's relief up)."""
    x, y, z, _ = random_peak_field(seed, 400, 40_000, 40_000)
    z = 0.3 * z + 0.1 * x
    low = np.argsort(z)[:80]
    gx, gy = np.meshgrid(np.linspace(2_000, 38_000, 10), np.linspace(2_000, 38_000, 8))
    vx, vy = x.copy(), y.copy()
    vx[low], vy[low] = gx.ravel(), gy.ravel()
    return (0.0, 0.0, 40_000.0, 40_000.0), x, y, z, vx, vy


def test_margins_judge_both_tails_and_the_relief():
    """The margins, re-measured by hand: the source itself is inside; the valley-in-every-disk placement keeps
    its low tail but lies outside on the relief; the high ground pulled down lies outside on the high tail."""
    ext, x, y, z, vx, vy = _trend_field(3)
    rec = _disk_record(x, y, z, ext)
    assert disk_rank_margins(x, y, z, ext, rec)["margin"] > -0.02
    m = disk_rank_margins(vx, vy, z, ext, rec)
    relief = _median_ranks_by_hand(vx, vy, z, ext, relief=True)
    want = np.interp(DISK_RANK_HIGH_LEVELS, rec["levels"], rec["peak_relief_m"])
    assert np.allclose(m["relief"], 1.0 - np.quantile(relief[np.isfinite(relief)], DISK_RANK_HIGH_LEVELS) / want)
    assert m["margin"] == pytest.approx(min(0.0, *m["low"], *m["high"], *m["relief"]))
    assert np.min(m["low"]) > -0.02 and np.min(m["relief"]) < -0.2
    top = np.where(z > np.median(z), np.median(z) + 0.2 * (z - np.median(z)), z)  # the high ground cut down
    h = disk_rank_margins(x, y, top, ext, rec)
    med = _median_ranks_by_hand(x, y, top, ext)
    assert np.allclose(h["high"], np.interp(DISK_RANK_HIGH_LEVELS, rec["levels"], rec["median_rank"])
                       - np.quantile(med[np.isfinite(med)], DISK_RANK_HIGH_LEVELS))
    old = {k: v for k, v in rec.items() if k != "peak_relief_m"}  # a session-18 type: no relief to judge
    assert "relief" not in disk_rank_margins(vx, vy, z, ext, old)


def test_fit_keeps_the_first_placement_inside_on_both_tails():
    """Draw 0 is kept when inside (nothing redrawn); from a basin of low peaks (low tail outside), a redraw that
    keeps the low tail with a valley in every disk is passed over for a later one inside on every margin; with
    none inside, the one outside by least: here the basin, since the valley lies further outside on the relief."""
    from types import SimpleNamespace

    ext, x, y, z, vx, vy = _trend_field(5)
    dom = SimpleNamespace(x0=ext[0], y0=ext[1], width=ext[2], height=ext[3])
    rec = _disk_record(x, y, z, ext)
    bx = x.copy()
    west = (x < 20_000) & (z > np.quantile(z, 0.2))
    bx[west] = 40_000 - 0.5 * x[west]  # the west holds only the lowest fifth: disks lower than any of the source
    same, basin, valley = (None, x, y), (None, bx, y), (None, vx, vy)
    bm, vm = (disk_rank_margins(p[1], p[2], z, ext, rec) for p in (basin, valley))  # valley: outside by more
    assert np.min(bm["low"]) < -0.05 and np.min(vm["low"]) > -0.05 and vm["margin"] < -0.05
    assert disk_rank_margins(x, y, z, ext, rec)["margin"] > -0.05  # the source's own placement on another grid

    def redraws(items):
        it = iter(items)
        return lambda gen: next(it)

    kept, fit = _fit_disk_rank(same, redraws([]), 0, rec, z, dom, 8, 0.05)
    assert kept is same and (fit["draw"], fit["draws"]) == (0, 1)
    kept, fit = _fit_disk_rank(basin, redraws([valley, same]), 0, rec, z, dom, 8, 0.05)
    assert kept is same and (fit["draw"], fit["draws"]) == (2, 3) and set(fit) >= {"low", "high", "relief"}
    kept, fit = _fit_disk_rank(basin, redraws([valley, valley]), 0, rec, z, dom, 3, 0.05)
    best = max(bm["margin"], vm["margin"])
    assert fit["draws"] == 3 and fit["margin"] == pytest.approx(best, abs=1e-4) and best < -0.05
    assert kept is basin and fit["draw"] == 0 and vm["margin"] < bm["margin"]  # low tail alone would take valley
    kept, fit = _fit_disk_rank(basin, redraws([valley, same]), 0, rec, z, dom, 1, 0.05)  # one draw: never redrawn
    assert kept is basin and fit["draws"] == 1
