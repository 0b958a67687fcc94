"""Ridge contrast (issue 11, session 8): synthesized ridges join low peaks to higher ones as often
as the source tree's do. Contrasts are re-measured here with scipy's Delaunay, not the code's."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial import Delaunay

from orokit.errors import SchemaError
from orokit.synthesis.fidelity import compare_to_type
from orokit.synthesis.ridges import delaunay_mst, fit_ridge_contrast, ridge_contrast
from orokit.synthesis.terrain_type import TerrainType
from orokit.synthesis.tree import SynthesisParams, synthesize_divide_tree


def _contrast_by_hand(x, y, z, a, b) -> float:
    """Median |dz| over the ridges / median |dz| over the Delaunay edges (scipy's triangulation)."""
    s = Delaunay(np.column_stack([x, y])).simplices
    e = np.unique(np.sort(np.concatenate([s[:, [0, 1]], s[:, [1, 2]], s[:, [0, 2]]]), axis=1), axis=0)
    return float(np.median(np.abs(z[a] - z[b])) / np.median(np.abs(z[e[:, 0]] - z[e[:, 1]])))


def _field(n=500, seed=0):
    """Peaks on a smooth elevation trend plus noise: neighbours of similar height dominate."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(0, 30_000, n), rng.uniform(0, 30_000, n)
    z = 1500 + 600 * np.sin(x / 6000.0) * np.cos(y / 8000.0) + rng.normal(0, 150, n)
    return x, y, z


def _is_spanning_tree(a, b, n) -> bool:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(a.size), (a, b)), shape=(n, n))
    return a.size == n - 1 and connected_components(g, directed=False)[0] == 1


def test_ridge_contrast_matches_a_hand_count():
    x, y, z = _field()
    a, b = delaunay_mst(x, y, z, rho=1.0)
    assert ridge_contrast(x, y, z, a, b) == pytest.approx(_contrast_by_hand(x, y, z, a, b))
    flat = np.full(x.size, 100.0)
    assert np.isnan(ridge_contrast(x, y, flat, a, b))  # every Delaunay edge has dz = 0: undefined


def test_fit_reaches_a_contrast_the_paper_weight_misses():
    x, y, z = _field()
    a0, b0 = delaunay_mst(x, y, z, rho=1.0)
    c0 = _contrast_by_hand(x, y, z, a0, b0)
    a, b, strength, reached = fit_ridge_contrast(x, y, z, c0 + 0.3, rho=1.0)
    assert strength > 0 and _is_spanning_tree(a, b, x.size)
    assert _contrast_by_hand(x, y, z, a, b) == pytest.approx(reached)
    assert abs(reached - (c0 + 0.3)) < 0.05
    # ridges with a larger contrast are also longer (real trees have the longer ridges, issue 11)
    assert np.median(np.hypot(x[a] - x[b], y[a] - y[b])) > np.median(np.hypot(x[a0] - x[b0], y[a0] - y[b0]))
    # the paper's own contrast as target: the paper's tree
    a1, b1, s1, _ = fit_ridge_contrast(x, y, z, c0, rho=1.0)
    assert s1 == 0.0
    assert set(zip(a1.tolist(), b1.tolist())) == set(zip(a0.tolist(), b0.tolist()))


def test_type_records_its_tree_contrast_and_round_trips(small_type):
    tree = synthesize_divide_tree(small_type, size_m=30_000.0, rng=2)
    t = TerrainType.from_divide_tree(tree, area_km2=900.0, min_prominence_m=30.0)
    pruned = tree.prune(30.0)
    x, y, z = (pruned.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    want = _contrast_by_hand(x, y, z, pruned.edges["peak_a"].to_numpy(), pruned.edges["peak_b"].to_numpy())
    assert t.ridge_contrast == pytest.approx(want)
    assert TerrainType.from_dict(t.to_dict()).ridge_contrast == pytest.approx(want)
    old = t.to_dict()
    del old["ridge_contrast"]  # a type written before session 8
    assert TerrainType.from_dict(old).ridge_contrast is None
    assert t.scaled("elevation", 2.0).ridge_contrast == t.ridge_contrast  # a ratio: edits keep it
    with pytest.raises(SchemaError, match="ridge_contrast"):
        dataclasses.replace(t, ridge_contrast=-1.0)


def test_synthesis_follows_the_type_contrast(small_type):
    size = 30_000.0
    params_off = SynthesisParams(follow_ridge_contrast=False)
    base = synthesize_divide_tree(small_type, size_m=size, rng=5, params=params_off)
    x, y, z = (base.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    c_paper = _contrast_by_hand(x, y, z, base.edges["peak_a"].to_numpy(), base.edges["peak_b"].to_numpy())
    assert small_type.ridge_contrast is None and base.attrs["ridge_contrast"] is None
    target = dataclasses.replace(small_type, ridge_contrast=c_paper + 0.25)
    off = synthesize_divide_tree(target, size_m=size, rng=5, params=params_off)
    assert off.edges.equals(base.edges)  # off: the type's record is ignored
    on = synthesize_divide_tree(target, size_m=size, rng=5)
    x, y, z = (on.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    got = _contrast_by_hand(x, y, z, on.edges["peak_a"].to_numpy(), on.edges["peak_b"].to_numpy())
    assert abs(got - (c_paper + 0.25)) < 0.05 and on.attrs["ridge_contrast"]["reached"] == pytest.approx(got, abs=1e-3)
    on.validate()
    assert compare_to_type(on, small_type)["max_bin_error"].max() < 0.2
