"""Forced prominence (issue 11, session 19): the least prominence a tree's peaks and ridges allow. A type records
how often its high peaks stand among much lower ones (``forced_tail``); ``follow_forced_tail`` joins a twin's peaks
along higher ground until its tree does it no more often. Re-measured here by brute force over tree paths."""
from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest

from orokit.errors import InputError, OrokitWarning
from orokit.synthesis.saddles import forced_tail
from orokit.synthesis.tree import SynthesisParams, synthesize_divide_tree

from helpers.type_records import check_optional_record

FAST = {"follow_neighbour_gradient": False}


def _forced_by_hand(z: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per peak: h minus the best, over higher peaks, of the lowest ridge end on the tree path there."""
    adj: dict[int, list[int]] = {i: [] for i in range(z.size)}
    for u, v in zip(a.tolist(), b.tolist()):
        adj[u].append(v)
        adj[v].append(u)
    out = np.full(z.size, np.nan)
    for i in range(z.size):
        best = -np.inf
        stack = [(i, -1, np.inf)]
        while stack:
            u, parent, low = stack.pop()
            if u != i and (z[u] > z[i] or (z[u] == z[i] and u < i)):
                best = max(best, low)
            for v in adj[u]:
                if v != parent:
                    stack.append((v, u, min(low, z[u], z[v])))
        if np.isfinite(best):
            out[i] = z[i] - best
    return out


def _digest(tree) -> str:
    parts = [tree.peaks[["x", "y", "elevation"]], tree.saddles[["x", "y", "elevation"]], tree.edges]
    return hashlib.sha256(b"".join(np.ascontiguousarray(p.to_numpy()).tobytes() for p in parts)).hexdigest()


def _share(tree, threshold: float) -> float:
    return forced_tail(tree.peaks["elevation"].to_numpy(float), tree.edges["peak_a"].to_numpy(np.int64),
                       tree.edges["peak_b"].to_numpy(np.int64), threshold)


def test_type_records_the_forced_tail_by_brute_force(synthesized_type):
    tree, t = synthesized_type
    pruned = tree.prune(30.0)
    z = pruned.peaks["elevation"].to_numpy(float)
    forced = _forced_by_hand(z, pruned.edges["peak_a"].to_numpy(), pruned.edges["peak_b"].to_numpy())
    pt = pruned.prominence_table()
    prom = pt["prominence"].to_numpy(float)[pt["key_saddle"].to_numpy() >= 0]
    keyed = np.isfinite(forced)
    assert keyed.sum() == prom.size
    assert t.forced_tail == pytest.approx(float((forced[keyed] >= np.quantile(prom, 0.9)).mean()))
    assert 0 < t.forced_tail < 1
    check_optional_record(t, "forced_tail", 1.5)
    assert t.scaled("prominence", 1.5).forced_tail is None
    assert t.with_density(t.peak_density_per_km2 * 2).forced_tail is None


def test_old_types_and_several_types_are_unchanged(synthesized_type):
    _, t = synthesized_type
    old = dataclasses.replace(t, forced_tail=None)
    plain = synthesize_divide_tree(old, size_m=30_000, rng=4, params=SynthesisParams(**FAST))
    with pytest.warns(OrokitWarning, match="follow_forced_tail does nothing here.*no forced_tail record"):
        on = synthesize_divide_tree(old, size_m=30_000, rng=4, params=SynthesisParams(follow_forced_tail=True, **FAST))
    assert _digest(on) == _digest(plain) and on.attrs["forced_tail"] is None
    with pytest.raises(InputError):
        SynthesisParams(follow_forced_tail=1)


def test_follow_forced_tail_joins_high_peaks_along_high_ground(synthesized_type):
    """Asked for no forced tail at all, the option raises rho step by step: the tree's share, re-measured by brute
    force, falls below the plain tree's in every seed, and the peaks and their elevations are the same."""
    _, t = synthesized_type
    want = dataclasses.replace(t, forced_tail=0.0)
    for seed in range(3):
        p0 = synthesize_divide_tree(want, size_m=30_000, rng=seed, params=SynthesisParams(**FAST))
        p1 = synthesize_divide_tree(want, size_m=30_000, rng=seed, params=SynthesisParams(follow_forced_tail=True, **FAST))
        p1.validate()
        rec = p1.attrs["forced_tail"]
        assert rec["target"] == 0.0 and rec["rho_added"] > 0
        z1 = p1.peaks["elevation"].to_numpy(float)
        assert np.array_equal(np.sort(z1), np.sort(p0.peaks["elevation"].to_numpy(float)))
        f0 = _forced_by_hand(p0.peaks["elevation"].to_numpy(float), p0.edges["peak_a"].to_numpy(), p0.edges["peak_b"].to_numpy())
        f1 = _forced_by_hand(z1, p1.edges["peak_a"].to_numpy(), p1.edges["peak_b"].to_numpy())
        thr = 300.0
        assert np.nanmean(f1 >= thr) < np.nanmean(f0 >= thr) or np.nanmax(f1) < np.nanmax(f0)
