"""Settled peaks of chunk summaries (the streaming criterion of docs/scaling.md) are final."""
from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from orokit.tiling.summary import chunk_summary, merge_summaries, settled_peaks
from orokit.topology.engine import orometry

from tiling.test_tiled_equals_untiled import grids


def _check(s, final, eps, outside, seen):
    got = settled_peaks(s, eps)
    pos = {int(c): i for i, c in enumerate(final.peak_cell)}
    for j, cell in enumerate(got["cell"]):
        i = pos.get(int(cell))
        if not got["kept"][j]:
            assert i is None, f"settled peak {cell} below the threshold is a final peak"
            continue
        assert i is not None, f"settled peak {cell} is not a final peak"
        assert got["key_saddle_cell"][j] == final.key_saddle_cell[i]
        assert got["key_saddle_z"][j] == final.key_saddle_z[i]
        assert got["prominence"][j] == final.prominence[i]
        if outside == "unknown":
            assert (not got["touched"][j]) == final.prominence_exact[i]
        seen.add(int(cell))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grids(), st.sampled_from([0.0, 1.0, 2.0]), st.sampled_from(["unknown", "sea"]),
       st.sampled_from(["halves", "rows"]))
def test_settled_peaks_are_final(case, eps, outside, order):
    """Every summary on the way (chunks, strips, halves): its settled peaks have their final
    prominence, key saddle cell and height and exactness flag; settled peaks below the threshold
    are no final peak. At the root every kept peak but the domains' highest is settled."""
    z, ch, cw = case
    assume(not np.isnan(z).all())
    H, W = z.shape
    final = orometry(z, min_prominence_m=eps, outside=outside)
    zp = np.pad(z, 1, constant_values=np.nan)
    rb, cb = list(range(0, H, ch)) + [H], list(range(0, W, cw)) + [W]
    seen: set[int] = set()

    def tile(i, j):
        s = chunk_summary(zp[rb[i]:rb[i + 1] + 2, cb[j]:cb[j + 1] + 2], rb[i], cb[j], (H, W), eps)
        _check(s, final, eps, outside, seen)
        return s

    def merge(a, b):
        s = merge_summaries(a, b, eps)
        _check(s, final, eps, outside, seen)
        return s

    def reduce(i0, i1, j0, j1):
        if i1 - i0 == 1 and j1 - j0 == 1:
            return tile(i0, j0)
        if i1 - i0 >= j1 - j0:
            m = (i0 + i1) // 2
            return merge(reduce(i0, m, j0, j1), reduce(m, i1, j0, j1))
        m = (j0 + j1) // 2
        return merge(reduce(i0, i1, j0, m), reduce(i0, i1, m, j1))

    if order == "halves":
        reduce(0, len(rb) - 1, 0, len(cb) - 1)
    else:
        strips = []
        for i in range(len(rb) - 1):
            s = tile(i, 0)
            for j in range(1, len(cb) - 1):
                s = merge(s, tile(i, j))
            strips.append(s)
        s = strips[0]
        for r in strips[1:]:
            s = merge(s, r)
    # the whole raster has no side: every non-root kept peak is settled there
    nonroot = final.key_saddle_cell >= 0
    assert set(final.peak_cell[nonroot].tolist()) <= seen


def test_settled_share_grows_with_the_region():
    """On a rough surface most peaks are settled before the last merges (what streaming saves)."""
    rng = np.random.default_rng(0)
    z = np.round(rng.normal(size=(120, 120)).cumsum(axis=0) * 0.3 + rng.normal(size=(120, 120)), 1)
    H, W = z.shape
    zp = np.pad(z, 1, constant_values=np.nan)
    eps = 1.0
    t = [chunk_summary(zp[r:r + 32, c:c + 32], r, c, (H, W), eps) for r in (0, 30, 60, 90) for c in (0, 30, 60, 90)]
    shares = []
    for level in range(4):
        t = [merge_summaries(t[k], t[k + 1], eps) for k in range(0, len(t), 2)] if level else t
        got = [settled_peaks(s, eps) for s in t]
        shares.append(sum(g["kept"].sum() for g in got) / sum(int(s.ismax.sum()) for s in t))
    assert shares[0] < shares[-1]
