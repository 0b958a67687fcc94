"""Saddle level term of the saddle OT (issue 11, session 17): with ``level_weight`` the prominence and
dominance targets go to the peaks that stand as far above their neighbours' saddles, so nearby saddles
lie nearer one level; the histograms are the same draws. Spreads are re-measured here by brute force."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from orokit.errors import InputError, OrokitWarning
from orokit.synthesis.ridges import delaunay_mst
from orokit.synthesis.saddles import SaddleTargets, assign_saddle_elevations, max_bin_errors
from orokit.synthesis.tree import SynthesisParams, synthesize_divide_tree

from helpers.type_records import check_optional_record


def _off_level_by_hand(x, y, a, b, sz, k: int = 16) -> float:
    """Mean over ridges of |saddle - median of the saddles of the k ridges nearest to its midpoint| (m)."""
    mx, my = 0.5 * (x[a] + x[b]), 0.5 * (y[a] + y[b])
    d = np.hypot(mx[:, None] - mx[None, :], my[:, None] - my[None, :])
    near = np.argsort(d, axis=1, kind="stable")[:, :k]
    return float(np.mean(np.abs(sz - np.median(sz[near], axis=1))))


@pytest.fixture(scope="module")
def dome_field(small_type):
    """Domes on a tilted plain: peak = plain + a dome height of the type's prominence range."""
    rng = np.random.default_rng(7)
    n = 300
    x, y = rng.uniform(0, 30_000, n), rng.uniform(0, 30_000, n)
    z = 400.0 + 0.002 * x + rng.uniform(30.0, 300.0, n)
    a, b = delaunay_mst(x, y, z)
    targets = SaddleTargets(np.zeros(n, np.int64), [small_type.histograms["dominance"]],
                            [small_type.histograms["prominence"]])
    return x, y, z, a, b, targets


def test_level_weight_brings_nearby_saddles_to_one_level(dome_field):
    x, y, z, a, b, targets = dome_field
    sz0 = np.minimum(z[a], z[b])
    for seed in (1, 2):
        free, _ = assign_saddle_elevations(z, x, y, a, b, sz0, targets, rng=seed)
        level, _ = assign_saddle_elevations(z, x, y, a, b, sz0, targets, rng=seed, level_weight=8.0)
        # 59-66 m without the term, 33 m with it (seeds 1-3)
        assert _off_level_by_hand(x, y, a, b, level) < 0.7 * _off_level_by_hand(x, y, a, b, free)
    # the saddles stay between 0 and their lower peak, and the histograms are matched about as well
    assert np.all(level <= np.minimum(z[a], z[b]) + 1e-9) and np.all(level >= -1e-9)
    assert max(max_bin_errors(z, a, b, level, targets)) <= max(max_bin_errors(z, a, b, free, targets)) + 0.05


def test_level_weight_zero_is_the_paper_cost(dome_field):
    x, y, z, a, b, targets = dome_field
    sz0 = np.minimum(z[a], z[b])
    free, _ = assign_saddle_elevations(z, x, y, a, b, sz0, targets, rng=3)
    zero, _ = assign_saddle_elevations(z, x, y, a, b, sz0, targets, rng=3, level_weight=0.0)
    assert np.array_equal(free, zero)


def test_synthesis_option(small_type):
    off = synthesize_divide_tree(small_type, size_m=30_000.0, rng=5)
    zero = synthesize_divide_tree(small_type, size_m=30_000.0, rng=5, params=SynthesisParams(saddle_level_weight=0.0))
    on = synthesize_divide_tree(small_type, size_m=30_000.0, rng=5, params=SynthesisParams(saddle_level_weight=8.0))
    assert off.saddles.equals(zero.saddles) and off.peaks.equals(zero.peaks)
    assert off.peaks.equals(on.peaks)  # the term moves saddles only
    assert not np.array_equal(off.saddles["elevation"].to_numpy(), on.saddles["elevation"].to_numpy())
    with pytest.raises(InputError, match="saddle_level_weight"):
        SynthesisParams(saddle_level_weight=-1.0)


def _level_by_hand(tree, k: int = 16) -> float:
    """saddle_level by brute force: median over ridges of (median - lowest) / (highest end - lowest), k nearest."""
    x, y, z = (tree.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    a, b = tree.edges["peak_a"].to_numpy(), tree.edges["peak_b"].to_numpy()
    s = tree.saddles["elevation"].to_numpy(float)[tree.edges["saddle"].to_numpy()]
    mx, my = 0.5 * (x[a] + x[b]), 0.5 * (y[a] + y[b])
    d = np.hypot(mx[:, None] - mx[None, :], my[:, None] - my[None, :])
    near = np.argsort(d, axis=1, kind="stable")[:, :k]
    top = np.maximum(z[a], z[b])[near].max(axis=1)
    lo = s[near].min(axis=1)
    return float(np.median((np.median(s[near], axis=1) - lo) / (top - lo)))


def test_type_records_saddle_level(synthesized_type):
    tree, t = synthesized_type
    assert t.saddle_level == pytest.approx(_level_by_hand(tree.prune(30.0)))
    check_optional_record(t, "saddle_level", 1.5)
    assert t.scaled("prominence", 1.5).saddle_level is None and t.with_density(0.5).saddle_level is None


def test_synthesis_follows_the_saddle_level(synthesized_type):
    _, t = synthesized_type
    free = synthesize_divide_tree(t, size_m=30_000.0, rng=3)
    got = _level_by_hand(free)
    # a type asking for saddles nearer one level than the free tree has
    target = 0.6 * got
    on = SynthesisParams(follow_saddle_level=True)
    fitted = synthesize_divide_tree(dataclasses.replace(t, saddle_level=target), size_m=30_000.0, rng=3, params=on)
    fit = fitted.attrs["saddle_level"]
    assert fit["weight"] > 0 and fit["reached"] == pytest.approx(_level_by_hand(fitted), abs=1e-4)
    assert abs(_level_by_hand(fitted) - target) < abs(got - target)
    assert fitted.peaks.equals(free.peaks)
    # a type already as level as the free tree: weight 0, the same tree as without the option
    easy = synthesize_divide_tree(dataclasses.replace(t, saddle_level=min(1.0, 1.5 * got)), size_m=30_000.0, rng=3,
                                  params=on)
    assert easy.attrs["saddle_level"]["weight"] == 0 and easy.saddles.equals(free.saddles)
    # without the record: off, and said (a type made before session 17)
    with pytest.warns(OrokitWarning, match="follow_saddle_level does nothing.*records no saddle_level.*orokit type"):
        none = synthesize_divide_tree(dataclasses.replace(t, saddle_level=None), size_m=30_000.0, rng=3, params=on)
    assert none.attrs["saddle_level"] is None and none.saddles.equals(free.saddles)


def test_follow_saddle_level_says_when_it_does_nothing(synthesized_type, small_type):
    """A mixture of types (one of them without ``saddle_level``) is synthesized without the fit, with a warning;
    the option off, or one type that records it, warns nothing."""
    import warnings

    _, t = synthesized_type
    on = SynthesisParams(follow_saddle_level=True)
    type_map = np.zeros((8, 8), dtype=np.int64)
    type_map[:, 4:] = 1
    with pytest.warns(OrokitWarning, match="follow_saddle_level does nothing.*mixes 2 types"):
        mixed = synthesize_divide_tree([t, small_type], size_m=20_000.0, type_map=type_map, rng=4, params=on)
    assert mixed.attrs["saddle_level"] is None
    with warnings.catch_warnings():
        warnings.simplefilter("error", OrokitWarning)
        synthesize_divide_tree([t, small_type], size_m=20_000.0, type_map=type_map, rng=4)
        assert synthesize_divide_tree(t, size_m=20_000.0, rng=4, params=on).attrs["saddle_level"] is not None
