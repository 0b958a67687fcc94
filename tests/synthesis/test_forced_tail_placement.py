"""Forced-tail placement (issue 11, session 20): the dart throwing follows the type's ``forced_tail`` by keeping the
passes' lower peaks off the ridges of the earlier passes whose lower end stands far above them (a low peak on such a
ridge splits it and forces a high prominence on its end). Re-measured here by brute force: every pass's MST rebuilt
from the placed peaks and each peak's distance to its segments."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from orokit.errors import InputError, OrokitWarning
from orokit.synthesis.darts import pass_bounds
from orokit.synthesis.ridges import delaunay_mst
from orokit.synthesis.tree import SynthesisParams, _prominence_q90, synthesize_divide_tree

FAST = {"follow_neighbour_gradient": False}


def _deep_splits(tree, rho: float, threshold: float, n_passes: int = 4) -> int:
    """Peaks placed within half their pass's spacing of an earlier pass's ridge whose lower end is ``threshold`` or
    more above them (peaks in the tree's order: highest first, as placed)."""
    x, y, z = (tree.peaks[c].to_numpy(float) for c in ("x", "y", "elevation"))
    assert np.all(np.diff(z) <= 0)
    dom = tree.attrs["domain"]
    count = 0
    for s, e in pass_bounds(z.size, n_passes)[1:]:
        a, b = delaunay_mst(x[:s], y[:s], z[:s], rho=np.full(s, rho))
        reach = 0.5 * np.sqrt(dom["width"] * dom["height"] / s)
        ax, ay, bx, by = x[a], y[a], x[b], y[b]
        low = np.minimum(z[a], z[b])
        for k in range(s, e):
            vx, vy = bx - ax, by - ay
            t = np.clip(((x[k] - ax) * vx + (y[k] - ay) * vy) / np.maximum(vx * vx + vy * vy, 1e-12), 0.0, 1.0)
            d = np.hypot(ax + t * vx - x[k], ay + t * vy - y[k])
            count += bool(np.any((d <= reach) & (low - z[k] >= threshold)))
    return count


def test_placement_keeps_the_elevations_and_the_spacing(synthesized_type):
    """The option only chooses among the same candidates: the same peak elevations, all inside the domain, the
    median distance to the nearest peak within 15 % of the plain layout's."""
    from scipy.spatial import cKDTree

    _, t = synthesized_type
    for seed in range(2):
        p0 = synthesize_divide_tree(t, size_m=30_000, rng=seed, params=SynthesisParams(**FAST))
        p1 = synthesize_divide_tree(t, size_m=30_000, rng=seed, params=SynthesisParams(forced_tail_placement=True, **FAST))
        p1.validate()
        z0, z1 = (p.peaks["elevation"].to_numpy(float) for p in (p0, p1))
        assert np.array_equal(np.sort(z0), np.sort(z1))
        xy = p1.peaks[["x", "y"]].to_numpy(float)
        assert np.all((xy >= 0) & (xy <= 30_000))
        nn = [np.median(cKDTree(p.peaks[["x", "y"]].to_numpy(float)).query(p.peaks[["x", "y"]].to_numpy(float), k=2)[0][:, 1])
              for p in (p0, p1)]
        assert nn[1] == pytest.approx(nn[0], rel=0.15)
        rec = p1.attrs["forced_tail_placement"]
        assert sum(rec["placed"][0]) == pytest.approx(p1.n_peaks - 1)
        assert sum(rec["target"][0]) == pytest.approx(p1.n_peaks - 1)
        assert "forced_tail_placement" not in p0.attrs


def test_asked_for_no_tail_the_lower_peaks_keep_off_deep_ridges(synthesized_type):
    """With a type asking for no forced tail, fewer peaks split a deep ridge of an earlier pass (brute force) than
    without the option, in every seed."""
    _, t = synthesized_type
    want = dataclasses.replace(t, forced_tail=0.0)
    for seed in range(3):
        p0 = synthesize_divide_tree(want, size_m=30_000, rng=seed, params=SynthesisParams(**FAST))
        p1 = synthesize_divide_tree(want, size_m=30_000, rng=seed,
                                    params=SynthesisParams(forced_tail_placement=True, **FAST))
        d0 = _deep_splits(p0, want.rho, _prominence_q90(want))
        d1 = _deep_splits(p1, want.rho, _prominence_q90(want))
        assert d1 < d0, (seed, d0, d1)
        assert p1.attrs["forced_tail_placement"]["target"][0][1] == 0.0


def test_old_types_warn_and_keep_their_bytes(synthesized_type):
    _, t = synthesized_type
    old = dataclasses.replace(t, forced_tail=None)
    plain = synthesize_divide_tree(old, size_m=30_000, rng=4, params=SynthesisParams(**FAST))
    with pytest.warns(OrokitWarning, match="forced_tail_placement does nothing here.*no terrain type has a forced_tail"):
        on = synthesize_divide_tree(old, size_m=30_000, rng=4,
                                    params=SynthesisParams(forced_tail_placement=True, **FAST))
    for part in ("peaks", "saddles", "edges"):
        assert getattr(on, part).equals(getattr(plain, part))
    assert "forced_tail_placement" not in on.attrs
    with pytest.raises(InputError):
        SynthesisParams(forced_tail_placement=1)
