"""Neighbour gradient and ridge-slope bound (issue 11, session 9): a type records how much its
neighbouring peaks differ in elevation and how steep its steepest ridges are; synthesis follows
both. Values are re-measured here by brute force, not with the code's KD-tree or quantile."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from orokit.errors import InputError, SchemaError
from orokit.synthesis.controls import make_domain, random_elevation_field, random_elevation_fields
from orokit.synthesis.fidelity import compare_to_type
from orokit.synthesis.ridges import delaunay_mst
from orokit.synthesis.saddles import SaddleTargets, assign_saddle_elevations
from orokit.synthesis.terrain_type import TerrainType
from orokit.synthesis.tree import SynthesisParams, synthesize_divide_tree


def _nn_gradient_by_hand(x, y, z) -> np.ndarray:
    d = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
    np.fill_diagonal(d, np.inf)
    j = np.argmin(d, axis=1)
    return np.abs(z - z[j]) / d[np.arange(x.size), j]


def _ridge_slopes(tree) -> np.ndarray:
    x, y, z = (tree.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    a, b = tree.edges["peak_a"].to_numpy(), tree.edges["peak_b"].to_numpy()
    s = tree.saddles["elevation"].to_numpy(float)[tree.edges["saddle"].to_numpy()]
    return (z[a] + z[b] - 2 * s) / np.hypot(x[a] - x[b], y[a] - y[b])


def test_type_records_neighbour_gradient_and_ridge_slope(synthesized_type):
    tree, t = synthesized_type
    pruned = tree.prune(30.0)
    x, y, z = (pruned.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    assert t.neighbour_gradient == pytest.approx(float(np.median(_nn_gradient_by_hand(x, y, z))))
    slopes = np.sort(_ridge_slopes(pruned))
    # the 99th percentile lies between the two order statistics around it
    k = 0.99 * (slopes.size - 1)
    assert slopes[int(np.floor(k))] <= t.max_ridge_slope <= slopes[int(np.ceil(k))]
    back = TerrainType.from_dict(t.to_dict())
    assert (back.neighbour_gradient, back.max_ridge_slope) == (t.neighbour_gradient, t.max_ridge_slope)
    old = t.to_dict()
    del old["neighbour_gradient"], old["max_ridge_slope"]  # a type written before session 9
    assert TerrainType.from_dict(old).neighbour_gradient is None and TerrainType.from_dict(old).max_ridge_slope is None
    with pytest.raises(SchemaError, match="max_ridge_slope"):
        dataclasses.replace(t, max_ridge_slope=-0.1)
    with pytest.raises(SchemaError, match="neighbour_gradient"):
        dataclasses.replace(t, neighbour_gradient=float("nan"))


def test_edits_drop_the_records_that_no_longer_hold(synthesized_type):
    _, t = synthesized_type
    shifted = t.shifted("elevation", 500.0)  # a shift changes no gradient
    assert (shifted.neighbour_gradient, shifted.max_ridge_slope) == (t.neighbour_gradient, t.max_ridge_slope)
    scaled = t.scaled("elevation", 2.0)
    assert scaled.neighbour_gradient is None and scaled.max_ridge_slope is None
    prom = t.scaled("prominence", 1.5)  # deeper saddles: the ridge-slope bound goes, neighbours stay
    assert prom.neighbour_gradient == t.neighbour_gradient and prom.max_ridge_slope is None
    turned = t.with_counts("saddle_direction", np.ones(t.histograms["saddle_direction"].n_bins))
    assert turned.max_ridge_slope == t.max_ridge_slope
    dense = t.with_density(2 * t.peak_density_per_km2)
    assert dense.neighbour_gradient is None and dense.max_ridge_slope is None


def test_saddles_never_fall_below_the_ridge_slope_bound(small_type, peak_table):
    rng = np.random.default_rng(4)
    n = 300
    x, y = rng.uniform(0, 30_000, n), rng.uniform(0, 30_000, n)
    z = np.sort(rng.uniform(300, 2500, n))[::-1]
    a, b = delaunay_mst(x, y, z)
    targets = SaddleTargets(np.zeros(n, np.int64), [small_type.histograms["dominance"]],
                            [small_type.histograms["prominence"]])
    sz0 = np.minimum(z[a], z[b])
    free, _ = assign_saddle_elevations(z, x, y, a, b, sz0, targets, rng=1)
    length = np.hypot(x[a] - x[b], y[a] - y[b])
    slope_free = (z[a] + z[b] - 2 * free) / length
    cap = float(np.quantile(slope_free, 0.8))
    capped, _ = assign_saddle_elevations(z, x, y, a, b, sz0, targets, rng=1, max_ridge_slope=cap)
    floor = np.minimum(np.maximum(0.5 * (z[a] + z[b] - cap * length), 0.0), np.minimum(z[a], z[b]))
    assert (free < floor - 1e-6).sum() >= 0.1 * a.size  # without the bound a fifth of the ridges go deeper
    assert np.all(capped >= floor - 1e-9)
    assert np.all(capped <= np.minimum(z[a], z[b]) + 1e-9)


def test_synthesis_follows_the_ridge_slope_bound(synthesized_type):
    _, t = synthesized_type
    on = SynthesisParams(follow_ridge_slope=True)
    free = synthesize_divide_tree(dataclasses.replace(t, max_ridge_slope=None), size_m=30_000.0, rng=3, params=on)
    cap = float(np.quantile(_ridge_slopes(free), 0.9))
    capped_type = dataclasses.replace(t, max_ridge_slope=cap)
    capped = synthesize_divide_tree(capped_type, size_m=30_000.0, rng=3, params=on)
    off = synthesize_divide_tree(capped_type, size_m=30_000.0, rng=3, params=SynthesisParams(follow_ridge_slope=False))
    assert capped.attrs["max_ridge_slope"] == pytest.approx(cap) and off.attrs["max_ridge_slope"] is None
    assert off.saddles.equals(free.saddles)  # off: the record is ignored
    over = lambda tr: float(np.mean(_ridge_slopes(tr) > cap + 1e-9))  # noqa: E731
    assert over(free) >= 0.08 and over(capped) < 0.5 * over(free)
    capped.validate()
    assert compare_to_type(capped, t)["max_bin_error"].max() < 0.2
    # the factor scales the bound: twice the cap lets more ridges over the cap
    loose = synthesize_divide_tree(capped_type, size_m=30_000.0, rng=3,
                                   params=SynthesisParams(follow_ridge_slope=True, ridge_slope_factor=2.0))
    assert loose.attrs["max_ridge_slope"] == pytest.approx(2 * cap)
    assert over(loose) > over(capped)
    with pytest.raises(InputError, match="ridge_slope_factor"):
        SynthesisParams(ridge_slope_factor=0.0)


def test_fine_elevation_fields():
    dom = make_domain(30_000.0, grid_cells=128)
    from orokit.synthesis.terrain_type import FeatureHistogram

    hist = FeatureHistogram(tuple(np.linspace(500, 2500, 11)), tuple(np.ones(10)))
    old = random_elevation_field(dom, hist, correlation_m=4000.0, rng=7)
    w0, w1, w2 = random_elevation_fields(dom, hist, correlation_m=4000.0, rng=7, fine_weights=(0.0, 0.5, 2.0))
    np.testing.assert_array_equal(old, w0)  # weight 0: the field without the fine component
    step = lambda f: float(np.median(np.abs(np.diff(f, axis=1))))  # noqa: E731
    assert step(w0) < step(w1) < step(w2)
    for f in (w1, w2):  # every field follows the elevation histogram (rank mapping)
        assert np.quantile(f, [0.0, 0.5, 1.0]) == pytest.approx(np.quantile(w0, [0.0, 0.5, 1.0]), abs=1.0)
    with pytest.raises(InputError, match="fine_elevation_m"):
        SynthesisParams(fine_elevation_m=0.0)


def test_synthesis_fits_the_neighbour_gradient(synthesized_type):
    _, t = synthesized_type
    plain = synthesize_divide_tree(t, size_m=30_000.0, rng=6, params=SynthesisParams(follow_neighbour_gradient=False))
    x, y, z = (plain.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    g0 = float(np.median(_nn_gradient_by_hand(x, y, z)))
    target = 1.6 * g0
    on = SynthesisParams(follow_neighbour_gradient=True)
    fitted = synthesize_divide_tree(dataclasses.replace(t, neighbour_gradient=target), size_m=30_000.0, rng=6,
                                    params=on)
    x, y, z = (fitted.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    g1 = float(np.median(_nn_gradient_by_hand(x, y, z)))
    rec = fitted.attrs["neighbour_gradient"]
    assert rec["reached"] == pytest.approx(g1, rel=1e-4) and rec["fine_weight"] > 0
    assert abs(np.log(g1 / target)) < 0.5 * abs(np.log(g0 / target))
    again = synthesize_divide_tree(dataclasses.replace(t, neighbour_gradient=target), size_m=30_000.0, rng=6,
                                   params=on)
    assert again.peaks.equals(fitted.peaks) and again.saddles.equals(fitted.saddles)  # same seed, same tree
    assert plain.attrs["neighbour_gradient"] is None
    fitted.validate()


def test_fine_component_needs_reach(synthesized_type):
    """Session 11: with ``fine_needs_reach`` a median no weight reaches gets no fine component."""
    _, t = synthesized_type
    far = dataclasses.replace(t, neighbour_gradient=100.0 * t.neighbour_gradient)
    closest = synthesize_divide_tree(far, size_m=30_000.0, rng=6,
                                     params=SynthesisParams(follow_neighbour_gradient=True))
    none = synthesize_divide_tree(far, size_m=30_000.0, rng=6,
                                  params=SynthesisParams(follow_neighbour_gradient=True, fine_needs_reach=True))
    assert closest.attrs["neighbour_gradient"]["fine_weight"] > 0
    rec = none.attrs["neighbour_gradient"]
    assert rec["fine_weight"] == 0.0 and rec["trials"] == closest.attrs["neighbour_gradient"]["trials"]
    x, y, z = (none.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    assert rec["reached"] == pytest.approx(float(np.median(_nn_gradient_by_hand(x, y, z))), rel=1e-4)
    plain = synthesize_divide_tree(t, size_m=30_000.0, rng=6, params=SynthesisParams(follow_neighbour_gradient=False))
    x, y, z = (plain.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    near = dataclasses.replace(t, neighbour_gradient=1.3 * float(np.median(_nn_gradient_by_hand(x, y, z))))  # reachable
    a, b = (synthesize_divide_tree(near, size_m=30_000.0, rng=6, params=SynthesisParams(
        follow_neighbour_gradient=True, fine_needs_reach=r)) for r in (False, True))
    assert a.peaks.equals(b.peaks) and a.attrs["neighbour_gradient"]["fine_weight"] > 0
    with pytest.raises(InputError, match="fine_needs_reach"):
        SynthesisParams(fine_needs_reach=1)  # type: ignore[arg-type]


def _higher_gradient_by_hand(tree) -> np.ndarray:
    x, y, z = (tree.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    d = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
    d[~(z[None, :] > z[:, None])] = np.inf
    j = np.argmin(d, axis=1)
    has = np.isfinite(d[np.arange(x.size), j])
    return (z[j] - z)[has] / d[np.arange(x.size), j][has]


# session 15's synthesis defaults: the steep tail below is open there (session 16's defaults bound it already)
SESSION15 = dict(void_weight=1.0, border_density=False, valley_network=0.0, follow_ridge_slope=False,
                 follow_neighbour_gradient=False, gradient_tail=None)


def test_gradient_tail_bounds_the_steepest_peaks(small_type):
    """Session 11: ``gradient_tail`` closes the open last bin of the gradient histogram (session 15's
    other settings, with their type: the tree and the bound as measured then)."""
    tree = synthesize_divide_tree(small_type, size_m=30_000.0, rng=2, params=SynthesisParams(**SESSION15))
    t = TerrainType.from_divide_tree(tree, area_km2=900.0, min_prominence_m=30.0)
    edge = float(t.gradient.edges[-1])
    assert t.gradient.open_last
    steep = dataclasses.replace(t, neighbour_gradient=3.0 * t.neighbour_gradient)  # a large fine component
    kw = dict(SESSION15, follow_neighbour_gradient=True)
    free = synthesize_divide_tree(steep, size_m=30_000.0, rng=4, params=SynthesisParams(**kw))
    capped = synthesize_divide_tree(steep, size_m=30_000.0, rng=4, params=SynthesisParams(**dict(kw, gradient_tail=1.5)))
    over = lambda tr: float(np.mean(_higher_gradient_by_hand(tr) > 1.5 * edge))  # noqa: E731
    assert over(free) >= 0.02 and over(capped) < 0.5 * over(free)
    capped.validate()
    with pytest.raises(InputError, match="gradient_tail"):
        SynthesisParams(gradient_tail=0.5)
