"""Plain dominance (issue 11, session 19): each peak's prominence over its height above the lowest saddle of the
16 ridges nearest to it (other than its key ridge). Types record its histogram; ``follow_plain_dominance``
makes it a third feature of the saddle OT. Values are re-measured here by brute force (distances over all
ridges, key saddles from :meth:`DivideTree.prominence_table`)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
from scipy.stats import wasserstein_distance

from orokit.errors import InputError, OrokitWarning
from orokit.synthesis.ridges import delaunay_mst
from orokit.synthesis.saddles import plain_dominance
from orokit.synthesis.terrain_type import FeatureHistogram, TerrainType
from orokit.synthesis.tree import SynthesisParams, synthesize_divide_tree
from orokit.topology.divide_tree import DivideTree

from helpers.type_records import check_optional_record


def _plain_by_hand(tree: DivideTree, k: int = 16) -> np.ndarray:
    """min(1, prominence / (h - s0)) per non-root peak, s0 the lowest saddle of the k ridges whose midpoints lie
    nearest to the peak, its key ridge left out (brute-force distances; ties by ridge index)."""
    x, y, z = (tree.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    a, b = tree.edges["peak_a"].to_numpy(), tree.edges["peak_b"].to_numpy()
    s = tree.saddles["elevation"].to_numpy(float)[tree.edges["saddle"].to_numpy()]
    ridge_of_saddle = np.empty(len(s), np.int64)
    ridge_of_saddle[tree.edges["saddle"].to_numpy()] = np.arange(len(a))
    table = tree.prominence_table()
    ks = table["key_saddle"].to_numpy()
    prom = table["prominence"].to_numpy(float)
    mx, my = 0.5 * (x[a] + x[b]), 0.5 * (y[a] + y[b])
    out = []
    for p in np.flatnonzero(ks >= 0):
        own = ridge_of_saddle[ks[p]]
        d = np.hypot(mx - x[p], my - y[p])
        order = [e for e in np.argsort(d, kind="stable") if e != own][:k]
        s0 = s[order].min()
        out.append(1.0 if z[p] - prom[p] <= s0 else prom[p] / (z[p] - s0))
    return np.clip(np.asarray(out), 0.0, 1.0)


def _dune_field(seed: int, n: int = 500, side_m: float = 40_000.0) -> DivideTree:
    """Domes on a tilted plain: most ridges' saddles lie on the plain (a dune's key saddle is the plain: plain
    dominance near 1), a quarter of them up on the lower dome (subsidiary tops: low plain dominance)."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, side_m, n), rng.uniform(0, side_m, n)
    plain = 200.0 + 0.002 * x + 0.001 * y
    z = plain + rng.uniform(40.0, 200.0, n)
    a, b = delaunay_mst(x, y, z)
    mx, my = 0.5 * (x[a] + x[b]), 0.5 * (y[a] + y[b])
    low = np.minimum(z[a], z[b])
    s = 200.0 + 0.002 * mx + 0.001 * my + rng.uniform(0.0, 5.0, a.size)
    up = rng.random(a.size) < 0.25
    s = np.where(up, low - rng.uniform(30.0, 60.0, a.size), s)
    s = np.minimum(s, low - 30.0)
    return DivideTree(pd.DataFrame({"x": x, "y": y, "elevation": z}),
                      pd.DataFrame({"x": mx, "y": my, "elevation": s}),
                      pd.DataFrame({"peak_a": a, "peak_b": b, "saddle": np.arange(a.size)}), None, {"units": "m"})


@pytest.fixture(scope="module")
def dune_type():
    tree = _dune_field(3)
    return tree, TerrainType.from_divide_tree(tree, area_km2=1600.0, min_prominence_m=30.0, name="dunes")


def test_plain_dominance_matches_brute_force(synthesized_type):
    tree, _ = synthesized_type
    x, y, z = (tree.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    a, b = tree.edges["peak_a"].to_numpy(np.int64), tree.edges["peak_b"].to_numpy(np.int64)
    s = tree.saddles["elevation"].to_numpy(float)[tree.edges["saddle"].to_numpy()]
    got = plain_dominance(z, x, y, a, b, s)
    roots = tree.prominence_table()["key_saddle"].to_numpy() < 0
    assert np.isnan(got[roots]).all() and np.isfinite(got[~roots]).all()
    np.testing.assert_allclose(got[~roots], _plain_by_hand(tree), atol=1e-12)
    assert 0.0 < np.median(got[~roots]) < 1.0  # not a constant


def test_type_records_plain_dominance(dune_type):
    tree, t = dune_type
    want = FeatureHistogram.from_values(_plain_by_hand(tree.prune(30.0)), np.linspace(0.0, 1.0, 41))
    assert t.plain_dominance is not None
    np.testing.assert_allclose(t.plain_dominance.counts, want.counts)
    check_optional_record(t, "plain_dominance", FeatureHistogram((0.0, 0.5, 1.5), (1.0, 1.0)))
    assert t.scaled("prominence", 1.5).plain_dominance is None and t.with_density(0.5).plain_dominance is None


def test_dune_field_twins_get_their_key_saddles_on_the_plain(dune_type):
    """The source's dunes stand with most of their height above the lowest nearby saddle (median 0.92); the
    paper's OT scatters the twins' key saddles above it (median 0.69-0.71, W1 0.15). With the option the twins
    come close (W1 0.02-0.03, seeds 1-2) at a cost in the prominence histogram (max-bin error 0.01-0.02 ->
    0.10-0.12: the trade of the option, see NOTES). Per-band targets: with ``use_bands="auto"`` this source's
    twins take the marginal targets, where neither setting comes close (W1 0.26-0.28)."""
    tree, t = dune_type
    real = _plain_by_hand(tree.prune(30.0))
    for seed in (1, 2):
        free = synthesize_divide_tree(t, size_m=40_000.0, rng=seed, params=SynthesisParams(use_bands=True))
        fit = synthesize_divide_tree(t, size_m=40_000.0, rng=seed,
                                     params=SynthesisParams(use_bands=True, follow_plain_dominance=True))
        assert fit.peaks.equals(free.peaks)  # saddles only
        w_free = wasserstein_distance(real, _plain_by_hand(free))
        w_fit = wasserstein_distance(real, _plain_by_hand(fit))
        assert w_fit < 0.5 * w_free
        assert abs(np.median(_plain_by_hand(fit)) - np.median(real)) < 0.05 < np.median(real) - np.median(
            _plain_by_hand(free))
        a, b = fit.edges["peak_a"].to_numpy(), fit.edges["peak_b"].to_numpy()
        s, z = fit.saddles["elevation"].to_numpy(float), fit.peaks["elevation"].to_numpy(float)
        assert np.all(s <= np.minimum(z[a], z[b]) + 1e-9) and np.all(s >= -1e-9)
        assert fit.attrs["plain_dominance"] and not free.attrs["plain_dominance"]
        assert len(fit.attrs["ot_errors"][0]) == 3 and len(free.attrs["ot_errors"][0]) == 2


def test_without_the_record_the_option_does_nothing_and_says_so(dune_type, small_type):
    import warnings

    _, t = dune_type
    on = SynthesisParams(follow_plain_dominance=True)
    free = synthesize_divide_tree(t, size_m=20_000.0, rng=4)
    with pytest.warns(OrokitWarning, match="follow_plain_dominance does nothing.*records no plain_dominance"):
        none = synthesize_divide_tree(dataclasses.replace(t, plain_dominance=None), size_m=20_000.0, rng=4, params=on)
    assert none.saddles.equals(free.saddles) and none.peaks.equals(free.peaks)
    assert small_type.plain_dominance is None  # a type from a peak table without a tree
    with warnings.catch_warnings():
        warnings.simplefilter("error", OrokitWarning)
        synthesize_divide_tree(t, size_m=20_000.0, rng=4, params=on)
    with pytest.raises(InputError, match="follow_plain_dominance"):
        SynthesisParams(follow_plain_dominance=1)  # type: ignore[arg-type]
