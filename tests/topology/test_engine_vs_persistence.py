"""Prominence is 0-dimensional persistence (elder rule): cripser as an oracle.

The multiset of finite (birth, death) pairs of the superlevel filtration with
8-connectivity (cripser's T-construction) equals the multiset of (elevation, key
saddle elevation) of the non-root peaks; the essential classes are the roots, one per
8-connected domain of valid cells. Compared as multisets: ties make pairings ambiguous.
"""
from __future__ import annotations

import numpy as np
from helpers.orometry_oracles import flat_domain_cells, grids, make_dem, persistence_pairs
from hypothesis import given, settings
from hypothesis import strategies as st

import orokit


def engine_pairs(peaks) -> tuple[list[tuple[float, float]], list[float]]:
    root = peaks["island_parent"].to_numpy() == -1
    e = peaks["elevation"].to_numpy(float)
    s = peaks["saddle_elevation"].to_numpy(float)
    return sorted(zip(e[~root], s[~root])), sorted(e[root].tolist())


def oracle_pairs(z: np.ndarray, eps: float) -> tuple[list[tuple[float, float]], list[float]]:
    """cripser pairs with persistence >= eps; essential classes of flat domains removed
    (the flat-domain convention is tested apart in test_engine_bad_input.py)."""
    zz = np.where(flat_domain_cells(z), np.nan, z.astype(np.float64))
    if not np.isfinite(zz).any():
        return [], []
    fin, ess = persistence_pairs(zz)
    # roots: prominence = elevation, kept when it reaches eps; eps = 0 keeps every peak
    return [(b, d) for b, d in fin if b - d >= eps], [b for b in ess if eps == 0 or b >= eps]


def _roots_of_domains_with_kept_peaks(z: np.ndarray, peaks) -> list[float]:
    """Domain maxima of the 8-connected domains that hold a kept non-root peak: the engine
    keeps such a root even below eps (it is the parent of a kept peak)."""
    from scipy import ndimage

    lab, _ = ndimage.label(np.isfinite(z), structure=np.ones((3, 3), bool))
    nonroot = peaks[peaks["island_parent"] != -1]
    doms = set(lab[nonroot["row"].to_numpy(int), nonroot["col"].to_numpy(int)].tolist())
    return [float(np.nanmax(np.where(lab == d, z, np.nan))) for d in doms]


def check(z: np.ndarray, eps: float) -> None:
    peaks = orokit.analyze(make_dem(z), min_prominence_m=eps, isolation=False).peaks
    got_fin, got_roots = engine_pairs(peaks)
    exp_fin, exp_roots = oracle_pairs(z, eps)
    if eps > 0:
        below = sorted(r for r in _roots_of_domains_with_kept_peaks(z, peaks) if r < eps)
        exp_roots = sorted(exp_roots + below)
    assert got_fin == exp_fin, f"finite pairs differ at eps={eps} for\n{z!r}"
    assert got_roots == exp_roots, f"roots differ at eps={eps} for\n{z!r}"


@settings(max_examples=150, deadline=None)
@given(z=grids(12))
def test_persistence_pairs_eps0(z):
    check(z, 0.0)


@settings(max_examples=100, deadline=None)
@given(z=grids(12), eps=st.sampled_from([0.25, 1.0, 2.0, 7.5, 40.0]))
def test_persistence_pairs_thresholded(z, eps):
    check(z, eps)


def test_cripser_oracle_is_eight_connected():
    # diagonal-only contact: 8-connectivity joins the two 3s through the 2-cell saddle
    z = np.array([[3, 0, 0], [0, 2, 0], [0, 0, 3]], np.float64)
    fin, ess = persistence_pairs(z)
    assert fin == [(3.0, 2.0)] and ess == [3.0]
